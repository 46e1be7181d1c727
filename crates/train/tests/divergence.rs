//! A loss or parameter that turns NaN/Inf stops training with the iteration and the
//! parameter group named, and nothing non-finite is ever checkpointed: the last good
//! checkpoint stays `latest`.

mod common;

use train::field::DeformOutput;
use train::hook::{DeformHook, HookContext, HookError};
use train::state::AuxStore;
use train::{checkpoint, TrainError, Trainer};

fn trained(iters: u32, steps: u32) -> Trainer {
    let mut tr = Trainer::new(common::small_config(iters), common::dataset(), 3).unwrap();
    for _ in 0..steps {
        tr.step().unwrap();
    }
    tr
}

fn diverged(r: Result<impl std::fmt::Debug, TrainError>) -> (u32, String) {
    match r {
        Err(TrainError::NonFinite { iteration, what }) => (iteration, what),
        other => panic!("expected a divergence error, got {other:?}"),
    }
}

#[test]
fn a_nan_parameter_stops_the_step_and_names_its_group_and_row() {
    let mut tr = trained(40, 3);
    tr.state.model.log_scales[3 * 17 + 1] = f32::NAN;
    let (it, what) = diverged(tr.step());
    assert_eq!(it, 4);
    assert!(
        what.contains("`log_scales`") && what.contains("Gaussian 17 "),
        "{what}"
    );
}

#[test]
fn a_diverged_state_is_never_checkpointed_and_latest_stays_good() {
    let mut tr = trained(40, 2);
    let run = tempfile::tempdir().unwrap();
    let good = checkpoint::save(&tr, run.path()).unwrap();
    tr.step().unwrap();
    tr.state.adam[0].v[5] = f32::INFINITY;
    let (it, what) = diverged(checkpoint::save(&tr, run.path()));
    assert_eq!(it, 3);
    assert!(
        what.contains("second moment of `means`") && what.contains("not written"),
        "{what}"
    );
    assert_eq!(checkpoint::latest(run.path()).unwrap(), good);
    assert_eq!(checkpoint::iterations(run.path()).unwrap().len(), 1);
    assert!(checkpoint::load_trainer(&good, common::dataset()).is_ok());
}

/// A hook whose gradient is NaN: the field's Adam step writes NaN weights.
struct NanHook;

impl DeformHook for NanHook {
    fn topk(&self, _: u32) -> usize {
        0
    }
    fn apply(
        &mut self,
        _: &HookContext,
        _: &mut AuxStore,
        d: &mut DeformOutput,
    ) -> Result<f32, HookError> {
        d.dx[0] = f32::NAN;
        Ok(0.0)
    }
}

#[test]
fn a_nan_gradient_is_caught_at_the_step_that_writes_it() {
    let iters = 40;
    let warm = common::small_config(iters).field.warm_up;
    let mut tr = trained(iters, warm);
    let (it, what) = diverged(tr.step_with(Some(&mut NanHook)));
    assert_eq!(it, warm + 1);
    assert!(what.contains("deformation-field weight"), "{what}");
}
