//! `--only NAME[,NAME…]` and `--without NAME[,NAME…]`, shared by `render` and `export`:
//! the flags, and their resolution against a run's objects (train::objects::select).

use anyhow::Result;
use clap::builder::NonEmptyStringValueParser;
use train::objects::{RigidObject, SelectMode, Selection};

/// Which parts of a rigid-objects run (`train --objects`) to keep. --only and --without
/// exclude each other; without either, everything is kept.
#[derive(clap::Args, Debug, Default)]
pub struct SelectArgs {
    /// Keep only these parts of a run trained with --objects: object names as the run
    /// names them (e.g. `white-suv`; case does not matter), object IDs, or the pseudo-name
    /// `background` (the deformable rest: every Gaussian of no object). Several names go
    /// space- or comma-separated after one flag, or in repeated flags (put the run folder
    /// before the flag). E.g. `--only white-suv` keeps the car alone (rendered over the
    /// background colour, or exported as its Gaussians only). An unknown name is an error
    /// that lists the run's objects.
    #[arg(long, value_name = "NAME", num_args = 1.., value_delimiter = ',',
        conflicts_with = "without", value_parser = NonEmptyStringValueParser::new())]
    pub only: Vec<String>,
    /// Keep everything but these parts (names, IDs or `background`, as for --only). E.g.
    /// `--without white-suv` keeps the scene without the moving car, `--without
    /// background` the objects alone.
    #[arg(long, value_name = "NAME", num_args = 1.., value_delimiter = ',',
        value_parser = NonEmptyStringValueParser::new())]
    pub without: Vec<String>,
}

impl SelectArgs {
    /// None when neither flag is given; otherwise the selection, or an error naming the
    /// run's objects (unknown names, or a run without objects).
    pub fn resolve(&self, objects: &[RigidObject]) -> Result<Option<Selection>> {
        let (mode, names) = match (self.only.is_empty(), self.without.is_empty()) {
            (true, true) => return Ok(None),
            (false, _) => (SelectMode::Only, &self.only),
            (true, false) => (SelectMode::Without, &self.without),
        };
        Ok(Some(Selection::resolve(objects, mode, names)?))
    }
}

/// `only white-suv, yellow-sedan` / `without background` for messages.
pub fn describe(s: &Selection) -> String {
    let mode = match s.mode {
        SelectMode::Only => "only",
        SelectMode::Without => "without",
    };
    format!("{mode} {}", s.names.join(", "))
}
