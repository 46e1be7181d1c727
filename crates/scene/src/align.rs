//! Comparing two camera sets of the same frames whose worlds differ by a similarity
//! (structure from motion recovers poses only up to scale, rotation and translation).
//!
//! The similarity `x ↦ s·R·x + t` taking the estimated camera centres onto the reference
//! ones is Umeyama's least-squares solution (S. Umeyama, "Least-squares estimation of
//! transformation parameters between two point patterns", PAMI 1991), with the rotation
//! found as Horn's unit quaternion (B. Horn, "Closed-form solution of absolute orientation
//! using unit quaternions", JOSA A 1987): the eigenvector of the largest eigenvalue of a
//! symmetric 4 × 4 built from the cross-covariance, by Jacobi iteration. Both give the same
//! rotation; the quaternion form needs no SVD and cannot return a reflection.

use serde::Serialize;

/// `x ↦ scale·rotation·x + translation`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Similarity {
    pub scale: f64,
    /// Row-major.
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

impl Similarity {
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| {
            self.scale * (0..3).map(|k| self.rotation[i][k] * p[k]).sum::<f64>()
                + self.translation[i]
        })
    }
}

/// Least-squares similarity taking `src[i]` onto `dst[i]`; `None` with fewer than 3
/// points or when the source points all coincide.
pub fn umeyama(src: &[[f64; 3]], dst: &[[f64; 3]]) -> Option<Similarity> {
    let n = src.len();
    if n < 3 || dst.len() != n {
        return None;
    }
    let mean = |p: &[[f64; 3]]| -> [f64; 3] {
        std::array::from_fn(|k| p.iter().map(|v| v[k]).sum::<f64>() / n as f64)
    };
    let (ms, md) = (mean(src), mean(dst));
    let mut cov = [[0.0f64; 3]; 3]; // Σ (dst − md)(src − ms)ᵀ
    let mut var_src = 0.0;
    for (s, d) in src.iter().zip(dst) {
        let (a, b): ([f64; 3], [f64; 3]) = (
            std::array::from_fn(|k| s[k] - ms[k]),
            std::array::from_fn(|k| d[k] - md[k]),
        );
        var_src += a.iter().map(|v| v * v).sum::<f64>();
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += b[i] * a[j];
            }
        }
    }
    if var_src.is_nan() || var_src <= 1e-300 {
        return None;
    }
    let rotation = horn_rotation(&cov);
    // Umeyama's scale: trace(Rᵀ·cov) / Σ|src − ms|².
    let tr: f64 = (0..3)
        .map(|i| (0..3).map(|k| rotation[k][i] * cov[k][i]).sum::<f64>())
        .sum();
    let scale = tr / var_src;
    let rms: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| rotation[i][k] * ms[k]).sum());
    let translation = std::array::from_fn(|i| md[i] - scale * rms[i]);
    let s = Similarity {
        scale,
        rotation,
        translation,
    };
    (scale.is_finite() && scale > 0.0).then_some(s)
}

/// Scale and translation of the least-squares similarity `src → dst` with its rotation
/// given.
fn with_rotation(
    src: &[[f64; 3]],
    dst: &[[f64; 3]],
    rotation: [[f64; 3]; 3],
) -> Option<Similarity> {
    let n = src.len() as f64;
    let mean = |p: &[[f64; 3]]| -> [f64; 3] {
        std::array::from_fn(|k| p.iter().map(|v| v[k]).sum::<f64>() / n)
    };
    let (ms, md) = (mean(src), mean(dst));
    let (mut num, mut den) = (0.0, 0.0);
    for (s, d) in src.iter().zip(dst) {
        let a: [f64; 3] = std::array::from_fn(|k| s[k] - ms[k]);
        let ra: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| rotation[i][k] * a[k]).sum());
        num += (0..3).map(|k| ra[k] * (d[k] - md[k])).sum::<f64>();
        den += a.iter().map(|v| v * v).sum::<f64>();
    }
    let scale = num / den;
    let rms: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| rotation[i][k] * ms[k]).sum());
    let translation = std::array::from_fn(|i| md[i] - scale * rms[i]);
    (scale.is_finite() && scale > 0.0).then_some(Similarity {
        scale,
        rotation,
        translation,
    })
}

