//! `semdynreg prepare INPUT --out SCENE`: a video or a folder of images → a scene the other
//! commands read (D-NeRF layout with per-frame times, `points3d.ply`, `prepare.json`),
//! with the cameras from COLMAP (docs/real-data.md).
//!
//! Stages: frames (ffmpeg for a video, the `image` crate for a folder) → COLMAP feature
//! extraction → matching (sequential by default: the frames are a sequence) → mapper →
//! undistortion when the camera model has distortion → the scene. Everything is written
//! into a hidden folder beside `--out` and renamed at the end, so a failure leaves nothing
//! under `--out`. Frames COLMAP does not register are listed in `prepare.json` with a
//! reason and left out of the scene.

use anyhow::{bail, Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use scene::colmap::{self, ColmapModel};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Make a scene from a video or a folder of images: frames, COLMAP poses, times.
#[derive(ClapArgs)]
pub struct Args {
    /// A video file (anything ffmpeg reads) or a folder of images (png, jpg, in file-name
    /// order).
    input: PathBuf,
    /// Scene folder to create (D-NeRF layout; refused if it exists and is not empty,
    /// unless --force).
    #[arg(long)]
    out: PathBuf,
    /// Frames per second taken from a video (default: every frame).
    #[arg(long)]
    fps: Option<f64>,
    /// Keep at most this many frames (the first ones).
    #[arg(long)]
    max_frames: Option<usize>,
    /// Shrink frames by this integer factor before anything else.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Feature matching: sequential (neighbours in frame order; video, ordered frames) or
    /// exhaustive (every pair; unordered photos, slower).
    #[arg(long, value_enum, default_value_t = Matcher::Sequential)]
    matcher: Matcher,
    /// Sequential matcher: how many following frames each frame is matched with.
    #[arg(long, default_value_t = 10)]
    overlap: usize,
    /// Sequential matcher: loop detection with this vocabulary tree file (COLMAP's
    /// `vocab_tree_*.bin`); off without it.
    #[arg(long, value_name = "FILE")]
    vocab_tree: Option<PathBuf>,
    /// COLMAP camera model (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, ...);
    /// models with distortion are undistorted before the scene is written.
    #[arg(long, default_value = "SIMPLE_RADIAL")]
    camera_model: String,
    /// Known intrinsics in --camera-model's parameter order (e.g. "f,cx,cy,k" for
    /// SIMPLE_RADIAL, "fx,fy,cx,cy" for PINHOLE), in pixels of the frames after
    /// --downscale; held fixed by COLMAP. Without it COLMAP estimates them, which a scene
    /// with little depth (a flat table seen from one side) leaves ambiguous.
    #[arg(long, value_name = "P1,P2,...")]
    camera_params: Option<String>,
    /// One camera (intrinsics) shared by all frames: true for one video or one phone;
    /// false for photos from several cameras.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    single_camera: bool,
    /// Folder of per-frame masks of what moves (hands, people, vehicles): COLMAP extracts
    /// features only where a mask is 255 (white), so the poses come from the static scene.
    /// The project's object-ID maps (255 = background, `segment`'s output) are such masks.
    /// Matched to the frames by file name, else in file-name order (then one per frame);
    /// resized to the frames (nearest).
    #[arg(long, value_name = "DIR")]
    masks: Option<PathBuf>,
    /// Hold out every N-th frame (frame k with k % N == 0) for evaluation; 0 = none.
    #[arg(long, default_value_t = 8)]
    holdout: usize,
    /// Threads for COLMAP (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Replace an existing --out.
    #[arg(long)]
    force: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
enum Matcher {
    Sequential,
    Exhaustive,
}

/// `--camera-params` checked against the model's parameter count, in COLMAP's form.
fn parse_camera_params(text: &str, model_id: usize) -> Result<String> {
    let (model, count) = colmap::CAMERA_MODELS[model_id];
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.iter().all(|x| x.is_finite()))
        .with_context(|| {
            format!("--camera-params {text}: not a comma-separated list of numbers")
        })?;
    if values.len() != count {
        bail!(
            "--camera-params {text}: {model} takes {count} parameters, {} given",
            values.len()
        );
    }
    Ok(values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(","))
}

/// One frame as extracted, before COLMAP.
struct Extracted {
    /// File stem under `frames/` (and later `images/`).
    stem: String,
    /// Where it came from (the source image, or `INPUT@pts_time`).
    source: String,
    time: f32,
}

#[derive(Serialize)]
struct FailedFrame {
    index: usize,
    file: String,
    reason: String,
}

#[derive(Serialize)]
struct PrepareReport {
    input: String,
    input_kind: &'static str,
    frames_extracted: usize,
    frames_registered: usize,
    failed: Vec<FailedFrame>,
    mean_reprojection_error_px: Option<f64>,
    points: usize,
    time_source: &'static str,
    train_frames: usize,
    test_frames: usize,
    holdout: usize,
    matcher: Matcher,
    camera_model: String,
    single_camera: bool,
    /// Whether the intrinsics were given (--camera-params) and held fixed.
    intrinsics_given: bool,
    /// The --masks folder, when features were restricted to the static scene.
    masks: Option<String>,
    undistorted: bool,
    /// Pinhole intrinsics of the written images (first camera), in pixels.
    camera: BTreeMap<&'static str, f64>,
    colmap_models: usize,
    colmap_version: String,
    seconds: BTreeMap<&'static str, f64>,
}

pub fn run(a: Args) -> Result<()> {
    let start = Instant::now();
    if a.downscale == 0 {
        bail!("--downscale must be ≥ 1");
    }
    if a.fps.is_some_and(|f| !(f.is_finite() && f > 0.0)) {
        bail!("--fps must be a number > 0");
    }
    let model_id = colmap::CAMERA_MODELS
        .iter()
        .position(|(n, _)| n.eq_ignore_ascii_case(&a.camera_model))
        .with_context(|| {
            let names: Vec<&str> = colmap::CAMERA_MODELS.iter().map(|m| m.0).collect();
            format!(
                "--camera-model {}: not a COLMAP camera model ({})",
                a.camera_model,
                names.join(", ")
            )
        })?;
    let camera_model = colmap::CAMERA_MODELS[model_id].0.to_string();
    let camera_params = a
        .camera_params
        .as_deref()
        .map(|p| parse_camera_params(p, model_id))
        .transpose()?;
    let is_video = if a.input.is_dir() {
        false
    } else if a.input.is_file() {
        true
    } else {
        bail!("{}: no such file or folder", a.input.display());
    };
    let folder_images = if is_video {
        Vec::new()
    } else {
        let imgs = list_images(&a.input)?;
        if imgs.is_empty() {
            bail!(
                "{}: the folder holds no images (png, jpg or jpeg)",
                a.input.display()
            );
        }
        imgs
    };
    if is_video {
        require_tool("ffmpeg", "ffmpeg")?;
    }
    require_tool("colmap", "colmap")?;
    check_out(&a.out, a.force)?;

    let parent = match a.out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    let name = a
        .out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".{name}.partial-"))
        .tempdir_in(&parent)
        .with_context(|| format!("creating a temporary folder in {}", parent.display()))?;
    let root = tmp.path();
    let work = root.join(".work");
    let frames_dir = work.join("frames");
    std::fs::create_dir_all(&frames_dir)?;
    let mut seconds = BTreeMap::new();

    // 1. Frames.
    let t0 = Instant::now();
    let bar = spinner("frames");
    let (frames, time_source) = if is_video {
        extract_video(&a, &frames_dir, &bar)?
    } else {
        (
            convert_folder(&a, &folder_images, &frames_dir, &bar)?,
            "frame order",
        )
    };
    bar.finish_with_message(format!("frames: {} extracted", frames.len()));
    seconds.insert("frames", t0.elapsed().as_secs_f64());
    tracing::info!(
        "{} frames from {} in {:.1} s",
        frames.len(),
        a.input.display(),
        t0.elapsed().as_secs_f64()
    );
    if frames.len() < 3 {
        bail!(
            "{}: only {} frame(s) could be read; structure from motion needs at least 3",
            a.input.display(),
            frames.len()
        );
    }

    // 2. COLMAP.
    let mask_dir = work.join("masks");
    if let Some(m) = &a.masks {
        write_colmap_masks(m, &frames, &frames_dir, &mask_dir)?;
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1)
        .to_string();
    let db = work.join("database.db");
    let logs = work.join("logs");
    std::fs::create_dir_all(&logs)?;
    let n = frames.len() as u64;
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let t0 = Instant::now();
    let mut fe_args: Vec<String> = [
        "feature_extractor",
        "--database_path",
        &s(&db),
        "--image_path",
        &s(&frames_dir),
        "--ImageReader.camera_model",
        &camera_model,
        "--ImageReader.single_camera",
        if a.single_camera { "1" } else { "0" },
        "--SiftExtraction.use_gpu",
        "0",
        "--SiftExtraction.num_threads",
        &threads,
    ]
    .map(String::from)
    .to_vec();
    if let Some(p) = &camera_params {
        fe_args.extend(["--ImageReader.camera_params".into(), p.clone()]);
    }
    if a.masks.is_some() {
        fe_args.extend(["--ImageReader.mask_path".into(), s(&mask_dir)]);
    }
    let fe_args: Vec<&str> = fe_args.iter().map(String::as_str).collect();
    let fe_log = colmap_stage("features", &logs, n, &fe_args, "Processed file [")?;
    seconds.insert("colmap_features", t0.elapsed().as_secs_f64());
    let t0 = Instant::now();
    let mut match_args: Vec<String> = match a.matcher {
        Matcher::Sequential => vec![
            "sequential_matcher".into(),
            "--SequentialMatching.overlap".into(),
            a.overlap.max(1).to_string(),
            "--SequentialMatching.loop_detection".into(),
            if a.vocab_tree.is_some() { "1" } else { "0" }.into(),
        ],
        Matcher::Exhaustive => vec!["exhaustive_matcher".into()],
    };
    if let (Matcher::Sequential, Some(v)) = (a.matcher, &a.vocab_tree) {
        match_args.extend(["--SequentialMatching.vocab_tree_path".into(), s(v)]);
    }
    match_args.extend([
        "--database_path".into(),
        s(&db),
        "--SiftMatching.use_gpu".into(),
        "0".into(),
        "--SiftMatching.num_threads".into(),
        threads.clone(),
    ]);
    let margs: Vec<&str> = match_args.iter().map(String::as_str).collect();
    colmap_stage("matching", &logs, n, &margs, "Matching image [")?;
    seconds.insert("colmap_matching", t0.elapsed().as_secs_f64());
    let t0 = Instant::now();
    let sparse = work.join("sparse");
    std::fs::create_dir_all(&sparse)?;
    colmap_stage(
        "mapper",
        &logs,
        n,
        &[
            "mapper",
            "--database_path",
            &s(&db),
            "--image_path",
            &s(&frames_dir),
            "--output_path",
            &s(&sparse),
            "--Mapper.num_threads",
            &threads,
            // Given intrinsics stay as given.
            "--Mapper.ba_refine_focal_length",
            if camera_params.is_some() { "0" } else { "1" },
            "--Mapper.ba_refine_extra_params",
            if camera_params.is_some() { "0" } else { "1" },
        ],
        "Registering image #",
    )
    .with_context(|| {
        format!(
            "COLMAP could not register the sequence {}",
            a.input.display()
        )
    })?;
    seconds.insert("colmap_mapper", t0.elapsed().as_secs_f64());
    let models = read_models(&sparse)?;
    let Some((best_dir, best)) = models
        .iter()
        .max_by_key(|(_, m)| m.images.len())
        .map(|(d, m)| (d.clone(), m.clone()))
    else {
        bail!(
            "COLMAP could not register the sequence {}: the mapper found no initial pair of \
             frames to start from (too little texture, too little camera motion, or frames \
             that do not overlap); see the mapper's log:\n{}",
            a.input.display(),
            tail(&logs.join("mapper.log"), 12)
        );
    };
    if best.images.len() < 3 {
        bail!(
            "COLMAP could not register the sequence {}: only {} of {} frames in its largest model",
            a.input.display(),
            best.images.len(),
            frames.len()
        );
    }
    let distorted = best.cameras.values().any(|c| c.has_distortion());
    let (model, image_dir) = if distorted {
        let t0 = Instant::now();
        let dense = work.join("dense");
        colmap_stage(
            "undistort",
            &logs,
            best.images.len() as u64,
            &[
                "image_undistorter",
                "--image_path",
                &s(&frames_dir),
                "--input_path",
                &s(&best_dir),
                "--output_path",
                &s(&dense),
                "--output_type",
                "COLMAP",
            ],
            "Undistorting image [",
        )?;
        seconds.insert("colmap_undistort", t0.elapsed().as_secs_f64());
        let m = colmap::read_model(&dense.join("sparse"))
            .context("reading COLMAP's undistorted model")?;
        (m, dense.join("images"))
    } else {
        (best.clone(), frames_dir.clone())
    };

    // 3. The scene.
    let t0 = Instant::now();
    let features = feature_counts(&fe_log);
    let by_name: HashMap<&str, &colmap::ColmapImage> =
        model.images.iter().map(|i| (i.name.as_str(), i)).collect();
    let mut failed = Vec::new();
    let mut registered = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        let file = format!("{}.png", f.stem);
        match by_name.get(file.as_str()) {
            Some(img) => registered.push((k, f, *img)),
            None => {
                let other = models
                    .iter()
                    .find(|(d, m)| *d != best_dir && m.images.iter().any(|i| i.name == file));
                let reason = match (other, features.get(&file)) {
                    (Some((d, m)), _) => format!(
                        "registered only in a separate COLMAP model ({}, {} frames) that does \
                         not connect to the main one",
                        d.file_name().unwrap_or_default().to_string_lossy(),
                        m.images.len()
                    ),
                    (None, Some(&c)) if c < 100 => format!(
                        "not registered: only {c} SIFT features (blurred, dark or textureless?)"
                    ),
                    (None, Some(&c)) => format!(
                        "not registered by COLMAP's mapper ({c} SIFT features, too few matched \
                         with its neighbours)"
                    ),
                    (None, None) => "not registered by COLMAP's mapper".to_string(),
                };
                tracing::warn!("frame {k} ({}): {reason}", f.source);
                failed.push(FailedFrame {
                    index: k,
                    file: f.source.clone(),
                    reason,
                });
            }
        }
    }
    let images_out = root.join("images");
    std::fs::create_dir_all(&images_out)?;
    registered.par_iter().try_for_each(|(_, f, img)| {
        let from = image_dir.join(&img.name);
        let to = images_out.join(format!("{}.png", f.stem));
        std::fs::rename(&from, &to)
            .or_else(|_| std::fs::copy(&from, &to).map(|_| ()))
            .with_context(|| format!("moving {} to {}", from.display(), to.display()))
    })?;
    let (train, test) = write_transforms(root, &model, &registered, a.holdout)?;
    let (points, colors) = colmap::points_of(&model);
    let points = points.unwrap_or_default();
    if points.is_empty() {
        bail!("COLMAP's model has no 3D points: nothing to start the Gaussians from");
    }
    scene::write_ply_points_rgb(&root.join("points3d.ply"), &points, colors.as_deref())?;
    let kept = root.join("colmap");
    colmap::write_model(
        &model,
        &kept.join("sparse").join("0"),
        colmap::ModelFormat::Binary,
    )?;
    std::fs::rename(&logs, kept.join("logs")).context("keeping COLMAP's logs")?;
    let cam0 = model
        .cameras
        .values()
        .next()
        .map(|c| c.pinhole())
        .unwrap_or_default();
    let cam_size = model
        .cameras
        .values()
        .next()
        .map(|c| (c.width, c.height))
        .unwrap_or_default();
    seconds.insert("scene", t0.elapsed().as_secs_f64());
    seconds.insert("total", start.elapsed().as_secs_f64());
    let report = PrepareReport {
        input: a.input.display().to_string(),
        input_kind: if is_video { "video" } else { "images" },
        frames_extracted: frames.len(),
        frames_registered: registered.len(),
        failed,
        mean_reprojection_error_px: model.mean_reprojection_error(),
        points: points.len(),
        time_source,
        train_frames: train,
        test_frames: test,
        holdout: a.holdout,
        matcher: a.matcher,
        camera_model: camera_model.clone(),
        single_camera: a.single_camera,
        intrinsics_given: camera_params.is_some(),
        masks: a.masks.as_ref().map(|m| m.display().to_string()),
        undistorted: distorted,
        camera: BTreeMap::from([
            ("fx", cam0[0]),
            ("fy", cam0[1]),
            ("cx", cam0[2]),
            ("cy", cam0[3]),
            ("width", cam_size.0 as f64),
            ("height", cam_size.1 as f64),
        ]),
        colmap_models: models.len(),
        colmap_version: colmap_version(),
        seconds,
    };
    scene::io::write_json(&root.join("prepare.json"), &report)?;
    std::fs::remove_dir_all(&work).with_context(|| format!("removing {}", work.display()))?;
    finish_out(tmp, &a.out)?;
    eprintln!(
        "{}: {}/{} frames registered ({} train, {} held out), mean reprojection error {}, {} points, {:.0} s",
        a.out.display(),
        report.frames_registered,
        report.frames_extracted,
        train,
        test,
        report
            .mean_reprojection_error_px
            .map_or("n/a".into(), |e| format!("{e:.3} px")),
        report.points,
        start.elapsed().as_secs_f64()
    );
    for f in &report.failed {
        eprintln!("  left out: frame {} ({}): {}", f.index, f.file, f.reason);
    }
    Ok(())
}

