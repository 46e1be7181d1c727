//! One module per subcommand.
pub mod compare;
pub mod demo;
pub mod eval;
pub mod export;
pub mod metrics;
pub mod render;
pub mod render_case;
pub mod segment;
pub mod synth;
pub mod train;
