//! Test helpers: reading the reference cases (`tests/fixtures/reference/FORMAT.md`) and
//! comparing.
#![allow(dead_code)]

mod fixtures;
pub use fixtures::cases_dir;

use npyz::npz::NpzArchive;
use splat::{Camera, Colors, Gaussians, RenderOptions};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// An opened `.npz` whose arrays are read as f64 whatever their dtype.
pub struct Npz(NpzArchive<BufReader<File>>, PathBuf);

impl Npz {
    pub fn open(path: &Path) -> Self {
        let a = NpzArchive::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        Npz(a, path.to_path_buf())
    }

    pub fn get(&mut self, name: &str) -> Option<(Vec<f64>, Vec<u64>)> {
        let f = self.0.by_name(name).expect("npz read")?;
        let shape = f.shape().to_vec();
        let ty = f
            .dtype()
            .descr()
            .trim_matches(|c| c == '\'' || c == '"')
            .to_string();
        let v = match ty.as_str() {
            "<f8" => f.into_vec::<f64>().expect("f64"),
            "<f4" => f
                .into_vec::<f32>()
                .expect("f32")
                .into_iter()
                .map(f64::from)
                .collect(),
            "<i8" => f
                .into_vec::<i64>()
                .expect("i64")
                .into_iter()
                .map(|x| x as f64)
                .collect(),
            "<i4" => f
                .into_vec::<i32>()
                .expect("i32")
                .into_iter()
                .map(f64::from)
                .collect(),
            t => panic!("{}: {name} has dtype {t}", self.1.display()),
        };
        Some((v, shape))
    }

    pub fn req(&mut self, name: &str) -> Vec<f64> {
        let p = self.1.clone();
        self.get(name)
            .unwrap_or_else(|| panic!("{}: no {name}", p.display()))
            .0
    }

    pub fn scalar(&mut self, name: &str) -> f64 {
        self.req(name)[0]
    }
}

pub fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// A reference case: inputs as the rasterizer takes them, plus its expected outputs.
pub struct Case {
    pub name: String,
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub logits: Vec<f32>,
    pub colors: Vec<f32>,
    /// (K, degree) for SH, None for RGB.
    pub sh: Option<(usize, usize)>,
    pub cam: Camera,
    pub opts: RenderOptions,
    pub weights: Vec<f32>,
    pub alpha_weights: Option<Vec<f32>>,
}

impl Case {
    /// The case and its expected outputs.
    pub fn load(stem: &str) -> (Case, Npz) {
        let dir = cases_dir();
        let case = Case::from_npz(&dir.join(format!("{stem}.npz")));
        let expected = Npz::open(&dir.join(format!("{stem}.expected.npz")));
        (case, expected)
    }

    /// A scene in the reference cases' input format (FORMAT.md), expected outputs aside.
    pub fn from_npz(path: &Path) -> Case {
        let mut i = Npz::open(path);
        let (colors, sh) = match i.get("sh") {
            Some((v, shape)) => (
                f32s(&v),
                Some((shape[1] as usize, i.scalar("sh_degree") as usize)),
            ),
            None => (f32s(&i.req("colors")), None),
        };
        let vm = i.req("viewmat");
        let bg = i.req("background");
        let cam = Camera {
            width: i.scalar("width") as u32,
            height: i.scalar("height") as u32,
            fx: i.scalar("fx") as f32,
            fy: i.scalar("fy") as f32,
            cx: i.scalar("cx") as f32,
            cy: i.scalar("cy") as f32,
            viewmat: std::array::from_fn(|r| std::array::from_fn(|c| vm[4 * r + c] as f32)),
        };
        let opts = RenderOptions {
            background: [bg[0] as f32, bg[1] as f32, bg[2] as f32],
            topk: 0,
            eps2d: i.scalar("eps2d") as f32,
            near_plane: i.scalar("near_plane") as f32,
            ..RenderOptions::default()
        };
        Case {
            name: path
                .file_stem()
                .map_or(String::new(), |s| s.to_string_lossy().into_owned()),
            means: f32s(&i.req("means")),
            quats: f32s(&i.req("quats")),
            scales: i
                .req("log_scales")
                .iter()
                .map(|&l| l.exp() as f32)
                .collect(),
            logits: f32s(&i.req("opacity_logits")),
            colors,
            sh,
            cam,
            opts,
            weights: f32s(&i.req("weights")),
            alpha_weights: i.get("alpha_weights").map(|(v, _)| f32s(&v)),
        }
    }

