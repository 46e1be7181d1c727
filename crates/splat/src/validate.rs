//! Input checks shared by the forward and backward passes (bad input is an error, never a
//! panic inside the kernels).

use crate::sh::{num_coeffs, MAX_DEGREE};
use crate::{Camera, Colors, Gaussians, SplatError};

fn check_len(name: &'static str, got: usize, expected: usize) -> Result<(), SplatError> {
    if got == expected {
        Ok(())
    } else {
        Err(SplatError::Length {
            name,
            got,
            expected,
        })
    }
}

pub(crate) fn validate_forward(g: &Gaussians, cam: &Camera) -> Result<(), SplatError> {
    let n = g.len();
    if n > u32::MAX as usize - 1 {
        return Err(SplatError::Invalid(format!(
            "{n} Gaussians exceed the u32 index range"
        )));
    }
    check_len("means", g.means.len(), n * 3)?;
    check_len("quats", g.quats.len(), n * 4)?;
    check_len("scales", g.scales.len(), n * 3)?;
    match g.colors {
        Colors::Rgb(c) => check_len("colors", c.len(), n * 3)?,
        Colors::Sh {
            coeffs,
            num_coeffs: k,
            degree,
        } => {
            if degree > MAX_DEGREE || k < num_coeffs(degree) {
                return Err(SplatError::Invalid(format!(
                    "SH degree {degree} with {k} coefficients per Gaussian (degree ≤ {MAX_DEGREE} and ≥ (degree+1)² coefficients needed)"
                )));
            }
            check_len("sh coefficients", coeffs.len(), n * k * 3)?;
        }
    }
    if cam.width == 0 || cam.height == 0 {
        return Err(SplatError::Invalid(format!(
            "empty image {}×{}",
            cam.width, cam.height
        )));
    }
    let intr = [cam.fx, cam.fy, cam.cx, cam.cy];
    if !intr.iter().all(|v| v.is_finite()) || cam.fx == 0.0 || cam.fy == 0.0 {
        return Err(SplatError::Invalid(format!(
            "bad intrinsics fx {} fy {} cx {} cy {}",
            cam.fx, cam.fy, cam.cx, cam.cy
        )));
    }
    Ok(())
}

pub(crate) fn validate_backward(
    g: &Gaussians,
    cam: &Camera,
    shape: Option<(usize, u32, u32)>,
    dl_dimage: &[f32],
    dl_dalpha: Option<&[f32]>,
) -> Result<(), SplatError> {
    validate_forward(g, cam)?;
    if shape != Some((g.len(), cam.width, cam.height)) {
        return Err(SplatError::Invalid(
            "backward called without a forward pass of the same Gaussians and image size".into(),
        ));
    }
    let px = cam.width as usize * cam.height as usize;
    check_len("dl_dimage", dl_dimage.len(), px * 3)?;
    if let Some(a) = dl_dalpha {
        check_len("dl_dalpha", a.len(), px)?;
    }
    Ok(())
}
