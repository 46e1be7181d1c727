//! The viewer's metadata (`/api/meta`): the runs, the slider's times, the scene's cameras
//! as viewpoints, and a default orbit. Cameras are given in the renderer's convention:
//! camera-to-world rotation as a quaternion `[x, y, z, w]` and the centre, OpenCV axes
//! (x right, y down, z forward), as in our `splat::Camera` and gsplat.js alike.

use super::frames::{object_colour, BACKGROUND_COLOUR};
use serde::Serialize;

#[derive(Serialize)]
pub struct Meta {
    pub runs: Vec<RunMeta>,
    /// The slider's steps (any t in [0, 1] may be asked for).
    pub times: Vec<f32>,
    pub image: [u32; 2],
    pub background: [f32; 3],
    pub cameras: Vec<CameraMeta>,
    pub orbit: Orbit,
}

#[derive(Serialize)]
pub struct RunMeta {
    pub name: String,
    pub path: String,
    pub iteration: u32,
    pub gaussians: usize,
    pub objects: Vec<ObjectMeta>,
    pub background_colour: [u8; 3],
}

#[derive(Serialize)]
pub struct ObjectMeta {
    pub id: u8,
    pub name: String,
    pub colour: [u8; 3],
    pub gaussians: usize,
}

#[derive(Serialize)]
pub struct CameraMeta {
    /// `train/r_000`: the frame's path in the scene.
    pub name: String,
    pub split: &'static str,
    pub time: f32,
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub position: [f32; 3],
    pub rotation: [f32; 4],
}

/// Where the orbit camera starts: it circles `target` about `up` at `radius`.
#[derive(Serialize, Debug)]
pub struct Orbit {
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub radius: f32,
}

impl RunMeta {
    pub fn of(name: String, path: String, r: &crate::cmd::render::LoadedRun) -> Self {
        let objects = r
            .objects
            .iter()
            .enumerate()
            .map(|(k, o)| ObjectMeta {
                id: o.id,
                name: o.name.clone(),
                colour: object_colour(k),
                gaussians: r.column.iter().filter(|&&c| c == o.id).count(),
            })
            .collect();
        Self {
            name,
            path,
            iteration: r.iteration,
            gaussians: r.model.len(),
            objects,
            background_colour: BACKGROUND_COLOUR,
        }
    }
}

pub fn cameras(ds: &scene::Dataset) -> Vec<CameraMeta> {
    let splits = [("train", &ds.train), ("val", &ds.val), ("test", &ds.test)];
    splits
        .iter()
        .flat_map(|(split, frames)| frames.iter().map(move |f| camera(split, f)))
        .collect()
}

fn camera(split: &'static str, f: &scene::Frame) -> CameraMeta {
    let c = &f.camera;
    CameraMeta {
        name: f.file_path.clone(),
        split,
        time: f.time,
        width: c.width,
        height: c.height,
        fx: c.fx,
        fy: c.fy,
        position: c.center(),
        rotation: quaternion_xyzw(&transpose(&rotation(c))),
    }
}

type M3 = [[f32; 3]; 3];

/// The world-to-camera rotation of `viewmat = [R | t]`.
fn rotation(c: &splat::Camera) -> M3 {
    let v = &c.viewmat;
    [
        [v[0][0], v[0][1], v[0][2]],
        [v[1][0], v[1][1], v[1][2]],
        [v[2][0], v[2][1], v[2][2]],
    ]
}

fn transpose(m: &M3) -> M3 {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

/// Unit quaternion `[x, y, z, w]` of a rotation matrix (Shepperd's method: the largest
/// of the four candidates is the divisor, so no branch loses precision).
pub fn quaternion_xyzw(m: &M3) -> [f32; 4] {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
            0.25 * s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[2][1] - m[1][2]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
            (m[0][2] - m[2][0]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
            (m[1][0] - m[0][1]) / s,
        ]
    };
    let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    q.map(|v| v / n)
}

