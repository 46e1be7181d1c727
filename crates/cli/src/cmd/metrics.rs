//! `semdynreg metrics A B`: PSNR, SSIM and LPIPS of image A against image B (A a render, B the
//! ground truth), or of every image in folder A against the same-named image in folder B,
//! with per-file values and their mean (the mean of per-image values, as 3DGS's
//! `metrics.py`). Optionally on a crop. Text table by default, JSON with `--json`.

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use metrics::{BBox, Lpips, LpipsNet, Scores, SsimVariant};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// PSNR, SSIM and LPIPS of images (or folders of images) against references.
#[derive(clap::Args)]
pub struct Args {
    /// Image (or folder of images) to score, e.g. renders.
    a: PathBuf,
    /// Reference image (or folder with the same file names), e.g. ground truth.
    b: PathBuf,
    /// LPIPS backbone [default: alex; skipped with a warning if its weights are absent].
    #[arg(long, value_enum)]
    lpips: Option<NetArg>,
    /// Skip LPIPS.
    #[arg(long, conflicts_with = "lpips")]
    no_lpips: bool,
    /// SSIM averaging: 3dgs (all pixels, zero padding; our tables) or skimage (5 px cropped).
    #[arg(long, value_enum, default_value = "3dgs")]
    ssim: SsimArg,
    /// Score only this box, `x,y,w,h` in pixels (grown to >= 32 px for LPIPS, see docs).
    #[arg(long, value_parser = parse_bbox)]
    crop: Option<BBox>,
    /// Print JSON instead of a table (PSNR of identical images is written as null).
    #[arg(long)]
    json: bool,
    /// Also write the JSON report to this file.
    #[arg(long)]
    output: Option<PathBuf>,
}

#[derive(Clone, Copy, ValueEnum)]
enum NetArg {
    Alex,
    Vgg,
}

#[derive(Clone, Copy, ValueEnum)]
enum SsimArg {
    #[value(name = "3dgs")]
    Gs3d,
    Skimage,
}

#[derive(Serialize)]
struct Row {
    name: String,
    /// The box actually scored (after clamping and growing), if cropping.
    #[serde(skip_serializing_if = "Option::is_none")]
    crop: Option<BBox>,
    #[serde(flatten)]
    scores: Scores,
}

#[derive(Serialize)]
struct Report {
    lpips_net: Option<&'static str>,
    ssim_variant: &'static str,
    results: Vec<Row>,
    mean: Scores,
}

fn parse_bbox(s: &str) -> Result<BBox, String> {
    let v: Vec<usize> = s
        .split(',')
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("crop '{s}': {e} (expected x,y,w,h in pixels)"))?;
    match v[..] {
        [x, y, w, h] if w > 0 && h > 0 => Ok(BBox { x, y, w, h }),
        _ => Err(format!("crop '{s}': expected x,y,w,h with w, h > 0")),
    }
}