/// `name` on PATH, or one error saying how to install it.
fn require_tool(name: &str, package: &str) -> Result<()> {
    if find_on_path(name).is_some() {
        return Ok(());
    }
    bail!(
        "`{name}` was not found on PATH; `semdynreg prepare` needs it. Install it with \
         `apt-get install {package}` (Debian/Ubuntu; other systems: see docs/real-data.md)"
    )
}

fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// `--out` must not exist, be an empty folder, or be replaced with --force.
fn check_out(out: &Path, force: bool) -> Result<()> {
    if !out.exists() || force {
        return Ok(());
    }
    let empty = out.is_dir() && std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_none());
    if !empty {
        bail!(
            "{} already exists and is not empty: choose another --out, or --force to replace it",
            out.display()
        );
    }
    Ok(())
}

/// Renames the finished temporary folder to `out` (replacing an old one only now).
fn finish_out(tmp: tempfile::TempDir, out: &Path) -> Result<()> {
    let path = tmp.keep();
    let old = if out.exists() {
        let aside = path.with_extension("old");
        std::fs::rename(out, &aside)
            .with_context(|| format!("moving the old {} aside", out.display()))?;
        Some(aside)
    } else {
        None
    };
    if let Err(e) = std::fs::rename(&path, out) {
        let _ = std::fs::remove_dir_all(&path);
        if let Some(old) = &old {
            let _ = std::fs::rename(old, out);
        }
        return Err(e).with_context(|| format!("renaming the finished scene to {}", out.display()));
    }
    if let Some(old) = old {
        let _ = std::fs::remove_dir_all(old);
    }
    Ok(())
}

fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let p = e?.path();
        let ext = p
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if p.is_file() && matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg")) {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

fn spinner(stage: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(stage.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}

fn stage_bar(stage: &str, total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{msg:10} [{bar:40}] {pos}/{len} {elapsed} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(stage.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(500));
    bar
}

/// Frames of a video with ffmpeg: `frames/NNNNN.png`, times from the frames' presentation
/// timestamps (ffmpeg's `showinfo` filter), else their order.
fn extract_video(
    a: &Args,
    frames_dir: &Path,
    bar: &ProgressBar,
) -> Result<(Vec<Extracted>, &'static str)> {
    let mut filters = Vec::new();
    if let Some(f) = a.fps {
        filters.push(format!("fps={f}"));
    }
    if a.downscale > 1 {
        filters.push(format!(
            "scale=trunc(iw/{d}):trunc(ih/{d}):flags=area",
            d = a.downscale
        ));
    }
    filters.push("showinfo".into());
    let mut cmd = Command::new("ffmpeg");
    cmd.args(["-nostdin", "-hide_banner", "-loglevel", "info", "-i"])
        .arg(&a.input)
        .args([
            "-map",
            "0:v:0",
            "-vf",
            &filters.join(","),
            "-vsync",
            "passthrough",
        ]);
    if let Some(m) = a.max_frames {
        cmd.args(["-frames:v", &m.max(1).to_string()]);
    }
    cmd.args(["-start_number", "0"])
        .arg(frames_dir.join("%05d.png"));
    bar.set_message("frames (ffmpeg)");
    let out = cmd
        .stdin(Stdio::null())
        .output()
        .context("running ffmpeg")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    let mut names: Vec<String> = std::fs::read_dir(frames_dir)?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png"))
        .collect();
    names.sort();
    if !out.status.success() || names.is_empty() {
        let last: Vec<&str> = stderr
            .lines()
            .filter(|l| !l.contains("Parsed_showinfo"))
            .collect();
        let last = last[last.len().saturating_sub(6)..].join("\n");
        bail!(
            "ffmpeg could not read video frames from {} ({}):\n{last}",
            a.input.display(),
            if out.status.success() {
                "no frame decoded".to_string()
            } else {
                out.status.to_string()
            }
        );
    }
    let mut pts: Vec<f64> = stderr
        .lines()
        .filter(|l| l.contains("Parsed_showinfo") && l.contains(" n:"))
        .filter_map(|l| {
            let v = l.split("pts_time:").nth(1)?.split_whitespace().next()?;
            v.parse().ok()
        })
        .collect();
    let n = names.len();
    // showinfo may have seen a frame more than was written (--max-frames).
    pts.truncate(n);
    let monotone = pts.len() == n && pts.windows(2).all(|w| w[1] > w[0]);
    let (times, source): (Vec<f32>, &'static str) = if monotone && n > 1 {
        let (p0, p1) = (pts[0], pts[n - 1]);
        (
            pts.iter().map(|p| ((p - p0) / (p1 - p0)) as f32).collect(),
            "video timestamps",
        )
    } else {
        (
            (0..n)
                .map(|k| {
                    if n > 1 {
                        k as f32 / (n - 1) as f32
                    } else {
                        0.0
                    }
                })
                .collect(),
            "frame order",
        )
    };
    let frames = names
        .iter()
        .enumerate()
        .map(|(k, name)| Extracted {
            stem: name.trim_end_matches(".png").to_string(),
            source: match pts.get(k) {
                Some(p) if monotone => format!("{}@{p:.3}s", a.input.display()),
                _ => format!("{}#{k}", a.input.display()),
            },
            time: times[k],
        })
        .collect();
    Ok((frames, source))
}

/// `--masks`: one mask per frame, as COLMAP reads them (`<frame file>.png` in `out`, 0 = no
/// features): 255 stays 255, every other value (an object) becomes 0.
fn write_colmap_masks(
    masks: &Path,
    frames: &[Extracted],
    frames_dir: &Path,
    out: &Path,
) -> Result<()> {
    if !masks.is_dir() {
        bail!("--masks {}: not a folder", masks.display());
    }
    let files = list_images(masks)?;
    let by_stem: HashMap<String, &PathBuf> = files
        .iter()
        .map(|p| {
            (
                p.file_stem()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned(),
                p,
            )
        })
        .collect();
    let chosen: Vec<&PathBuf> = if frames.iter().all(|f| by_stem.contains_key(&f.stem)) {
        frames.iter().map(|f| by_stem[&f.stem]).collect()
    } else if files.len() == frames.len() {
        files.iter().collect()
    } else {
        bail!(
            "--masks {}: {} mask images for {} frames, and their names do not match the \
             frames' ({}…); give one mask per frame",
            masks.display(),
            files.len(),
            frames.len(),
            frames[0].stem
        );
    };
    std::fs::create_dir_all(out)?;
    frames.par_iter().zip(chosen).try_for_each(|(f, path)| {
        let frame = frames_dir.join(format!("{}.png", f.stem));
        let (w, h) = image::image_dimensions(&frame)
            .with_context(|| format!("reading {}", frame.display()))?;
        let m = scene::load_mask(path)
            .with_context(|| format!("reading the mask {}", path.display()))?;
        let keep = image::GrayImage::from_fn(w, h, |x, y| {
            let mx = (u64::from(x) * u64::from(m.width) / u64::from(w)) as u32;
            let my = (u64::from(y) * u64::from(m.height) / u64::from(h)) as u32;
            let v = m.data[(my * m.width + mx) as usize];
            image::Luma([if v == scene::MASK_BACKGROUND { 255 } else { 0 }])
        });
        let to = out.join(format!("{}.png.png", f.stem));
        keep.save(&to)
            .with_context(|| format!("writing {}", to.display()))
    })
}

/// A folder of images → `frames/<stem>.png` (decoded, downscaled), times from their order.
fn convert_folder(
    a: &Args,
    images: &[PathBuf],
    frames_dir: &Path,
    bar: &ProgressBar,
) -> Result<Vec<Extracted>> {
    let images = &images[..a.max_frames.map_or(images.len(), |m| m.min(images.len()))];
    let mut seen = HashMap::new();
    for p in images {
        let stem = p
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        if let Some(other) = seen.insert(stem.clone(), p) {
            bail!(
                "{} and {} have the same name without extension; rename one",
                other.display(),
                p.display()
            );
        }
    }
    bar.set_message("frames (decoding images)");
    let n = images.len();
    images
        .par_iter()
        .enumerate()
        .map(|(k, p)| {
            let img = scene::ImageU8::load(p, [0.0; 3])
                .with_context(|| format!("reading the image {}", p.display()))?
                .downscale(a.downscale);
            if img.width < 8 || img.height < 8 {
                bail!(
                    "{}: smaller than 8×8 after --downscale {}",
                    p.display(),
                    a.downscale
                );
            }
            let stem = p
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let buf = image::RgbImage::from_raw(img.width, img.height, img.data)
                .context("image buffer")?;
            let to = frames_dir.join(format!("{stem}.png"));
            buf.save(&to)
                .with_context(|| format!("writing {}", to.display()))?;
            Ok(Extracted {
                stem,
                source: p.display().to_string(),
                time: if n > 1 {
                    k as f32 / (n - 1) as f32
                } else {
                    0.0
                },
            })
        })
        .collect()
}

/// Runs one COLMAP command with a progress bar fed by the log lines that start with
/// `progress` (`... [i/n]` or a count of such lines); its output goes to
/// `logs/<stage>.log`. Returns the log text.
fn colmap_stage(
    stage: &str,
    logs: &Path,
    total: u64,
    args: &[&str],
    progress: &'static str,
) -> Result<String> {
    let bar = stage_bar(stage, total);
    let t0 = Instant::now();
    let mut child = Command::new("colmap")
        .args(args)
        .env("QT_QPA_PLATFORM", "offscreen")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting `colmap {}`", args[0]))?;
    let lines = Arc::new(Mutex::new(Vec::<String>::new()));
    let count = Arc::new(Mutex::new(0u64));
    let readers: Vec<_> = [
        child
            .stdout
            .take()
            .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        child
            .stderr
            .take()
            .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
    ]
    .into_iter()
    .flatten()
    .map(|r| {
        let (lines, count, bar) = (lines.clone(), count.clone(), bar.clone());
        std::thread::spawn(move || {
            for line in BufReader::new(r).lines().map_while(Result::ok) {
                if line.trim_start().starts_with(progress) {
                    let mut c = count.lock().unwrap_or_else(|e| e.into_inner());
                    *c += 1;
                    bar.set_position(*c);
                }
                lines.lock().unwrap_or_else(|e| e.into_inner()).push(line);
            }
        })
    })
    .collect();
    let status = child
        .wait()
        .with_context(|| format!("waiting for `colmap {}`", args[0]))?;
    for r in readers {
        let _ = r.join();
    }
    let text = lines.lock().unwrap_or_else(|e| e.into_inner()).join("\n");
    let log = logs.join(format!("{stage}.log"));
    std::fs::write(&log, format!("$ colmap {}\n{text}\n", args.join(" ")))
        .with_context(|| format!("writing {}", log.display()))?;
    bar.finish_and_clear();
    tracing::info!(
        "COLMAP {stage} ({}) in {:.1} s",
        args[0],
        t0.elapsed().as_secs_f64()
    );
    if !status.success() {
        let all: Vec<&str> = text.lines().collect();
        bail!(
            "COLMAP {stage} (`colmap {}`) failed ({status}):\n{}",
            args[0],
            all[all.len().saturating_sub(12)..].join("\n")
        );
    }
    Ok(text)
}

fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// Every model the mapper wrote (`sparse/0`, `sparse/1`, ...).
fn read_models(sparse: &Path) -> Result<Vec<(PathBuf, ColmapModel)>> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(sparse)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| colmap::model_format(p).is_some())
        .collect();
    dirs.sort();
    dirs.into_iter()
        .map(|d| {
            let m = colmap::read_model(&d)
                .with_context(|| format!("reading COLMAP's model {}", d.display()))?;
            Ok((d, m))
        })
        .collect()
}