    pub fn gaussians(&self) -> Gaussians<'_> {
        Gaussians {
            means: &self.means,
            quats: &self.quats,
            scales: &self.scales,
            opacity_logits: &self.logits,
            colors: match self.sh {
                Some((k, d)) => Colors::Sh {
                    coeffs: &self.colors,
                    num_coeffs: k,
                    degree: d,
                },
                None => Colors::Rgb(&self.colors),
            },
        }
    }
}

pub const CASES: [&str; 5] = [
    "01_tiny_sh3_offcentre_behind",
    "02_small_sh0",
    "03_medium_sh3",
    "04_clamp_sh1",
    "05_rgb_colors",
];

/// ‖a − b‖ / ‖b‖ (absolute when b is zero).
pub fn rel_l2(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    if den == 0.0 {
        num.sqrt()
    } else {
        (num / den).sqrt()
    }
}

/// A seeded random scene of `n` Gaussians 2–4 units in front of a slightly rotated camera.
pub struct Scene {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub logits: Vec<f32>,
    pub colors: Vec<f32>,
    pub sh: Option<(usize, usize)>,
    pub cam: Camera,
}

impl Scene {
    /// `sh_degree = None` gives RGB colours.
    pub fn random(seed: u64, n: usize, width: u32, height: u32, sh_degree: Option<usize>) -> Scene {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut u = |lo: f32, hi: f32| rng.gen_range(lo..hi);
        let (c, s) = (0.1f32.cos(), 0.1f32.sin());
        let cam = Camera {
            width,
            height,
            fx: width as f32 * 0.9,
            fy: width as f32 * 0.9,
            cx: width as f32 * 0.47,
            cy: height as f32 * 0.53,
            viewmat: [
                [c, 0.0, s, 0.1],
                [0.0, 1.0, 0.0, -0.05],
                [-s, 0.0, c, 0.2],
                [0.0, 0.0, 0.0, 1.0],
            ],
        };
        let mut means = Vec::new();
        let mut quats = Vec::new();
        let mut scales = Vec::new();
        let mut logits = Vec::new();
        for _ in 0..n {
            let z = u(2.0, 4.0);
            means.extend([u(-0.6, 0.6) * z, u(-0.5, 0.5) * z, z]);
            quats.extend([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
            scales.extend([u(0.03, 0.3), u(0.03, 0.3), u(0.03, 0.3)]);
            logits.push(u(-1.0, 2.5));
        }
        let (colors, sh) = match sh_degree {
            Some(d) => {
                let k = (d + 1) * (d + 1);
                let v = (0..n * k * 3).map(|_| u(-0.4, 0.4)).collect();
                (v, Some((k, d)))
            }
            None => ((0..n * 3).map(|_| u(0.0, 1.0)).collect(), None),
        };
        Scene {
            means,
            quats,
            scales,
            logits,
            colors,
            sh,
            cam,
        }
    }

    pub fn gaussians(&self) -> Gaussians<'_> {
        Gaussians {
            means: &self.means,
            quats: &self.quats,
            scales: &self.scales,
            opacity_logits: &self.logits,
            colors: match self.sh {
                Some((k, d)) => Colors::Sh {
                    coeffs: &self.colors,
                    num_coeffs: k,
                    degree: d,
                },
                None => Colors::Rgb(&self.colors),
            },
        }
    }
}
