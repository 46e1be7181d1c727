//! Which Gaussians the deformation field is evaluated on. With `visible_only`, only those
//! whose canonical mean projects in front of the camera and inside the image enlarged by a
//! margin: a cheap superset of what the view can show when deformations are small next to
//! the margin. The others keep δ = 0 for this iteration and get no field gradient.

use rayon::prelude::*;
use splat::Camera;

/// Indices of Gaussians to evaluate: all of them, or the pre-projected visible ones.
pub fn field_rows(
    means: &[f32],
    cam: &Camera,
    visible_only: bool,
    margin: f32,
    out: &mut Vec<u32>,
) {
    let n = means.len() / 3;
    out.clear();
    if !visible_only {
        out.extend(0..n as u32);
        return;
    }
    let (w, h) = (cam.width as f32, cam.height as f32);
    let (mx, my) = (margin * w, margin * h);
    let keep: Vec<bool> = means
        .par_chunks_exact(3)
        .map(|m| match cam.project([m[0], m[1], m[2]]) {
            Some((p, _)) => p[0] >= -mx && p[0] <= w + mx && p[1] >= -my && p[1] <= h + my,
            None => false,
        })
        .collect();
    out.extend(
        keep.iter()
            .enumerate()
            .filter(|(_, &k)| k)
            .map(|(i, _)| i as u32),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_points_in_view_with_margin() {
        let cam = Camera {
            width: 100,
            height: 100,
            fx: 100.0,
            fy: 100.0,
            cx: 50.0,
            cy: 50.0,
            viewmat: [
                [1., 0., 0., 0.],
                [0., 1., 0., 0.],
                [0., 0., 1., 0.],
                [0., 0., 0., 1.],
            ],
        };
        // centre; just outside (x = 0.55 → 105 px, inside the 10% margin); far out; behind.
        let means = [0.0, 0.0, 1.0, 0.55, 0.0, 1.0, 3.0, 0.0, 1.0, 0.0, 0.0, -1.0];
        let mut rows = Vec::new();
        field_rows(&means, &cam, true, 0.1, &mut rows);
        assert_eq!(rows, vec![0, 1]);
        field_rows(&means, &cam, false, 0.1, &mut rows);
        assert_eq!(rows, vec![0, 1, 2, 3]);
    }
}
