//! `semdynreg export RUN --time T --out F.ply` or `--times a:b:step --out DIR`
//! `[--iteration N] [--only|--without NAME,…]`: the Gaussians deformed to time t (all, or
//! the selected objects/background), as standard 3DGS PLYs any viewer opens. With
//! `--per-object --out DIR [--times a:b:step]`, each object in its own frame with its
//! trajectory instead ([`super::export_objects`]).

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// The Gaussians deformed to time t as standard 3DGS PLY files (any splat viewer opens them),
/// or, with --per-object, each rigid object in its own frame plus its trajectory.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder made by `semdynreg train`.
    pub run: PathBuf,
    /// One time in [0, 1]; --out is the PLY file.
    #[arg(long, conflicts_with = "times")]
    pub time: Option<f32>,
    /// A sequence `a:b:step` (inclusive of b within rounding); --out is a folder. With
    /// --per-object, the times of the trajectory files' extra `times` rows.
    #[arg(long)]
    pub times: Option<String>,
    /// The PLY file (`--time`) or the folder of `t_0.0000.ply`, … files (`--times`,
    /// `--per-object`).
    #[arg(long)]
    pub out: PathBuf,
    /// Use the checkpoint of this iteration instead of the latest.
    #[arg(long)]
    pub iteration: Option<u32>,
    #[command(flatten)]
    pub select: super::select::SelectArgs,
    /// For each object of a run trained with --objects, write `DIR/<name>.ply`: its
    /// Gaussians in its own object frame (a standard 3DGS PLY), and
    /// `DIR/<name>.trajectory.json`: `{"id", "name", "static", "gaussians", "knot_times":
    /// [t, …], "frames": [{"split", "file_path", "time", "translation": [x, y, z],
    /// "quaternion_wxyz": [w, x, y, z], "object_to_world": 4×4}, …], "times": [{"time", …},
    /// …]}`. `frames` holds every frame of the run's scene (train, val and test, in time
    /// order), `times` one row per --times value (absent without it). A pose maps
    /// x_world = R(q)·x_object + translation; `object_to_world` is the same pose as a
    /// row-major 4×4 matrix, x_world = M·[x_object, 1] (the convention of toycars'
    /// objects.json). A part of an articulated object trained with skinning adds
    /// `"skinning": {"parts": [name, …], "weights": [[w, …] per Gaussian]}`: Gaussian i is
    /// placed at Σ_k weights[i][k]·pose_{parts[k]}(t)·x_i. Also writes `DIR/background.ply`:
    /// the Gaussians of no object, undeformed (canonical space; `--only background --time T`
    /// gives them deformed to time T).
    #[arg(long, conflicts_with_all = ["time", "only", "without"])]
    pub per_object: bool,
}

/// Parses `a:b:step` into the times a, a+step, … ≤ b.
pub fn parse_times(s: &str) -> Result<Vec<f32>> {
    let parts: Vec<f32> = s
        .split(':')
        .map(|p| {
            p.trim()
                .parse::<f32>()
                .with_context(|| format!("`{p}` in --times `{s}` is not a number"))
        })
        .collect::<Result<_>>()?;
    let [a, b, step] = parts[..] else {
        bail!("--times `{s}` must be a:b:step")
    };
    if step.is_nan()
        || step <= 0.0
        || b < a
        || !(0.0..=1.0).contains(&a)
        || !(0.0..=1.0).contains(&b)
    {
        bail!("--times `{s}` needs 0 ≤ a ≤ b ≤ 1 and step > 0");
    }
    let n = ((b - a) / step + 1e-4).floor() as usize;
    Ok((0..=n).map(|k| a + k as f32 * step).collect())
}

pub fn run(a: Args) -> Result<()> {
    let mut r = super::render::LoadedRun::open(&a.run, a.iteration)?;
    if a.per_object {
        let times = a.times.as_deref().map(parse_times).transpose()?;
        return super::export_objects::write(&r, &a.run, &a.out, &times.unwrap_or_default());
    }
    let (times, single) = match (&a.time, &a.times) {
        (Some(t), None) if (0.0..=1.0).contains(t) => (vec![*t], true),
        (Some(t), None) => bail!("--time {t} is outside [0, 1]"),
        (None, Some(s)) => (parse_times(s)?, false),
        _ => bail!("give --time T, --times a:b:step or --per-object"),
    };
    r.select(&a.select)?;
    if !single {
        std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    }
    for t in &times {
        let m = train::render::deformed_model(r.scene(), *t);
        let path = if single {
            a.out.clone()
        } else {
            a.out.join(format!("t_{t:.4}.ply"))
        };
        train::ply::write(&path, &m).with_context(|| format!("writing {}", path.display()))?;
    }
    println!("{} PLY file(s) → {}", times.len(), a.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_parse() {
        assert_eq!(
            parse_times("0:1:0.25").unwrap(),
            vec![0.0, 0.25, 0.5, 0.75, 1.0]
        );
        assert!(parse_times("0:1").is_err());
        assert!(parse_times("0.5:0.2:0.1").is_err());
        assert!(parse_times("0:1:0").is_err());
    }
}
