//! One training iteration at a trained state, by phase (speed measured where the
//! time goes in a real run, not only on a random init). Loads a run's checkpoint with its
//! scene, exactly as `train --resume` does, and takes training steps from it with density
//! control off (so every step sees the same Gaussians), printing per phase the median over
//! the steps, the (pixel, Gaussian) pairs the rasterizer evaluated, and the Gaussian count.
//!
//! ```text
//! SEMDYNREG_BENCH_RUN=RUN [SEMDYNREG_BENCH_ITERATION=N] [SEMDYNREG_BENCH_STEPS=20] \
//!     [SEMDYNREG_BENCH_AB=projection|field|simd] cargo bench -p train --bench trained_state
//! ```
//!
//! `SEMDYNREG_BENCH_AB` makes the steps alternate between a reference path and the fast one,
//! and prints the medians of each side by side (both take `STEPS` steps):
//! - `projection`: the rasterizer's scalar projection (one Gaussian at a time) against its
//!   16-lane one;
//! - `field`: the field's time features written into every row of the MLP's input (as
//!   Deformable-3DGS does) against folded once into its biases;
//! - `simd`: the rasterizer's kernels at every vector level this CPU has (portable, AVX2,
//!   AVX-512), so one machine measures the paths users' CPUs take. The field's GEMMs keep
//!   gemm's own dispatch.
//!
//! RUN is a run folder (`semdynreg train … --out RUN`); its latest checkpoint is used unless
//! an iteration is named. Without `SEMDYNREG_BENCH_RUN` it says what it needs and exits:
//! it has no built-in state to replay (docs/performance.md says which runs were measured).

use std::path::PathBuf;
use train::field_node::FieldNode;
use train::timing::PHASES;

fn field_mut(tr: &mut train::Trainer) -> &mut train::DeformField {
    &mut tr
        .nodes
        .get_mut::<FieldNode>()
        .expect("every run has a field")
        .field
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[v.len() / 2]
}

fn env_u32(name: &str) -> Option<u32> {
    let v = std::env::var(name).ok()?;
    Some(
        v.parse()
            .unwrap_or_else(|_| panic!("{name}={v} is not a count")),
    )
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument means another bench was asked for.
    if std::env::args().skip(1).any(|a| !a.starts_with('-')) {
        return;
    }
    let Some(run) = std::env::var_os("SEMDYNREG_BENCH_RUN").map(PathBuf::from) else {
        println!(
            "trained_state: set SEMDYNREG_BENCH_RUN to a run folder (semdynreg train … --out RUN) \
             to time one iteration at its checkpoint; skipped"
        );
        return;
    };
    let steps = env_u32("SEMDYNREG_BENCH_STEPS").unwrap_or(20).max(1) as usize;
    let info = train::run::RunInfo::load(&run).expect("run.json");
    let dataset = info.dataset().expect("the run's scene");
    let dir = match env_u32("SEMDYNREG_BENCH_ITERATION") {
        Some(it) => run.join("checkpoints").join(format!("iter_{it:07}")),
        None => train::checkpoint::latest(&run).expect("a checkpoint"),
    };
    let mut tr = train::checkpoint::load_trainer(&dir, dataset).expect("checkpoint loads");
    // Density control off: the same Gaussians every step, as the state was saved.
    tr.cfg.densify.until = 0;
    tr.cfg.densify.mcmc.until = 0;
    println!(
        "{}: iteration {}, {} Gaussians, {} training frames at {}×{}, field {}",
        dir.display(),
        tr.iteration,
        tr.state.len(),
        tr.dataset.train.len(),
        tr.dataset.train[0].camera.width,
        tr.dataset.train[0].camera.height,
        if tr.field_active_at(tr.iteration + 1) {
            "on"
        } else {
            "off (warm-up)"
        },
    );
    for _ in 0..3 {
        tr.step().expect("warm-up step");
    }
    let ab = std::env::var("SEMDYNREG_BENCH_AB").ok();
    let levels: Vec<splat::Simd> = splat::Simd::ALL
        .into_iter()
        .filter(|&l| l <= splat::cpu_simd_level())
        .collect();
    let variants: Vec<&str> = match ab.as_deref() {
        None => vec!["median"],
        Some("projection") => vec!["scalar projection", "16-lane projection"],
        Some("field") => vec!["time per row", "time in the bias"],
        Some("simd") => levels.iter().map(|l| l.name()).collect(),
        Some(other) => {
            panic!("SEMDYNREG_BENCH_AB={other}: the A/B switches are `projection`, `field`, `simd`")
        }
    };
    let mut samples: Vec<Samples> = variants.iter().map(|_| Samples::new()).collect();
    for step in 0..steps * variants.len() {
        let v = step % variants.len();
        match ab.as_deref() {
            Some("projection") => tr.rasterizer_mut().set_scalar_projection(v == 0),
            Some("field") => field_mut(&mut tr).set_time_per_row(v == 0),
            Some("simd") => tr.rasterizer_mut().set_simd_cap(levels[v]),
            _ => {}
        }
        samples[v].take(&mut tr);
    }
    println!("median of {steps} steps (ms):");
    let header: String = variants.iter().map(|v| format!("{v:>20}")).collect();
    println!("  {:<20} {header}", "");
    let medians: Vec<Vec<f64>> = samples.into_iter().map(Samples::medians).collect();
    let names = PHASES.iter().map(|p| p.name()).chain(["total"]);
    for (k, p) in names.enumerate() {
        if medians.iter().any(|m| m[k] > 0.0) {
            let cols: String = medians.iter().map(|m| format!("{:20.2}", m[k])).collect();
            println!("  {p:<20} {cols}");
        }
    }
    let m = &medians[medians.len() - 1];
    println!(
        "evaluated (pixel, Gaussian) pairs per step: median {:.3} M",
        m[PHASES.len() + 1] / 1e6
    );
    println!(
        "field rows with a nonzero gradient (back-propagated): median {:.1} % of those evaluated",
        100.0 * m[PHASES.len() + 2]
    );
}

/// Per-step measurements of one variant: ms per phase, then the total, the evaluated pairs
/// and the share of field rows with a gradient.
struct Samples(Vec<Vec<f64>>);

impl Samples {
    fn new() -> Self {
        Samples(vec![Vec::new(); PHASES.len() + 3])
    }

    fn take(&mut self, tr: &mut train::trainer::Trainer) {
        let before = tr.timings;
        tr.step().expect("step");
        let mut total = 0.0;
        for k in 0..PHASES.len() {
            let ms = (tr.timings.seconds[k] - before.seconds[k]) * 1e3;
            total += ms;
            self.0[k].push(ms);
        }
        self.0[PHASES.len()].push(total);
        self.0[PHASES.len() + 1].push(tr.evaluated_pairs() as f64);
        let field = &tr
            .nodes
            .get::<FieldNode>()
            .expect("every run has a field")
            .field;
        let evaluated = field.rows().len().max(1) as f64;
        self.0[PHASES.len() + 2].push(field.rows_with_gradient() as f64 / evaluated);
    }

    fn medians(self) -> Vec<f64> {
        self.0.into_iter().map(median).collect()
    }
}
