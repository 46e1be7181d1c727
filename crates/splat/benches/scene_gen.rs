//! Seeded benchmark scenes (shared by `benches/raster.rs` and `examples/raster_probe.rs`):
//! Gaussians uniform in the box [−1.3, 1.3]³ (the 3DGS/Deformable-3DGS synthetic init
//! volume) seen from 4 units away with a 50° horizontal field of view, scales log-uniform
//! in [0.004, 0.03] (≈ trained synthetic scenes), opacity logits in [−2, 3], SH degree 3.

use rand::{Rng, SeedableRng};
use splat::{Camera, Colors, Gaussians};

pub struct BenchScene {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub logits: Vec<f32>,
    pub sh: Vec<f32>,
    pub cam: Camera,
}

impl BenchScene {
    pub fn new(seed: u64, n: usize, width: u32, height: u32) -> Self {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut s = BenchScene {
            means: Vec::with_capacity(n * 3),
            quats: Vec::with_capacity(n * 4),
            scales: Vec::with_capacity(n * 3),
            logits: Vec::with_capacity(n),
            sh: Vec::with_capacity(n * 48),
            cam: camera(width, height),
        };
        let (lo, hi) = (0.004f32.ln(), 0.03f32.ln());
        for _ in 0..n {
            for _ in 0..3 {
                s.means.push(rng.gen_range(-1.3..1.3));
                s.scales.push(rng.gen_range(lo..hi).exp());
            }
            for _ in 0..4 {
                s.quats.push(rng.gen_range(-1.0..1.0));
            }
            s.logits.push(rng.gen_range(-2.0..3.0));
            for k in 0..48 {
                let amp = if k < 3 { 1.0 } else { 0.2 };
                s.sh.push(rng.gen_range(-amp..amp));
            }
        }
        s
    }

    pub fn gaussians(&self) -> Gaussians<'_> {
        Gaussians {
            means: &self.means,
            quats: &self.quats,
            scales: &self.scales,
            opacity_logits: &self.logits,
            colors: Colors::Sh {
                coeffs: &self.sh,
                num_coeffs: 16,
                degree: 3,
            },
        }
    }
}

/// Camera at (0, 0, −4) looking at the origin (+z), OpenCV axes.
fn camera(width: u32, height: u32) -> Camera {
    let fx = 0.5 * width as f32 / (25.0f32.to_radians()).tan();
    Camera {
        width,
        height,
        fx,
        fy: fx,
        cx: width as f32 / 2.0,
        cy: height as f32 / 2.0,
        viewmat: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 4.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}
