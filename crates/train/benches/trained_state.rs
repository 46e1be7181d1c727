//! One training iteration at a trained state, by phase (issue 17: speed measured where the
//! time goes in a real run, not only on a random init). Loads a run's checkpoint with its
//! scene, exactly as `train --resume` does, and takes training steps from it with density
//! control off (so every step sees the same Gaussians), printing per phase the median over
//! the steps, the (pixel, Gaussian) pairs the rasterizer evaluated, and the Gaussian count.
//!
//! ```text
//! SEMDYNREG_BENCH_RUN=RUN [SEMDYNREG_BENCH_ITERATION=N] [SEMDYNREG_BENCH_STEPS=20] \
//!     cargo bench -p train --bench trained_state
//! ```
//!
//! RUN is a run folder (`semdynreg train … --out RUN`); its latest checkpoint is used unless
//! an iteration is named. Without `SEMDYNREG_BENCH_RUN` it says what it needs and exits:
//! it has no built-in state to replay (docs/performance.md says which runs were measured).

use std::path::PathBuf;
use train::timing::PHASES;

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
    let mut per_phase: Vec<Vec<f64>> = vec![Vec::new(); PHASES.len()];
    let (mut totals, mut pairs, mut rows) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..steps {
        let before = tr.timings;
        tr.step().expect("step");
        let mut total = 0.0;
        for (k, v) in per_phase.iter_mut().enumerate() {
            let ms = (tr.timings.seconds[k] - before.seconds[k]) * 1e3;
            total += ms;
            v.push(ms);
        }
        totals.push(total);
        pairs.push(tr.evaluated_pairs() as f64);
        let evaluated = tr.field.rows().len().max(1) as f64;
        rows.push(tr.field.rows_with_gradient() as f64 / evaluated);
    }
    println!("median of {steps} steps (ms):");
    for (p, v) in PHASES.iter().zip(per_phase) {
        let m = median(v);
        if m > 0.0 {
            println!("  {:<20} {m:9.2}", p.name());
        }
    }
    println!("  {:<20} {:9.2}", "total", median(totals));
    println!(
        "evaluated (pixel, Gaussian) pairs per step: median {:.3} M",
        median(pairs) / 1e6
    );
    println!(
        "field rows with a nonzero gradient (back-propagated): median {:.1} % of those evaluated",
        100.0 * median(rows)
    );
}
