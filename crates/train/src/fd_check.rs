//! Test helper: the relative error of an analytic gradient against central differences,
//! `‖fd − analytic‖ / ‖fd‖` over chosen parameters (f32 parameters, f64 loss), shared by
//! the field's gradient tests (MLP, time network, whole field).

/// `param(state, i)` is parameter i of `state`, `loss(state)` the loss at the current
/// parameters, `analytic[i]` the gradient to check; each parameter in `indices` is moved by
/// ±`h` and restored. Returns the relative error and ‖fd‖ (so a test can reject a zero one).
pub fn relative_error<S>(
    state: &mut S,
    param: fn(&mut S, usize) -> &mut f32,
    mut loss: impl FnMut(&mut S) -> f64,
    analytic: &[f32],
    indices: impl IntoIterator<Item = usize>,
    h: f32,
) -> (f64, f64) {
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for i in indices {
        let p0 = *param(state, i);
        *param(state, i) = p0 + h;
        let lp = loss(state);
        *param(state, i) = p0 - h;
        let lm = loss(state);
        *param(state, i) = p0;
        let fd = (lp - lm) / (2.0 * h as f64);
        diff += (fd - analytic[i] as f64).powi(2);
        norm += fd * fd;
    }
    ((diff / norm).sqrt(), norm.sqrt())
}