/// The rotation `R` maximizing trace(Rᵀ·M) for the cross-covariance `M = Σ d sᵀ`.
fn horn_rotation(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    // Horn's N with S = Mᵀ in his notation (S_ab = Σ s_a d_b).
    let s = |a: usize, b: usize| m[b][a];
    let n = [
        [
            s(0, 0) + s(1, 1) + s(2, 2),
            s(1, 2) - s(2, 1),
            s(2, 0) - s(0, 2),
            s(0, 1) - s(1, 0),
        ],
        [
            s(1, 2) - s(2, 1),
            s(0, 0) - s(1, 1) - s(2, 2),
            s(0, 1) + s(1, 0),
            s(2, 0) + s(0, 2),
        ],
        [
            s(2, 0) - s(0, 2),
            s(0, 1) + s(1, 0),
            -s(0, 0) + s(1, 1) - s(2, 2),
            s(1, 2) + s(2, 1),
        ],
        [
            s(0, 1) - s(1, 0),
            s(2, 0) + s(0, 2),
            s(1, 2) + s(2, 1),
            -s(0, 0) - s(1, 1) + s(2, 2),
        ],
    ];
    let (vals, vecs) = jacobi_eigen4(n);
    let best = (0..4)
        .max_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    let q = [vecs[0][best], vecs[1][best], vecs[2][best], vecs[3][best]];
    crate::colmap::quat_to_rot(q)
}

/// Eigenvalues and eigenvectors (columns) of a symmetric 4 × 4 by cyclic Jacobi rotations.
fn jacobi_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..100 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let scale: f64 = a.iter().flatten().map(|x| x * x).sum();
        if off <= 1e-30 * scale.max(1e-300) {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let sign = if theta >= 0.0 { 1.0 } else { -1.0 };
                let t = sign / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (rp, rq) = (a[p], a[q]);
                for k in 0..4 {
                    a[p][k] = c * rp[k] - s * rq[k];
                    a[q][k] = s * rp[k] + c * rq[k];
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}

/// Pose errors of an estimate against a reference, after aligning the estimate's camera
/// centres onto the reference's.
#[derive(Clone, Debug, Serialize)]
pub struct PoseErrors {
    pub frames: usize,
    pub alignment: Similarity,
    /// The reference's scene extent: 1.1 × the largest distance of a camera centre from
    /// the centres' mean (3DGS's `getNerfppNorm`, `Dataset::scene_extent`).
    pub extent: f64,
    /// Centre errors in the reference's units, per frame in the order given.
    pub centre_errors: Vec<f64>,
    /// Rotation errors in degrees: the angle of `R_ref · (R·R_est)ᵀ` with camera-to-world
    /// rotations, per frame.
    pub rotation_errors_deg: Vec<f64>,
    pub centre_median_rel: f64,
    pub centre_max_rel: f64,
    pub rotation_median_deg: f64,
    pub rotation_max_deg: f64,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Camera centre and camera-to-world rotation of a world-to-camera matrix.
fn centre_rot(c: &splat::Camera) -> ([f64; 3], [[f64; 3]; 3]) {
    let m = c.viewmat.map(|r| r.map(f64::from));
    let rt: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]));
    let t = [m[0][3], m[1][3], m[2][3]];
    let centre = std::array::from_fn(|i| -(0..3).map(|k| rt[i][k] * t[k]).sum::<f64>());
    (centre, rt)
}

