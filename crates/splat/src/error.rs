use thiserror::Error;

/// Errors from bad input to the rasterizer (never from its arithmetic).
#[derive(Debug, Error)]
pub enum SplatError {
    #[error("array `{name}` has length {got}, expected {expected}")]
    Length {
        name: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("invalid input: {0}")]
    Invalid(String),
}
