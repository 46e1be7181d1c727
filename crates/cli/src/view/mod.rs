//! The web viewer behind `semdynreg view` ([`crate::cmd::view`]): [`frames`] makes a run's
//! Gaussians at time t from its checkpoint and caches them, [`meta`] describes the runs and
//! cameras, [`server`] serves them with the page (`page/`) and the vendored gsplat.js
//! renderer (`vendor/gsplat/`), both embedded by [`assets`].

pub mod assets;
pub mod frames;
pub mod meta;
pub mod server;