/// Aligns `estimate` onto `reference` (the same frames, in the same order) and measures.
pub fn compare_cameras(
    reference: &[splat::Camera],
    estimate: &[splat::Camera],
) -> Result<PoseErrors, String> {
    if reference.len() != estimate.len() {
        return Err(format!(
            "{} reference cameras but {} estimated",
            reference.len(),
            estimate.len()
        ));
    }
    let r: Vec<_> = reference.iter().map(centre_rot).collect();
    let e: Vec<_> = estimate.iter().map(centre_rot).collect();
    let rc: Vec<[f64; 3]> = r.iter().map(|x| x.0).collect();
    let ec: Vec<[f64; 3]> = e.iter().map(|x| x.0).collect();
    // The rotation from the cameras' orientations (the rotation closest to
    // Σ R_ref·R_estᵀ): centres alone leave it undetermined about the line of a nearly
    // straight camera path. Scale and translation then from the centres (Umeyama's, given R).
    let mut m = [[0.0f64; 3]; 3];
    for ((_, re), (_, rr)) in e.iter().zip(&r) {
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += (0..3).map(|k| rr[i][k] * re[j][k]).sum::<f64>();
            }
        }
    }
    let rotation = horn_rotation(&m);
    let sim = (ec.len() >= 3)
        .then(|| with_rotation(&ec, &rc, rotation))
        .flatten()
        .ok_or_else(|| {
            "cannot align: fewer than 3 cameras, or the estimated centres coincide".to_string()
        })?;
    let n = rc.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|k| rc.iter().map(|c| c[k]).sum::<f64>() / n);
    let extent = 1.1
        * rc.iter()
            .map(|c| (0..3).map(|k| (c[k] - mean[k]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
    let centre_errors: Vec<f64> = ec
        .iter()
        .zip(&rc)
        .map(|(e, r)| {
            let a = sim.apply(*e);
            (0..3).map(|k| (a[k] - r[k]).powi(2)).sum::<f64>().sqrt()
        })
        .collect();
    let rotation_errors_deg: Vec<f64> = e
        .iter()
        .zip(&r)
        .map(|((_, re), (_, rr))| {
            // aligned = R_sim · R_est; error E = R_ref · alignedᵀ; its angle as
            // atan2(sin, cos) (cos from the trace, sin from the skew part), which stays
            // accurate for small angles where acos of the trace alone does not.
            let al: [[f64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| sim.rotation[i][k] * re[k][j]).sum())
            });
            let e: [[f64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| rr[i][k] * al[j][k]).sum())
            });
            let cos = 0.5 * (e[0][0] + e[1][1] + e[2][2] - 1.0);
            let sin = 0.5
                * ((e[2][1] - e[1][2]).powi(2)
                    + (e[0][2] - e[2][0]).powi(2)
                    + (e[1][0] - e[0][1]).powi(2))
                .sqrt();
            sin.atan2(cos).to_degrees()
        })
        .collect();
    let rel = |v: f64| if extent > 0.0 { v / extent } else { f64::NAN };
    Ok(PoseErrors {
        frames: rc.len(),
        alignment: sim,
        extent,
        centre_median_rel: rel(median(&centre_errors)),
        centre_max_rel: rel(centre_errors.iter().copied().fold(0.0, f64::max)),
        rotation_median_deg: median(&rotation_errors_deg),
        rotation_max_deg: rotation_errors_deg.iter().copied().fold(0.0, f64::max),
        centre_errors,
        rotation_errors_deg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(c: [f64; 3], r: [[f64; 3]; 3]) -> splat::Camera {
        // viewmat = [Rᵀ | −Rᵀc] for camera-to-world rotation r.
        let mut v = [[0.0f32; 4]; 4];
        for i in 0..3 {
            for j in 0..3 {
                v[i][j] = r[j][i] as f32;
            }
            v[i][3] = -(0..3).map(|k| r[k][i] * c[k]).sum::<f64>() as f32;
        }
        v[3][3] = 1.0;
        splat::Camera {
            width: 8,
            height: 8,
            fx: 8.0,
            fy: 8.0,
            cx: 4.0,
            cy: 4.0,
            viewmat: v,
        }
    }

    #[test]
    fn recovers_a_known_similarity_exactly() {
        let rot = crate::colmap::quat_to_rot([0.8, 0.3, -0.5, 0.1]);
        let sim = Similarity {
            scale: 2.5,
            rotation: rot,
            translation: [1.0, -2.0, 0.5],
        };
        let mut refs = Vec::new();
        let mut ests = Vec::new();
        for k in 0..10 {
            let a = k as f64 * 0.4;
            let c = [a.cos() * 3.0, a.sin() * 2.0, 0.3 * a];
            let r = crate::colmap::quat_to_rot([1.0, 0.1 * a, -0.05 * a, 0.2]);
            ests.push(cam(c, r));
            // reference = similarity applied to the estimate: centre s·R·c + t, rotation R·r.
            let rr: [[f64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| rot[i][k] * r[k][j]).sum())
            });
            refs.push(cam(sim.apply(c), rr));
        }
        let e = compare_cameras(&refs, &ests).unwrap();
        assert!((e.alignment.scale - 2.5).abs() < 1e-5, "{:?}", e.alignment);
        assert!(e.centre_max_rel < 1e-5, "{e:?}");
        assert!(e.rotation_max_deg < 1e-3, "{e:?}");
    }

    #[test]
    fn a_rotated_camera_shows_its_angle() {
        let c: Vec<[f64; 3]> = (0..5)
            .map(|k| [k as f64, (k * k) as f64 * 0.1, 1.0])
            .collect();
        let id = crate::colmap::quat_to_rot([1.0, 0.0, 0.0, 0.0]);
        let tilt = crate::colmap::quat_to_rot([
            (0.5f64.to_radians()).cos(),
            (0.5f64.to_radians()).sin(),
            0.0,
            0.0,
        ]);
        let refs: Vec<_> = c.iter().map(|&p| cam(p, id)).collect();
        let mut ests = refs.clone();
        ests[2] = cam(c[2], tilt);
        let e = compare_cameras(&refs, &ests).unwrap();
        // The alignment's rotation is the cameras' mean: it takes a fifth of the tilt, the
        // others show that fifth and the tilted camera the rest.
        let r = &e.rotation_errors_deg;
        assert!(
            (r[2] + r[0] - 1.0).abs() < 1e-3 && (r[0] - 0.2).abs() < 1e-2,
            "{e:?}"
        );
    }
}
