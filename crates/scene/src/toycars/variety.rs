//! Seeded variety of toycars scenes for benchmarks: which vehicle drives and how far, a
//! second and third mover (another vehicle, a sliding or turning crate, a barrel lifted off
//! the ground and set down), routes of different lengths (speeds) with and without turns,
//! and still props parked near the movers' paths. Every draw is checked as `synth` checks
//! a command line (routes inside the volume) and further: no two objects may meet and every
//! object stays wholly in view at every frame; a rejected draw is replaced by the next one
//! from the same seed, so a seed always gives the same scene.

use super::motion::Layout;
use super::{AddSpec, Preset, PropKind, RouteSpec, ToycarsConfig};
use crate::SceneError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// Draws tried per seed before giving up (the acceptance rate is about one in three).
const TRIES: usize = 500;

/// A generated scene's settings and the `semdynreg synth toycars` arguments that make it.
#[derive(Clone, Debug)]
pub struct VariedScene {
    pub config: ToycarsConfig,
    pub args: Vec<String>,
}

/// The scene of `seed` at `width`×`height` and `frames` frames (the checks of view and
/// contact depend on them).
pub fn varied(
    seed: u64,
    width: u32,
    height: u32,
    frames: usize,
) -> Result<VariedScene, SceneError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..TRIES {
        let scene = draw(&mut rng, seed, width, height, frames)?;
        let Ok(layout) = Layout::build(&scene.config) else {
            continue;
        };
        if layout.collisions(frames).is_empty()
            && layout.out_of_view(width, height, frames).is_empty()
        {
            return Ok(scene);
        }
    }
    Err(SceneError::Argument(format!(
        "toycars variety: no scene for seed {seed} passed the checks in {TRIES} draws"
    )))
}

/// Writes the scene's ground-truth masks as its object-ID maps (`semantics/`, what
/// `semdynreg segment DIR --masks gt --labels gt` writes for these scenes), for benchmarks
/// that measure the objects without the segmentation.
pub fn ground_truth_id_maps(dir: &Path) -> Result<(), SceneError> {
    copy_tree(&dir.join("masks"), &dir.join("semantics"))
}

fn copy_tree(from: &Path, to: &Path) -> Result<(), SceneError> {
    fn io(p: &Path) -> impl Fn(std::io::Error) -> SceneError + '_ {
        move |e| SceneError::io(p, e)
    }
    std::fs::create_dir_all(to).map_err(io(to))?;
    for e in std::fs::read_dir(from).map_err(io(from))? {
        let p = e.map_err(io(from))?.path();
        let target = to.join(p.file_name().unwrap_or_default());
        if p.is_dir() {
            copy_tree(&p, &target)?;
        } else {
            std::fs::copy(&p, &target).map_err(io(&p))?;
        }
    }
    Ok(())
}

fn draw(
    rng: &mut ChaCha8Rng,
    seed: u64,
    width: u32,
    height: u32,
    frames: usize,
) -> Result<VariedScene, SceneError> {
    let preset = if rng.gen_bool(0.5) {
        Preset::Scene1
    } else {
        Preset::Scene2
    };
    let (driver, parked) = match preset {
        Preset::Scene1 => ("white-suv", ["yellow-sedan", "green-suv"]),
        Preset::Scene2 => ("yellow-sedan", ["white-suv", "green-suv"]),
    };
    let mut routes: Vec<String> = Vec::new();
    let mut drive = 1.0;
    // The driver: the preset's drive (a fraction of it: speed) or a route of its own.
    if rng.gen_bool(0.5) {
        drive = rng.gen_range(0.3..=1.0f32);
    } else {
        routes.push(format!("{driver}={}", route(rng, 0.0, false)));
    }
    // A second vehicle moves in about a third of the scenes.
    if rng.gen_bool(0.35) {
        let name = parked[rng.gen_range(0..2)];
        routes.push(format!("{name}={}", route(rng, 0.0, false)));
    }
    // One or two props near the middle of the mat, each still, sliding (and turning) or
    // lifted; at most one of them moves.
    let mut adds: Vec<String> = Vec::new();
    let mut prop_moves = false;
    let mut counts = [0usize; 2];
    for _ in 0..rng.gen_range(1..=2) {
        let kind = if rng.gen_bool(0.5) {
            PropKind::Crate
        } else {
            PropKind::Barrel
        };
        let k = kind as usize;
        counts[k] += 1;
        let name = match counts[k] {
            1 => kind.name().to_string(),
            n => format!("{}-{n}", kind.name()),
        };
        let (x, y) = (rng.gen_range(-0.7..0.7f32), rng.gen_range(-0.45..0.8f32));
        let yaw = rng.gen_range(-180.0..180.0f32);
        adds.push(format!("{}@{x:.3},{y:.3},{yaw:.1}", kind.name()));
        if !prop_moves && rng.gen_bool(0.45) {
            prop_moves = true;
            let lift = if rng.gen_bool(0.5) {
                rng.gen_range(0.12..0.35f32)
            } else {
                0.0
            };
            routes.push(format!(
                "{name}={}",
                route(rng, lift, kind == PropKind::Crate)
            ));
        }
    }
    let mut config = ToycarsConfig {
        preset,
        width,
        height,
        frames,
        seed,
        drive,
        ..ToycarsConfig::default()
    };
    config.routes = routes
        .iter()
        .map(|r| r.parse())
        .collect::<Result<Vec<RouteSpec>, _>>()?;
    config.adds = adds
        .iter()
        .map(|a| a.parse())
        .collect::<Result<Vec<AddSpec>, _>>()?;
    let mut args: Vec<String> = [
        "--preset",
        preset.name(),
        "--width",
        &width.to_string(),
        "--height",
        &height.to_string(),
        "--frames",
        &frames.to_string(),
        "--seed",
        &seed.to_string(),
        "--drive",
        &format!("{drive:.3}"),
    ]
    .map(str::to_string)
    .to_vec();
    for a in &adds {
        args.extend(["--add".to_string(), a.clone()]);
    }
    for r in &routes {
        args.extend(["--route".to_string(), r.clone()]);
    }
    Ok(VariedScene { config, args })
}

