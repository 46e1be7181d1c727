//! One module per subcommand, plus `select` (the --only/--without flags render and export
//! share) and `export_objects` (`export --per-object`).
pub mod compare;
pub mod compare_poses;
pub mod demo;
pub mod eval;
pub mod export;
pub mod export_objects;
pub mod metrics;
pub mod prepare;
pub mod render;
pub mod render_case;
pub mod segment;
pub mod select;
pub mod sweep;
pub mod synth;
pub mod train;
pub mod view;
pub mod weights;