/// `Name:` / `Features:` pairs of the feature extractor's log.
fn feature_counts(log: &str) -> HashMap<String, usize> {
    let mut out = HashMap::new();
    let mut name = None;
    for l in log.lines() {
        let l = l.trim();
        if let Some(n) = l.strip_prefix("Name:") {
            name = Some(n.trim().to_string());
        } else if let (Some(c), Some(n)) = (l.strip_prefix("Features:"), &name) {
            if let Ok(c) = c.trim().parse() {
                out.insert(n.clone(), c);
            }
        }
    }
    out
}

fn colmap_version() -> String {
    Command::new("colmap")
        .arg("-h")
        .env("QT_QPA_PLATFORM", "offscreen")
        .output()
        .ok()
        .and_then(|o| {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .find(|l| l.starts_with("COLMAP"))
                .map(|l| l.split(" -- ").next().unwrap_or(l).trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// `transforms_train.json` and `transforms_test.json` (D-NeRF layout, read by
/// `scene::load_dataset`): camera-to-world in OpenGL axes, per-frame `time`, intrinsics at
/// the top level when one camera, else per frame. Returns (train, test) counts.
fn write_transforms(
    root: &Path,
    model: &ColmapModel,
    registered: &[(usize, &Extracted, &colmap::ColmapImage)],
    holdout: usize,
) -> Result<(usize, usize)> {
    let single = model.cameras.len() == 1;
    let intr = |cam: &colmap::ColmapCamera| {
        let [fx, fy, cx, cy] = cam.pinhole();
        serde_json::json!({"fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy})
    };
    let mut splits: [Vec<serde_json::Value>; 2] = [Vec::new(), Vec::new()];
    for (k, f, img) in registered {
        let v = img.viewmat();
        let mut c2w = scene::math::invert(&v).context("a COLMAP pose is singular")?;
        // OpenCV (x right, y down, z forward) → OpenGL (x right, y up, z backward) columns.
        for row in c2w.iter_mut().take(3) {
            row[1] = -row[1];
            row[2] = -row[2];
        }
        let mut frame = serde_json::json!({
            "file_path": format!("./images/{}", f.stem),
            "time": f.time,
            "transform_matrix": c2w,
        });
        if !single {
            let cam = &model.cameras[&img.camera_id];
            if let (Some(o), serde_json::Value::Object(i)) = (frame.as_object_mut(), intr(cam)) {
                o.extend(i);
            }
        }
        let test = holdout > 0 && k % holdout == 0;
        splits[usize::from(test)].push(frame);
    }
    if splits[0].is_empty() {
        bail!("every registered frame is held out (--holdout {holdout}): nothing left to train on");
    }
    let counts = (splits[0].len(), splits[1].len());
    for (name, frames) in ["train", "test"].into_iter().zip(splits) {
        if frames.is_empty() {
            continue;
        }
        let mut top = serde_json::json!({ "frames": frames });
        if single {
            let cam = model.cameras.values().next().context("no camera")?;
            let o = top.as_object_mut().context("json")?;
            if let serde_json::Value::Object(i) = intr(cam) {
                o.extend(i);
            }
            let fx = cam.pinhole()[0];
            o.insert(
                "camera_angle_x".into(),
                serde_json::json!(2.0 * (0.5 * cam.width as f64 / fx).atan()),
            );
            o.insert("w".into(), serde_json::json!(cam.width));
            o.insert("h".into(), serde_json::json!(cam.height));
        }
        scene::io::write_json(&root.join(format!("transforms_{name}.json")), &top)?;
    }
    Ok(counts)
}
