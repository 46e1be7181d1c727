//! `semdynreg render-case IN.npz OUT.npz [--topk K] [--repeat R]`: renders a rasterizer
//! case (`crates/splat/tests/fixtures/reference/FORMAT.md`) with `splat`, takes the loss
//! `L = Σ image·weights (+ Σ alpha·alpha_weights)` and writes image, alpha, loss, every
//! gradient (named as FORMAT.md), optional top-k and the median timings, so that anyone
//! can compare our rasterizer with another implementation.

use crate::npz::{NpzReader, NpzWriter};
use anyhow::{bail, ensure, Context, Result};
use splat::{Camera, Colors, Gaussians, Gradients, Rasterizer, RenderOptions};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Render one rasterizer case (.npz) with its gradients, to compare with another renderer.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Input case (.npz with means, quats, log_scales, opacity_logits, sh/colors, camera, weights).
    pub input: PathBuf,
    /// Output archive (.npz), written atomically.
    pub output: PathBuf,
    /// Also record the per-pixel top-k contributors (ids int64, −1 where none; weights).
    #[arg(long, default_value_t = 0)]
    pub topk: usize,
    /// Run forward and backward R times; the timings written are medians.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
}

/// A case's inputs, converted to the rasterizer's f32 layouts.
struct Case {
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    logits: Vec<f32>,
    colors: Vec<f32>,
    /// (K, degree) for SH, None for RGB colours.
    sh: Option<(usize, usize)>,
    cam: Camera,
    opts: RenderOptions,
    weights: Vec<f64>,
    alpha_weights: Option<Vec<f64>>,
}

impl Case {
    fn gaussians(&self) -> Gaussians<'_> {
        Gaussians {
            means: &self.means,
            quats: &self.quats,
            scales: &self.scales,
            opacity_logits: &self.logits,
            colors: match self.sh {
                Some((k, degree)) => Colors::Sh {
                    coeffs: &self.colors,
                    num_coeffs: k,
                    degree,
                },
                None => Colors::Rgb(&self.colors),
            },
        }
    }
}

/// Reads arrays of an `.npz` as f64 with shape and finiteness checks naming file and key.
struct Reader {
    npz: NpzReader,
    path: PathBuf,
}

impl Reader {
    fn open(path: &Path) -> Result<Self> {
        let npz = NpzReader::open(path)
            .with_context(|| format!("{}: cannot open as .npz", path.display()))?;
        Ok(Reader {
            npz,
            path: path.to_path_buf(),
        })
    }

    /// The array `key` if present; `shape` entries of `None` are free dimensions.
    fn optional(
        &mut self,
        key: &str,
        shape: &[Option<usize>],
    ) -> Result<Option<(Vec<f64>, Vec<usize>)>> {
        let file = self.path.display().to_string();
        let Some(arr) = self
            .npz
            .by_name(key)
            .with_context(|| format!("{file}: cannot read key `{key}`"))?
        else {
            return Ok(None);
        };
        let got: Vec<usize> = arr.shape().iter().map(|&d| d as usize).collect();
        let fits = got.len() == shape.len()
            && got
                .iter()
                .zip(shape)
                .all(|(g, s)| s.is_none_or(|s| s == *g));
        if !fits {
            let want: Vec<String> = shape
                .iter()
                .map(|s| s.map_or("_".into(), |v| v.to_string()))
                .collect();
            bail!(
                "{file}: key `{key}` has shape {got:?}, expected ({})",
                want.join(", ")
            );
        }
        let descr = arr.dtype().descr();
        let descr = descr.trim_matches(|c| c == '\'' || c == '"');
        // A read error (data shorter than the header's shape) names the file and key too.
        let short = || format!("{file}: key `{key}`: cannot read its data");
        let data: Vec<f64> = match descr {
            "<f8" => arr.into_vec::<f64>().with_context(short)?,
            "<f4" => arr
                .into_vec::<f32>()
                .with_context(short)?
                .into_iter()
                .map(f64::from)
                .collect(),
            "<i8" => arr
                .into_vec::<i64>()
                .with_context(short)?
                .into_iter()
                .map(|v| v as f64)
                .collect(),
            "<i4" => arr
                .into_vec::<i32>()
                .with_context(short)?
                .into_iter()
                .map(f64::from)
                .collect(),
            other => bail!("{file}: key `{key}` has dtype {other}, expected float or int"),
        };
        if let Some(bad) = data.iter().position(|v| !v.is_finite()) {
            bail!(
                "{file}: key `{key}` has a non-finite value ({}) at flat index {bad}",
                data[bad]
            );
        }
        Ok(Some((data, got)))
    }

    fn required(&mut self, key: &str, shape: &[Option<usize>]) -> Result<(Vec<f64>, Vec<usize>)> {
        self.optional(key, shape)?
            .with_context(|| format!("{}: missing key `{key}`", self.path.display()))
    }