/// Waypoints `x,y[,z][@yaw]` of a route: 0.25–1.2 units long (a slow to a fast mover over
/// the 6 s), straight or turning 25–90° halfway; `lift` > 0 raises the middle waypoint off
/// the ground; `spin` gives yaw keys that turn the object on the spot as it moves.
fn route(rng: &mut ChaCha8Rng, lift: f32, spin: bool) -> String {
    let p0 = [rng.gen_range(-0.8..0.8f32), rng.gen_range(-0.5..0.85f32)];
    let heading = rng.gen_range(0.0..std::f32::consts::TAU);
    let len = rng.gen_range(0.25..1.2f32);
    let turn = if rng.gen_bool(0.5) {
        rng.gen_range(25.0..90.0f32).to_radians() * if rng.gen_bool(0.5) { 1.0 } else { -1.0 }
    } else {
        0.0
    };
    let step = |p: [f32; 2], h: f32| [p[0] + 0.5 * len * h.cos(), p[1] + 0.5 * len * h.sin()];
    let p1 = step(p0, heading);
    let p2 = step(p1, heading + turn);
    let yaw0 = rng.gen_range(-180.0..180.0f32);
    let spin_by = rng.gen_range(30.0..120.0f32);
    let point = |p: [f32; 2], z: f32, k: f32| {
        let mut s = format!("{:.3},{:.3}", p[0], p[1]);
        if z > 0.0 {
            s += &format!(",{z:.3}");
        }
        if spin {
            s += &format!("@{:.1}", yaw0 + k * spin_by);
        }
        s
    };
    [
        point(p0, 0.0, 0.0),
        point(p1, lift, 0.5),
        point(p2, 0.0, 1.0),
    ]
    .join(";")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_gives_one_scene_and_seeds_differ() {
        let a = varied(3, 160, 120, 24).unwrap();
        let b = varied(3, 160, 120, 24).unwrap();
        assert_eq!(a.args, b.args);
        let others: Vec<Vec<String>> = (4..8)
            .map(|s| varied(s, 160, 120, 24).unwrap().args)
            .collect();
        assert!(others.iter().all(|o| *o != a.args));
    }

    #[test]
    fn scenes_are_checked_and_varied() {
        let (mut two_movers, mut lifted, mut turned_props) = (0, 0, 0);
        for seed in 0..12 {
            let s = varied(seed, 160, 120, 24).unwrap();
            let layout = Layout::build(&s.config).unwrap();
            assert!(layout.collisions(24).is_empty(), "seed {seed}");
            assert!(layout.out_of_view(160, 120, 24).is_empty(), "seed {seed}");
            let movers = (0..layout.models.len())
                .filter(|&i| layout.is_moving(i))
                .count();
            assert!(
                movers >= 1 && movers < layout.models.len(),
                "seed {seed}: a still object too"
            );
            two_movers += usize::from(movers >= 2);
            lifted += usize::from(
                s.config
                    .routes
                    .iter()
                    .any(|r| r.waypoints.iter().any(|w| w.pos[2] > 0.0)),
            );
            turned_props += usize::from(
                s.config
                    .routes
                    .iter()
                    .any(|r| r.waypoints[0].angles_deg.is_some()),
            );
        }
        assert!(
            two_movers >= 3 && lifted >= 1 && turned_props >= 1,
            "{two_movers} {lifted} {turned_props}"
        );
    }
}
