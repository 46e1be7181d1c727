//! `semdynreg synth toycars`: generate the built-in toycars scenes.

use anyhow::Context;
use clap::{Args as ClapArgs, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use scene::toycars::{generate, AddSpec, Preset, RouteSpec, ToycarsConfig};
use std::path::PathBuf;

/// Generate a built-in synthetic scene with ground truth (toycars).
#[derive(ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand)]
enum What {
    /// Three toy vehicles on a textured mat, one driving, one moving camera (D-NeRF layout,
    /// plus masks/ and objects.json); --route and --add make other motions and props.
    Toycars(ToycarsArgs),
}

#[derive(ClapArgs)]
struct ToycarsArgs {
    /// Output folder (created; existing files with the same names are replaced).
    #[arg(long)]
    out: PathBuf,
    /// scene1: the white SUV drives; scene2: the yellow sedan drives.
    #[arg(long, default_value = "scene1")]
    preset: Preset,
    /// Image width in pixels.
    #[arg(long, default_value_t = 480)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 360)]
    height: u32,
    /// Number of frames (time 0..1 stands for 6 s).
    #[arg(long, default_value_t = 120)]
    frames: usize,
    /// Seed of the printed textures.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// One sample per pixel instead of 4 rotated-grid samples.
    #[arg(long)]
    no_antialias: bool,
    /// Disable sun shadows.
    #[arg(long)]
    no_shadows: bool,
    /// Fraction of its ~2.6-unit route the moving vehicle covers in the 6 s, in (0, 1].
    /// 1 is the full drive (with a left turn); e.g. 0.25 drives ~0.65 units straight, a
    /// motion deformable 3DGS can follow. With --route it applies to every moving object
    /// (the fraction of its own route).
    #[arg(long, default_value_t = 1.0)]
    drive: f32,
    /// Move an object along waypoints: SPEC = [NAME=]P;P;..., P = x,y[,z][@yaw[,pitch,roll]]
    /// (repeatable, one per object; quote it, `;` is special to the shell).
    ///
    /// At least 2 waypoints, in world units (the mat is [-1.25, 1.25]², z up) and degrees.
    /// NAME is an object's name in objects.json (white-suv, yellow-sedan, green-suv, or an
    /// --add'ed crate, crate-2, barrel, ...); without NAME= the preset's moving vehicle.
    /// The object passes through every waypoint at constant speed along a smooth
    /// (centripetal Catmull-Rom) curve over the 6 s. z is the height of its origin above
    /// the ground (default 0; z > 0 leaves the ground). It heads along the curve unless
    /// waypoints give @yaw: then yaw, pitch and roll (default 0; right-handed about the
    /// object's z, y, x axes: positive pitch lowers the nose, positive roll raises the
    /// left side) are interpolated between those waypoints the shortest way round (add a
    /// waypoint to turn 180° or more). Its box must stay inside [-1.3, 1.3]³ at every frame;
    /// a warning says when an object leaves the image or meets another one.
    ///
    /// Example (two cars crossing): --route '0.95,-0.35;-0.9,-0.35' --route 'green-suv=0.45,0.95;0.45,-0.55'
    #[arg(long = "route", value_name = "SPEC", allow_hyphen_values = true)]
    routes: Vec<RouteSpec>,
    /// Park a prop: KIND@x,y[,yaw], KIND crate, barrel or crane, yaw in degrees
    /// (repeatable).
    ///
    /// crate: a wooden toy crate (0.30 long, 0.22 wide, 0.20 high) with different markings
    /// on every face; barrel: an upright red barrel (0.19 across, 0.24 high) with a band,
    /// a label and a marked lid; crane: an articulated wooden crane (a 0.36 × 0.28 base,
    /// a 0.52 boom hinged 0.19 up that swings ±50° about the vertical once and dips twice,
    /// a bucket at its tip rocking ±35°), whose parts' poses objects.json records and whose
    /// part maps go to parts/. Props stand on the ground with their centre at (x, y),
    /// get the next mask IDs (3, 4, ...) and the names crate, crate-2, ..., barrel, ...;
    /// move one with --route crate=....
    ///
    /// Example (a crate sliding and turning 180° while the preset's car drives past):
    /// --add crate@0.25,-0.25 --route 'crate=0.25,-0.25@0;0.3,0.15@90;0.3,0.5@180'
    #[arg(
        long = "add",
        value_name = "KIND@x,y[,yaw]",
        allow_hyphen_values = true
    )]
    adds: Vec<AddSpec>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Toycars(a) => toycars(a),
    }
}

fn toycars(a: ToycarsArgs) -> anyhow::Result<()> {
    let cfg = ToycarsConfig {
        preset: a.preset,
        width: a.width,
        height: a.height,
        frames: a.frames,
        seed: a.seed,
        supersample: !a.no_antialias,
        shadows: !a.no_shadows,
        drive: a.drive,
        routes: a.routes,
        adds: a.adds,
    };
    let bar = ProgressBar::new(cfg.frames as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{bar:40}] {pos}/{len} frames {elapsed_precise} eta {eta}",
        )
        .context("progress bar template")?
        .progress_chars("=> "),
    );
    bar.set_message(format!("toycars {}", cfg.preset.name()));
    let start = std::time::Instant::now();
    generate(&cfg, &a.out, &|done, _| bar.set_position(done as u64)).with_context(|| {
        format!(
            "generating toycars {} into {}",
            cfg.preset.name(),
            a.out.display()
        )
    })?;
    bar.finish();
    tracing::info!(
        "wrote {} frames of {}×{} to {} in {:.1} s",
        cfg.frames,
        cfg.width,
        cfg.height,
        a.out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