pub fn run(args: Args) -> Result<()> {
    let model = load_model(&args)?;
    let pairs = list_pairs(&args.a, &args.b)?;
    let variant = match args.ssim {
        SsimArg::Gs3d => SsimVariant::Gs3d,
        SsimArg::Skimage => SsimVariant::Skimage,
    };
    let bar = progress(pairs.len());
    let mut results = Vec::with_capacity(pairs.len());
    for (name, pa, pb) in &pairs {
        bar.set_message(name.clone());
        results.push(score_pair(
            name,
            pa,
            pb,
            args.crop,
            variant,
            model.as_ref(),
        )?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let report = Report {
        lpips_net: model.as_ref().map(|m| match m.net() {
            LpipsNet::Alex => "alex",
            LpipsNet::Vgg => "vgg",
        }),
        ssim_variant: match variant {
            SsimVariant::Gs3d => "3dgs",
            SsimVariant::Skimage => "skimage",
        },
        mean: mean(&results),
        results,
    };
    let json = serde_json::to_string_pretty(&report)?;
    if let Some(path) = &args.output {
        write_atomic(path, json.as_bytes())?;
    }
    if args.json {
        println!("{json}");
    } else {
        print_table(&report);
    }
    Ok(())
}

fn load_model(args: &Args) -> Result<Option<Lpips>> {
    if args.no_lpips {
        return Ok(None);
    }
    let net = match args.lpips {
        Some(NetArg::Vgg) => LpipsNet::Vgg,
        _ => LpipsNet::Alex,
    };
    match Lpips::from_env(net) {
        Ok(m) => Ok(Some(m)),
        Err(e @ metrics::LpipsError::NotFound { .. }) if args.lpips.is_none() => {
            tracing::warn!("{e}; LPIPS skipped");
            Ok(None)
        }
        Err(e) => Err(e).context("loading LPIPS weights"),
    }
}

/// (name, A path, B path) for a pair of files or for matching names in two folders.
fn list_pairs(a: &Path, b: &Path) -> Result<Vec<(String, PathBuf, PathBuf)>> {
    match (a.is_dir(), b.is_dir()) {
        (false, false) => {
            let name = a.file_name().map(|n| n.to_string_lossy().into_owned());
            Ok(vec![(name.unwrap_or_default(), a.to_owned(), b.to_owned())])
        }
        (true, true) => {
            let mut pairs = Vec::new();
            for name in image_names(a)? {
                let pb = b.join(&name);
                if !pb.is_file() {
                    bail!(
                        "{} has no counterpart {}",
                        a.join(&name).display(),
                        pb.display()
                    );
                }
                pairs.push((name.clone(), a.join(&name), pb));
            }
            if pairs.is_empty() {
                bail!("no PNG/JPEG images in {}", a.display());
            }
            Ok(pairs)
        }
        _ => bail!(
            "{} and {} must both be files or both be folders",
            a.display(),
            b.display()
        ),
    }
}

fn image_names(dir: &Path) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let name = entry?.file_name().to_string_lossy().into_owned();
        let lower = name.to_ascii_lowercase();
        if [".png", ".jpg", ".jpeg"].iter().any(|e| lower.ends_with(e)) {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

fn score_pair(
    name: &str,
    pa: &Path,
    pb: &Path,
    crop: Option<BBox>,
    variant: SsimVariant,
    model: Option<&Lpips>,
) -> Result<Row> {
    let (ia, ib) = (metrics::load_rgb(pa)?, metrics::load_rgb(pb)?);
    if (ia.width, ia.height) != (ib.width, ib.height) {
        bail!(
            "{} is {}x{} but {} is {}x{}",
            pa.display(),
            ia.width,
            ia.height,
            pb.display(),
            ib.width,
            ib.height
        );
    }
    let ctx = || format!("scoring {} against {}", pa.display(), pb.display());
    let (w, h) = (ia.width, ia.height);
    let (crop, scores) = match crop {
        Some(bbox) => {
            let (used, s) = metrics::evaluate_crop(&ia.data, &ib.data, w, h, bbox, variant, model)
                .with_context(ctx)?;
            (Some(used), s)
        }
        None => (
            None,
            metrics::evaluate(&ia.data, &ib.data, w, h, variant, model).with_context(ctx)?,
        ),
    };
    Ok(Row {
        name: name.to_owned(),
        crop,
        scores,
    })
}

/// Mean of per-image values; PSNR's mean is +inf (JSON null) if any pair is identical.
fn mean(rows: &[Row]) -> Scores {
    let n = rows.len().max(1) as f64;
    let lpips: Option<Vec<f32>> = rows.iter().map(|r| r.scores.lpips).collect();
    Scores {
        psnr: rows.iter().map(|r| r.scores.psnr).sum::<f64>() / n,
        ssim: (rows.iter().map(|r| r.scores.ssim as f64).sum::<f64>() / n) as f32,
        lpips: lpips.map(|v| (v.iter().map(|&x| x as f64).sum::<f64>() / n) as f32),
    }
}

fn print_table(report: &Report) {
    let width = report
        .results
        .iter()
        .map(|r| r.name.len())
        .max()
        .unwrap_or(4)
        .max(4);
    println!(
        "{:<width$}  {:>8}  {:>7}  {:>7}",
        "name", "PSNR", "SSIM", "LPIPS"
    );
    let line = |name: &str, s: &Scores| {
        let lp = s.lpips.map_or("-".to_owned(), |v| format!("{v:.4}"));
        println!("{name:<width$}  {:>8.3}  {:>7.4}  {lp:>7}", s.psnr, s.ssim);
    };
    for r in &report.results {
        line(&r.name, &r.scores);
    }
    if report.results.len() > 1 {
        line("mean", &report.mean);
    }
}

fn progress(n: usize) -> ProgressBar {
    if n < 2 {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(n as u64);
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    bar
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming to {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, w: u32, h: u32, seed: u32) {
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let v = (x * 7 + y * 13 + seed * 31) % 256;
            image::Rgb([v as u8, (255 - v) as u8, ((v * 3) % 256) as u8])
        });
        img.save(path).unwrap();
    }

    fn args(a: &Path, b: &Path, crop: Option<BBox>, output: Option<PathBuf>) -> Args {
        Args {
            a: a.to_owned(),
            b: b.to_owned(),
            lpips: None,
            no_lpips: true,
            ssim: SsimArg::Gs3d,
            crop,
            json: false,
            output,
        }
    }

    #[test]
    fn folder_mode_scores_same_named_files_and_writes_json() {
        let dir = tempfile::tempdir().unwrap();
        let (ra, rb) = (dir.path().join("renders"), dir.path().join("gt"));
        std::fs::create_dir_all(&ra).unwrap();
        std::fs::create_dir_all(&rb).unwrap();
        // b.png identical in both folders, a.png differs; a non-image file is ignored.
        write_png(&ra.join("b.png"), 40, 36, 1);
        write_png(&rb.join("b.png"), 40, 36, 1);
        write_png(&ra.join("a.png"), 40, 36, 2);
        write_png(&rb.join("a.png"), 40, 36, 3);
        std::fs::write(ra.join("notes.txt"), "x").unwrap();
        let out = dir.path().join("report.json");
        run(args(&ra, &rb, None, Some(out.clone()))).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let res = v["results"].as_array().unwrap();
        assert_eq!(res.len(), 2);
        assert_eq!(
            (res[0]["name"].as_str(), res[1]["name"].as_str()),
            (Some("a.png"), Some("b.png"))
        );
        assert!(res[0]["psnr"].as_f64().unwrap().is_finite());
        assert!(res[0]["ssim"].as_f64().unwrap() < 0.99);
        // Identical pair: PSNR +inf → null, SSIM 1; the mean PSNR is then null too.
        assert!(res[1]["psnr"].is_null());
        assert!((res[1]["ssim"].as_f64().unwrap() - 1.0).abs() < 1e-6);
        assert!(v["mean"]["psnr"].is_null());
        assert!(v["lpips_net"].is_null() && res[0]["lpips"].is_null());
    }

    #[test]
    fn folder_mode_reports_a_missing_counterpart() {
        let dir = tempfile::tempdir().unwrap();
        let (ra, rb) = (dir.path().join("r"), dir.path().join("g"));
        std::fs::create_dir_all(&ra).unwrap();
        std::fs::create_dir_all(&rb).unwrap();
        write_png(&ra.join("only.png"), 8, 8, 0);
        let err = run(args(&ra, &rb, None, None)).unwrap_err().to_string();
        assert!(
            err.contains("only.png") && err.contains("no counterpart"),
            "{err}"
        );
        let err = run(args(&ra, &ra.join("only.png"), None, None)).unwrap_err();
        assert!(err.to_string().contains("both be files or both be folders"));
    }

    #[test]
    fn crop_is_parsed_grown_and_reported() {
        assert!(parse_bbox("1,2,0,4").is_err());
        assert!(parse_bbox("1,2,3").unwrap_err().contains("x,y,w,h"));
        let dir = tempfile::tempdir().unwrap();
        let (pa, pb) = (dir.path().join("a.png"), dir.path().join("b.png"));
        write_png(&pa, 64, 48, 4);
        write_png(&pb, 64, 48, 5);
        let out = dir.path().join("crop.json");
        let bbox = parse_bbox("10, 5, 8, 8").unwrap();
        run(args(&pa, &pb, Some(bbox), Some(out.clone()))).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let crop = &v["results"][0]["crop"];
        // An 8×8 box is grown to the 32×32 minimum, staying inside the 64×48 image.
        assert_eq!(
            (crop["w"].as_u64(), crop["h"].as_u64()),
            (Some(32), Some(32))
        );
        assert!(crop["y"].as_u64().unwrap() + 32 <= 48);
    }
}
