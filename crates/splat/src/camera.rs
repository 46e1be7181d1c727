//! Pinhole camera in the project's conventions (docs/architecture.md, "Conventions"):
//! OpenCV axes (x right, y down, z forward), world-to-camera 4×4, intrinsics in pixels,
//! pixel (row i, col j) sampled at (j + 0.5, i + 0.5).

/// A pinhole camera. `viewmat` is world→camera, row-major, OpenCV axes.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// World-to-camera transform, row-major: `p_cam = viewmat · [p_world, 1]`.
    pub viewmat: [[f32; 4]; 4],
}

impl Camera {
    /// Camera centre in world coordinates: `-Rᵀ t` for `viewmat = [R | t]`.
    pub fn center(&self) -> [f32; 3] {
        let m = &self.viewmat;
        let t = [m[0][3], m[1][3], m[2][3]];
        let mut c = [0.0f32; 3];
        for (k, ck) in c.iter_mut().enumerate() {
            *ck = -(m[0][k] * t[0] + m[1][k] * t[1] + m[2][k] * t[2]);
        }
        c
    }

    /// World point to camera coordinates.
    pub fn to_camera(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.viewmat;
        let mut out = [0.0f32; 3];
        for (r, o) in out.iter_mut().enumerate() {
            *o = m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3];
        }
        out
    }

    /// World point to pixel coordinates (x = column, y = row, continuous; pixel centres at
    /// +0.5) and camera depth z. Returns `None` behind the near plane (z ≤ 0.01).
    pub fn project(&self, p: [f32; 3]) -> Option<([f32; 2], f32)> {
        let c = self.to_camera(p);
        if c[2] <= 0.01 {
            return None;
        }
        Some((
            [
                self.fx * c[0] / c[2] + self.cx,
                self.fy * c[1] / c[2] + self.cy,
            ],
            c[2],
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn center_inverts_translation() {
        // Rotation about y by 90°, then translation.
        let cam = Camera {
            width: 4,
            height: 4,
            fx: 1.0,
            fy: 1.0,
            cx: 2.0,
            cy: 2.0,
            viewmat: [
                [0.0, 0.0, -1.0, 1.0],
                [0.0, 1.0, 0.0, 2.0],
                [1.0, 0.0, 0.0, 3.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        };
        let c = cam.center();
        let pc = cam.to_camera(c);
        for v in pc {
            assert!(v.abs() < 1e-6, "{pc:?}");
        }
    }
}