    fn scalar(&mut self, key: &str) -> Result<f64> {
        Ok(self.required(key, &[])?.0[0])
    }

    fn positive_int(&mut self, key: &str) -> Result<u32> {
        let v = self.scalar(key)?;
        ensure!(
            v >= 1.0 && v.fract() == 0.0 && v <= 65536.0,
            "{}: key `{key}` = {v} is not a positive integer image size",
            self.path.display()
        );
        Ok(v as u32)
    }
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

fn load_case(path: &Path) -> Result<Case> {
    let mut r = Reader::open(path)?;
    let (means, shape) = r.required("means", &[None, Some(3)])?;
    let n = shape[0];
    let (quats, _) = r.required("quats", &[Some(n), Some(4)])?;
    let (log_scales, _) = r.required("log_scales", &[Some(n), Some(3)])?;
    let (logits, _) = r.required("opacity_logits", &[Some(n)])?;
    let (colors, sh) = match r.optional("sh", &[Some(n), None, Some(3)])? {
        Some((c, s)) => {
            let d = r.scalar("sh_degree")?;
            ensure!(
                (0.0..=3.0).contains(&d) && d.fract() == 0.0 && s[1] >= (d as usize + 1).pow(2),
                "{}: key `sh_degree` = {d} does not fit `sh` with {} coefficients",
                path.display(),
                s[1]
            );
            (c, Some((s[1], d as usize)))
        }
        None => {
            let (c, _) = r
                .optional("colors", &[Some(n), Some(3)])?
                .with_context(|| format!("{}: missing key `sh` or `colors`", path.display()))?;
            (c, None)
        }
    };
    let (width, height) = (r.positive_int("width")?, r.positive_int("height")?);
    let (w, h) = (width as usize, height as usize);
    let (vm, _) = r.required("viewmat", &[Some(4), Some(4)])?;
    let (bg, _) = r.required("background", &[Some(3)])?;
    let (weights, _) = r.required("weights", &[Some(h), Some(w), Some(3)])?;
    let alpha_weights = r
        .optional("alpha_weights", &[Some(h), Some(w)])?
        .map(|(v, _)| v);
    let eps2d = r.optional("eps2d", &[])?.map_or(0.3, |(v, _)| v[0]);
    let near_plane = r.optional("near_plane", &[])?.map_or(0.01, |(v, _)| v[0]);
    let cam = Camera {
        width,
        height,
        fx: r.scalar("fx")? as f32,
        fy: r.scalar("fy")? as f32,
        cx: r.scalar("cx")? as f32,
        cy: r.scalar("cy")? as f32,
        viewmat: std::array::from_fn(|i| std::array::from_fn(|j| vm[4 * i + j] as f32)),
    };
    Ok(Case {
        means: f32s(&means),
        quats: f32s(&quats),
        scales: log_scales.iter().map(|&l| l.exp() as f32).collect(),
        logits: f32s(&logits),
        colors: f32s(&colors),
        sh,
        cam,
        opts: RenderOptions {
            background: [bg[0] as f32, bg[1] as f32, bg[2] as f32],
            topk: 0,
            eps2d: eps2d as f32,
            near_plane: near_plane as f32,
            // gsplat's binning, so that `n_isects` compares with gsplat's own (the image and
            // the gradients are the same with the default culling).
            cull: splat::Cull::Box3Sigma,
        },
        weights,
        alpha_weights,
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Everything written to the output archive.
struct Results {
    image: Vec<f64>,
    alpha: Vec<f64>,
    loss: f64,
    means2d: Vec<f64>,
    depths: Vec<f64>,
    radii: Vec<i32>,
    n_isects: i64,
    topk_ids: Vec<i64>,
    topk_weights: Vec<f64>,
    grads: Gradients,
    seconds_forward: f64,
    seconds_backward: f64,
}

fn render(case: &Case, topk: usize, repeat: u32) -> Result<Results> {
    let g = case.gaussians();
    let mut opts = case.opts.clone();
    opts.topk = topk;
    let mut rast = Rasterizer::new();
    let (mut tf, mut tb) = (Vec::new(), Vec::new());
    let mut grads = Gradients::default();
    let dl_dimage = f32s(&case.weights);
    let dl_dalpha = case.alpha_weights.as_deref().map(f32s);
    let mut res = None;
    for _ in 0..repeat {
        let t0 = Instant::now();
        let out = rast.forward(&g, &case.cam, &opts).context("forward pass")?;
        tf.push(t0.elapsed().as_secs_f64());
        let image: Vec<f64> = out.image.iter().map(|&v| v as f64).collect();
        let alpha: Vec<f64> = out.alpha.iter().map(|&v| v as f64).collect();
        let mut loss: f64 = image.iter().zip(&case.weights).map(|(a, b)| a * b).sum();
        if let Some(aw) = &case.alpha_weights {
            loss += alpha.iter().zip(aw).map(|(a, b)| a * b).sum::<f64>();
        }
        let partial = Results {
            image,
            alpha,
            loss,
            means2d: out
                .means2d
                .iter()
                .flat_map(|m| [m[0] as f64, m[1] as f64])
                .collect(),
            depths: out.depths.iter().map(|&d| d as f64).collect(),
            radii: out.radii.iter().flat_map(|r| *r).collect(),
            n_isects: out.n_isects as i64,
            topk_ids: out
                .topk_ids
                .iter()
                .map(|&i| if i == u32::MAX { -1 } else { i as i64 })
                .collect(),
            topk_weights: out.topk_weights.iter().map(|&w| w as f64).collect(),
            grads: Gradients::default(),
            seconds_forward: 0.0,
            seconds_backward: 0.0,
        };
        let t1 = Instant::now();
        rast.backward(
            &g,
            &case.cam,
            &opts,
            &dl_dimage,
            dl_dalpha.as_deref(),
            &mut grads,
        )
        .context("backward pass")?;
        tb.push(t1.elapsed().as_secs_f64());
        res = Some(partial);
    }
    let mut res = res.context("no run")?;
    res.grads = grads;
    res.seconds_forward = median(tf);
    res.seconds_backward = median(tb);
    Ok(res)
}

fn put(npz: &mut NpzWriter, key: &str, shape: &[usize], data: &[f64]) -> Result<()> {
    Ok(npz.put(key, shape, data.iter().copied())?)
}

fn put_int<T: npyz::AutoSerialize + Copy>(
    npz: &mut NpzWriter,
    key: &str,
    shape: &[usize],
    data: &[T],
) -> Result<()> {
    Ok(npz.put(key, shape, data.iter().copied())?)
}

fn write_results(path: &Path, case: &Case, topk: usize, r: &Results) -> Result<()> {
    let n = case.logits.len();
    let (h, w) = (case.cam.height as usize, case.cam.width as usize);
    let up = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
    let g = &r.grads;
    let grad_log_scales: Vec<f64> = g
        .scales
        .iter()
        .zip(&case.scales)
        .map(|(d, s)| (d * s) as f64)
        .collect();
    let mut npz = NpzWriter::create(path)?;
    put(&mut npz, "image", &[h, w, 3], &r.image)?;
    put(&mut npz, "alpha", &[h, w], &r.alpha)?;
    put(&mut npz, "loss", &[], &[r.loss])?;
    put(&mut npz, "grad_means", &[n, 3], &up(&g.means))?;
    put(&mut npz, "grad_quats", &[n, 4], &up(&g.quats))?;
    put(&mut npz, "grad_log_scales", &[n, 3], &grad_log_scales)?;
    put(
        &mut npz,
        "grad_opacity_logits",
        &[n],
        &up(&g.opacity_logits),
    )?;
    match case.sh {
        Some((k, _)) => put(&mut npz, "grad_sh", &[n, k, 3], &up(&g.colors))?,
        None => put(&mut npz, "grad_colors", &[n, 3], &up(&g.colors))?,
    }
    let m2: Vec<f64> = g
        .means2d
        .iter()
        .flat_map(|v| [v[0] as f64, v[1] as f64])
        .collect();
    put(&mut npz, "grad_means2d", &[n, 2], &m2)?;
    put(&mut npz, "means2d", &[n, 2], &r.means2d)?;
    put(&mut npz, "depths", &[n], &r.depths)?;
    put_int(&mut npz, "radii", &[n, 2], &r.radii)?;
    put_int(&mut npz, "n_isects", &[], &[r.n_isects])?;
    if topk > 0 {
        put_int(&mut npz, "topk_ids", &[h, w, topk], &r.topk_ids)?;
        put(&mut npz, "topk_weights", &[h, w, topk], &r.topk_weights)?;
    }
    put(&mut npz, "seconds_forward", &[], &[r.seconds_forward])?;
    put(&mut npz, "seconds_backward", &[], &[r.seconds_backward])?;
    npz.finish()?;
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    let case = load_case(&args.input)?;
    let res = render(&case, args.topk, args.repeat)
        .with_context(|| format!("rendering {}", args.input.display()))?;
    let mut tmp = args.output.clone().into_os_string();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    write_results(&tmp, &case, args.topk, &res)
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, &args.output)
        .with_context(|| format!("renaming {} to {}", tmp.display(), args.output.display()))?;
    tracing::info!(
        loss = res.loss,
        seconds_forward = res.seconds_forward,
        seconds_backward = res.seconds_backward,
        "wrote {}",
        args.output.display()
    );
    Ok(())
}