/// The orbit the training cameras suggest: `up` against their mean image-down axis, the
/// target the point nearest all their optical axes (least squares), the radius their mean
/// distance to it. Cameras that all look one way (no such point) orbit `fallback`, e.g.
/// the Gaussians' centre.
pub fn orbit(cams: &[splat::Camera], fallback: [f32; 3]) -> Orbit {
    let mut up = [0.0f32; 3];
    let mut a = [[0.0f64; 3]; 3];
    let mut b = [0.0f64; 3];
    for c in cams {
        let r = rotation(c);
        let (down, fwd, centre) = (r[1], r[2], c.center());
        for (u, d) in up.iter_mut().zip(down) {
            *u -= d;
        }
        // Σ (I − d dᵀ) p = Σ (I − d dᵀ) c over the axes c + s·d.
        for (i, (row, bi)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
            for (j, aij) in row.iter_mut().enumerate() {
                let identity = if i == j { 1.0 } else { 0.0 };
                let p = identity - f64::from(fwd[i] * fwd[j]);
                *aij += p;
                *bi += p * f64::from(centre[j]);
            }
        }
    }
    let target = solve3(&a, &b).unwrap_or(fallback);
    let radius = if cams.is_empty() {
        1.0
    } else {
        cams.iter().map(|c| dist(c.center(), target)).sum::<f32>() / cams.len() as f32
    };
    let n = up.iter().map(|v| v * v).sum::<f32>().sqrt();
    Orbit {
        target,
        up: if n > 1e-6 {
            up.map(|v| v / n)
        } else {
            [0.0, 0.0, 1.0]
        },
        radius: if radius > 1e-6 { radius } else { 1.0 },
    }
}

fn dist(p: [f32; 3], q: [f32; 3]) -> f32 {
    (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>().sqrt()
}

/// Cramer's rule; None when the system is (nearly) singular.
fn solve3(a: &[[f64; 3]; 3], b: &[f64; 3]) -> Option<[f32; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    let scale = a.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
    if scale == 0.0 || d.abs() < 1e-6 * scale.powi(3) {
        return None;
    }
    let mut x = [0.0f32; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = *a;
        for (row, br) in m.iter_mut().zip(b) {
            row[k] = *br;
        }
        *xk = (det(&m) / d) as f32;
    }
    Some(x)
}

/// The coordinate-wise median of the Gaussians' centres (robust to floaters).
pub fn median_centre(means: &[f32]) -> [f32; 3] {
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut v: Vec<f32> = means.iter().skip(k).step_by(3).copied().collect();
        if v.is_empty() {
            continue;
        }
        let mid = v.len() / 2;
        v.select_nth_unstable_by(mid, f32::total_cmp);
        *o = v[mid];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera at `centre` looking at the origin, image-down along −z (world z up).
    fn looking_at_origin(centre: [f32; 3]) -> splat::Camera {
        let n = dist(centre, [0.0; 3]);
        let fwd = centre.map(|v| -v / n);
        let down0 = [0.0, 0.0, -1.0];
        // right = down × fwd; down = fwd × right (x right, y down, z forward).
        let cross = |a: [f32; 3], b: [f32; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let right = cross(down0, fwd);
        let rn = right.iter().map(|v| v * v).sum::<f32>().sqrt();
        let right = right.map(|v| v / rn);
        let down = cross(fwd, right);
        let r = [right, down, fwd];
        let t: [f32; 3] =
            std::array::from_fn(|i| -(0..3).map(|j| r[i][j] * centre[j]).sum::<f32>());
        let mut viewmat = [[0.0; 4]; 4];
        for ((row, ri), ti) in viewmat.iter_mut().zip(r).zip(t) {
            row[..3].copy_from_slice(&ri);
            row[3] = ti;
        }
        viewmat[3][3] = 1.0;
        splat::Camera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            viewmat,
        }
    }

    #[test]
    fn orbit_finds_the_point_the_cameras_look_at() {
        let cams: Vec<_> = [[4.0, 0.0, 1.0], [0.0, 4.0, 1.0], [-3.0, -3.0, 2.0]]
            .into_iter()
            .map(looking_at_origin)
            .collect();
        let o = orbit(&cams, [9.0; 3]);
        assert!(dist(o.target, [0.0; 3]) < 1e-4, "{o:?}");
        assert!(o.up[2] > 0.8, "up is +z: {o:?}");
        let parallel = vec![looking_at_origin([4.0, 0.0, 0.0]); 3];
        assert_eq!(orbit(&parallel, [9.0; 3]).target, [9.0; 3]);
    }

    #[test]
    fn quaternion_reproduces_the_rotation() {
        let c = looking_at_origin([1.0, 2.0, 3.0]);
        let m = transpose(&rotation(&c));
        let [x, y, z, w] = quaternion_xyzw(&m);
        // gsplat.js's Matrix3.RotationFromQuaternion is the standard formula, as ours.
        let back = train::quat::to_matrix([w, x, y, z]);
        for (bi, mi) in back.iter().zip(&m) {
            for (x, y) in bi.iter().zip(mi) {
                assert!((x - y).abs() < 1e-5, "{back:?} vs {m:?}");
            }
        }
    }

    #[test]
    fn median_ignores_a_floater() {
        let means = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 100.0, 100.0, 100.0];
        assert_eq!(median_centre(&means), [1.0, 1.0, 1.0]);
    }
}
