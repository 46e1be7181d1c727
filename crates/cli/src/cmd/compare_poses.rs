//! `semdynreg compare-poses --reference REF SCENE`: how far a scene's cameras (e.g. from
//! `prepare`) are from a reference set (ground truth, or another reconstruction), after the
//! similarity that best aligns their camera centres (`scene::align`; structure from motion
//! fixes poses only up to one). Both are any scene layout `scene::load_dataset` reads.

use anyhow::{bail, Context, Result};
use clap::Args as ClapArgs;
use scene::{Frame, LoadOptions};
use std::path::PathBuf;

/// Compare a scene's cameras with a reference's after a similarity alignment.
#[derive(ClapArgs)]
pub struct Args {
    /// The scene whose cameras are measured.
    scene: PathBuf,
    /// The reference scene (same frames).
    #[arg(long)]
    reference: PathBuf,
    /// Write the numbers (per frame too) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Fail (exit status 1) when the largest centre error exceeds this fraction of the
    /// reference's scene extent ...
    #[arg(long)]
    max_centre: Option<f64>,
    /// ... or the median rotation error exceeds this many degrees.
    #[arg(long)]
    max_rotation_deg: Option<f64>,
}

/// Frames of both scenes paired: by file name (the last part of `file_path`) when every
/// frame of the scene has a namesake in the reference, else by time (nearest, within half
/// the reference's smallest time step).
fn pair<'a>(
    scene: &[&'a Frame],
    reference: &[&'a Frame],
) -> Result<(Vec<(&'a Frame, &'a Frame)>, &'static str)> {
    let base = |f: &Frame| f.file_path.rsplit('/').next().unwrap_or("").to_string();
    let by_name: std::collections::HashMap<String, &Frame> =
        reference.iter().map(|f| (base(f), *f)).collect();
    let named: Option<Vec<_>> = scene
        .iter()
        .map(|f| by_name.get(&base(f)).map(|r| (*f, *r)))
        .collect();
    if let Some(p) = named {
        return Ok((p, "file name"));
    }
    let mut times: Vec<f32> = reference.iter().map(|f| f.time).collect();
    times.sort_by(f32::total_cmp);
    let step = times
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .fold(f32::INFINITY, f32::min);
    let tol = if step.is_finite() { 0.5 * step } else { 1e-6 };
    let mut out = Vec::new();
    for f in scene {
        let r = reference
            .iter()
            .min_by(|a, b| (a.time - f.time).abs().total_cmp(&(b.time - f.time).abs()))
            .filter(|r| (r.time - f.time).abs() < tol)
            .with_context(|| {
                format!(
                    "frame {} (t = {}) has no reference frame of the same name or time",
                    f.file_path, f.time
                )
            })?;
        out.push((*f, *r));
    }
    Ok((out, "time"))
}

pub fn run(a: Args) -> Result<()> {
    let opts = LoadOptions::default();
    let est = scene::load_dataset(&a.scene, &opts)
        .with_context(|| format!("loading {}", a.scene.display()))?;
    let refs = scene::load_dataset(&a.reference, &opts)
        .with_context(|| format!("loading the reference {}", a.reference.display()))?;
    // val often repeats test (Nerfies, the every-8th holdout): each frame once.
    let once = |ds: &'_ scene::Dataset| -> Vec<Frame> {
        let mut seen = std::collections::HashSet::new();
        ds.all_frames()
            .filter(|f| seen.insert(f.file_path.clone()))
            .cloned()
            .collect()
    };
    let (e_all, r_all) = (once(&est), once(&refs));
    let ef: Vec<&Frame> = e_all.iter().collect();
    let rf: Vec<&Frame> = r_all.iter().collect();
    let (pairs, by) = pair(&ef, &rf)?;
    let r: Vec<splat::Camera> = pairs.iter().map(|p| p.1.camera.clone()).collect();
    let e: Vec<splat::Camera> = pairs.iter().map(|p| p.0.camera.clone()).collect();
    let errs = scene::align::compare_cameras(&r, &e).map_err(anyhow::Error::msg)?;
    let worst = errs
        .centre_errors
        .iter()
        .zip(&pairs)
        .max_by(|a, b| a.0.total_cmp(b.0))
        .map(|(_, p)| p.0.file_path.clone())
        .unwrap_or_default();
    println!(
        "{} of {} reference frames paired by {by}; alignment scale {:.6}",
        errs.frames,
        rf.len(),
        errs.alignment.scale
    );
    println!(
        "camera centres: median {:.3} %, max {:.3} % of the reference's scene extent ({:.4}; worst frame {worst})",
        100.0 * errs.centre_median_rel,
        100.0 * errs.centre_max_rel,
        errs.extent
    );
    println!(
        "rotations: median {:.3}°, max {:.3}°",
        errs.rotation_median_deg, errs.rotation_max_deg
    );
    if let Some(path) = &a.json {
        let names: Vec<&str> = pairs.iter().map(|p| p.0.file_path.as_str()).collect();
        let v = serde_json::json!({
            "scene": a.scene.display().to_string(),
            "reference": a.reference.display().to_string(),
            "paired_by": by,
            "reference_frames": rf.len(),
            "frame_names": names,
            "errors": errs,
        });
        scene::io::write_json(path, &v)?;
    }
    if a.max_centre.is_some_and(|m| above(errs.centre_max_rel, m)) {
        bail!(
            "largest centre error {:.3} % is above --max-centre {:.3} %",
            100.0 * errs.centre_max_rel,
            100.0 * a.max_centre.unwrap_or_default()
        );
    }
    if a.max_rotation_deg
        .is_some_and(|m| above(errs.rotation_median_deg, m))
    {
        bail!(
            "median rotation error {:.3}° is above --max-rotation-deg {}",
            errs.rotation_median_deg,
            a.max_rotation_deg.unwrap_or_default()
        );
    }
    Ok(())
}

/// `value > bound`, and true for a NaN value (an error that cannot be measured fails).
fn above(value: f64, bound: f64) -> bool {
    value.is_nan() || value > bound
}
