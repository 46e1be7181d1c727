//! The grid file of `semdynreg sweep` (TOML), read strictly: unknown keys, empty lists, a
//! config key the training config does not have, or a forked mode without the mode it
//! forks from are refused here, before anything runs, with the file and the key named.

use crate::report::methods::{self, METHODS};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The whole grid file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    /// The scenes: each a folder, or a `synth toycars` recipe made under `OUT/scenes/`.
    pub scenes: Vec<SceneSpec>,
    /// Methods to train, by key (`baseline`, `semdynreg`, `rigid`; `compare`'s methods).
    pub modes: Vec<String>,
    /// Seeds of every run.
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    /// Rescale every run's schedule to N iterations (`train --iters`); default the full 40k.
    pub iters: Option<u32>,
    #[serde(default = "default_downscale")]
    pub downscale: u32,
    #[serde(default)]
    pub white_background: bool,
    /// Seconds spanned by time 0 → 1 (toycars: 6 s), to place the crops at t = 0…5 s.
    #[serde(default = "default_duration")]
    pub duration_s: f32,
    /// Every run's training config, as `train --config` reads it (e.g. `[config.init]
    /// random_points = 20000`).
    #[serde(default)]
    pub config: toml::Table,
    /// Blocks of overrides, each a table of config keys to lists of values. The runs of a
    /// block are the cartesian product of its lists; the grid's are the union of its blocks'
    /// (a run two blocks share runs once). No block: one run per scene, mode and seed.
    #[serde(default)]
    pub sweep: Vec<toml::Table>,
}

fn default_seeds() -> Vec<u64> {
    vec![0]
}
fn default_downscale() -> u32 {
    1
}
fn default_duration() -> f32 {
    6.0
}

/// One scene: `path` (relative to the grid file's folder) or `synth`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Its name in run names and tables.
    pub name: String,
    pub path: Option<PathBuf>,
    pub synth: Option<SynthSpec>,
    /// Object-ID maps (`semdynreg segment`); a synth scene gets ground-truth ones by default.
    pub segment: Option<SegmentSpec>,
}

/// `semdynreg synth toycars` options (same names and defaults, except the demo's size).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SynthSpec {
    pub preset: String,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub seed: u64,
    pub drive: f32,
    pub route: Vec<String>,
    pub add: Vec<String>,
    pub no_antialias: bool,
    pub no_shadows: bool,
}

impl Default for SynthSpec {
    fn default() -> Self {
        Self {
            preset: "scene1".into(),
            width: 160,
            height: 120,
            frames: 96,
            seed: 0,
            drive: 1.0,
            route: Vec::new(),
            add: Vec::new(),
            no_antialias: false,
            no_shadows: false,
        }
    }
}

/// `semdynreg segment` options.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SegmentSpec {
    pub dict: Vec<String>,
    pub masks: MaskSource,
    pub labels: LabelSource,
    /// CLIP weights for `labels = "clip"`.
    pub clip: Option<PathBuf>,
}

impl Default for SegmentSpec {
    fn default() -> Self {
        Self {
            dict: vec![
                "white SUV".into(),
                "yellow sedan".into(),
                "green SUV".into(),
            ],
            masks: MaskSource::Gt,
            labels: LabelSource::Gt,
            clip: None,
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MaskSource {
    Gt,
    Sam,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LabelSource {
    Gt,
    Clip,
}

/// A swept config key (dotted, e.g. `reg.lambda`) with its values in file order (a block's
/// keys come in alphabetical order).
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub key: String,
    pub values: Vec<toml::Value>,
}

/// A grid read and checked: the file, its settings, and each sweep block as axes.
#[derive(Clone, Debug)]
pub struct CheckedGrid {
    pub file: PathBuf,
    pub grid: Grid,
    pub blocks: Vec<Vec<Axis>>,
}

/// Reads and checks `path`.
pub fn load(path: &Path) -> Result<CheckedGrid> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse(path, &text)
}

/// Parses and checks the grid text of `file` (named in every error).
pub fn parse(file: &Path, text: &str) -> Result<CheckedGrid> {
    let f = file.display();
    let grid: Grid = toml::from_str(text).with_context(|| format!("{f}: not a valid grid"))?;
    check_lists(file, &grid)?;
    check_modes(file, &grid.modes)?;
    for (i, s) in grid.scenes.iter().enumerate() {
        check_scene(file, i, s)?;
    }
    check_unique_scene_names(file, &grid.scenes)?;
    train::TrainConfig::validate(&config_from(file, &grid.config, "[config]")?)
        .with_context(|| format!("{f}: [config]"))?;
    let defaults = match toml::Value::try_from(train::TrainConfig::default()) {
        Ok(toml::Value::Table(t)) => t,
        _ => bail!("the default training config does not serialize as a TOML table"),
    };
    let blocks = grid
        .sweep
        .iter()
        .enumerate()
        .map(|(i, b)| block_axes(file, i, b, &defaults))
        .collect::<Result<Vec<_>>>()?;
    Ok(CheckedGrid {
        file: file.to_path_buf(),
        grid,
        blocks,
    })
}

fn check_lists(file: &Path, g: &Grid) -> Result<()> {
    let f = file.display();
    for (key, empty) in [
        ("scenes", g.scenes.is_empty()),
        ("modes", g.modes.is_empty()),
        ("seeds", g.seeds.is_empty()),
    ] {
        if empty {
            bail!("{f}: `{key}` is an empty list: give at least one");
        }
    }
    if g.iters == Some(0) {
        bail!("{f}: `iters` must be ≥ 1");
    }
    if g.downscale == 0 {
        bail!("{f}: `downscale` must be ≥ 1");
    }
    Ok(())
}

/// Every mode is a known method, named once, and the method a mode forks from is in the
/// grid too (its runs are the forks' starting points).
fn check_modes(file: &Path, modes: &[String]) -> Result<()> {
    let f = file.display();
    let known: Vec<&str> = METHODS.iter().map(|m| m.key).collect();
    for (i, m) in modes.iter().enumerate() {
        let Some(method) = methods::method(m) else {
            bail!(
                "{f}: `modes`: unknown mode `{m}` (known: {})",
                known.join(", ")
            );
        };
        if modes[..i].contains(m) {
            bail!("{f}: `modes`: `{m}` is listed twice");
        }
        if let Some(from) = method.training.fork_from {
            if !modes.iter().any(|x| x == from) {
                bail!(
                    "{f}: `modes`: `{m}` forks from `{from}` (train --fork), which is not in `modes`; add \"{from}\""
                );
            }
        }
    }
    Ok(())
}

fn check_scene(file: &Path, i: usize, s: &SceneSpec) -> Result<()> {
    let at = format!("{}: scenes[{i}] (`{}`)", file.display(), s.name);
    if s.name.is_empty() || !s.name.chars().all(name_char) {
        bail!("{at}: `name` must be non-empty letters, digits, `-`, `_` or `.`");
    }
    match (&s.path, &s.synth) {
        (Some(_), Some(_)) => bail!("{at}: give `path` or `synth`, not both"),
        (None, None) => bail!("{at}: give `path` (a scene folder) or `synth` (a recipe)"),
        _ => {}
    }
    if let Some(synth) = &s.synth {
        check_synth(&at, synth)?;
    }
    if let Some(seg) = &s.segment {
        if seg.dict.is_empty() {
            bail!("{at}: `segment.dict` is an empty list: give the objects' prompts");
        }
        if seg.labels == LabelSource::Clip && seg.clip.is_none() {
            bail!("{at}: `segment.labels = \"clip\"` needs `segment.clip` (CLIP weights)");
        }
    }
    Ok(())
}

/// The recipe's values as `synth toycars` would refuse them, checked here already.
fn check_synth(at: &str, s: &SynthSpec) -> Result<()> {
    s.preset
        .parse::<scene::toycars::Preset>()
        .with_context(|| format!("{at}: `synth.preset`"))?;
    for r in &s.route {
        r.parse::<scene::toycars::RouteSpec>()
            .with_context(|| format!("{at}: `synth.route`"))?;
    }
    for a in &s.add {
        a.parse::<scene::toycars::AddSpec>()
            .with_context(|| format!("{at}: `synth.add`"))?;
    }
    if s.width == 0 || s.height == 0 || s.frames < 2 {
        bail!("{at}: `synth` needs width and height ≥ 1 and frames ≥ 2");
    }
    if !(s.drive > 0.0 && s.drive <= 1.0) {
        bail!("{at}: `synth.drive` must be in (0, 1], got {}", s.drive);
    }
    Ok(())
}

fn check_unique_scene_names(file: &Path, scenes: &[SceneSpec]) -> Result<()> {
    for (i, s) in scenes.iter().enumerate() {
        if scenes[..i].iter().any(|o| o.name == s.name) {
            bail!(
                "{}: scenes[{i}]: the name `{}` is used twice",
                file.display(),
                s.name
            );
        }
    }
    Ok(())
}

/// Characters allowed in scene names and in the value part of run names.
pub fn name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || "-_.".contains(c)
}

/// Parses `table` as a training config (unknown keys and wrong types refused by serde).
pub fn config_from(file: &Path, table: &toml::Table, what: &str) -> Result<train::TrainConfig> {
    let text = toml::to_string(table).context("writing the config as TOML")?;
    toml::from_str(&text).with_context(|| format!("{}: {what}", file.display()))
}

/// The axes of sweep block `i`: every leaf a non-empty list under a key the training
/// config has; the modes' switches (`reg.enabled`, `objects.enabled`) are not sweepable.
fn block_axes(
    file: &Path,
    i: usize,
    block: &toml::Table,
    defaults: &toml::Table,
) -> Result<Vec<Axis>> {
    let at = format!("{}: sweep[{i}]", file.display());
    let mut axes = Vec::new();
    flatten(&at, "", block, &mut axes)?;
    if axes.is_empty() {
        bail!("{at}: an empty block: give at least one `key = [values]`");
    }
    for a in &axes {
        check_key(&at, &a.key, defaults)?;
        if a.key == "reg.enabled" || a.key == "objects.enabled" {
            bail!("{at}: `{}` is set by `modes`, not swept", a.key);
        }
        if a.values.is_empty() {
            bail!(
                "{at}: `{}` is an empty list: give at least one value",
                a.key
            );
        }
    }
    Ok(axes)
}

/// Collects the lists under `table` as dotted keys (`reg.k = [1, 3]` is `{reg: {k: …}}`).
fn flatten(at: &str, prefix: &str, table: &toml::Table, out: &mut Vec<Axis>) -> Result<()> {
    for (k, v) in table {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(t) => flatten(at, &key, t, out)?,
            toml::Value::Array(values) => out.push(Axis {
                key,
                values: values.clone(),
            }),
            other => {
                bail!("{at}: `{key}` must be a list of values (`{k} = [{other}]` for one value)")
            }
        }
    }
    Ok(())
}

/// `key` names a value of the training config (not a section), else an error listing what
/// the section it tried has.
fn check_key(at: &str, key: &str, defaults: &toml::Table) -> Result<()> {
    let mut table = defaults;
    let parts: Vec<&str> = key.split('.').collect();
    for (n, part) in parts.iter().enumerate() {
        let section = parts[..n].join(".");
        let Some(v) = table.get(*part) else {
            let have: Vec<&str> = table.keys().map(String::as_str).collect();
            let place = if section.is_empty() {
                "the training config".to_string()
            } else {
                format!("[{section}]")
            };
            bail!(
                "{at}: unknown config key `{key}` ({place} has: {})",
                have.join(", ")
            );
        };
        match v {
            toml::Value::Table(t) if n + 1 < parts.len() => table = t,
            toml::Value::Table(_) => bail!("{at}: `{key}` is a section, not a value"),
            _ if n + 1 < parts.len() => bail!("{at}: unknown config key `{key}`"),
            _ => {}
        }
    }
    Ok(())
}

/// The swept keys of every block, in first-appearance order (the table's columns).
pub fn swept_keys(blocks: &[Vec<Axis>]) -> Vec<String> {
    let mut keys: Vec<String> = Vec::new();
    for a in blocks.iter().flatten() {
        if !keys.contains(&a.key) {
            keys.push(a.key.clone());
        }
    }
    keys
}

/// A TOML value as JSON (for `sweep.json` and the tables).
pub fn to_json(v: &toml::Value) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}

/// An ordered key → value map of one run's overrides.
pub type Overrides = BTreeMap<String, toml::Value>;

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        format!("{:#}", parse(Path::new("g.toml"), text).unwrap_err())
    }

    const HEAD: &str =
        "modes = [\"baseline\", \"semdynreg\"]\n[[scenes]]\nname = \"a\"\nsynth = {}\n";

    #[test]
    fn a_two_block_grid_reads_with_dotted_keys() {
        let g = parse(
            Path::new("g.toml"),
            &format!("{HEAD}[[sweep]]\nreg.k = [1, 3]\nreg.lambda = [0.1]\n[[sweep]]\nreg.lambda = [1.0]\n"),
        )
        .unwrap();
        assert_eq!(g.blocks.len(), 2);
        assert_eq!(g.blocks[0][0].key, "reg.k");
        assert_eq!(swept_keys(&g.blocks), ["reg.k", "reg.lambda"]);
        assert_eq!(g.grid.scenes[0].synth.as_ref().unwrap().width, 160);
    }

    #[test]
    fn bad_grids_name_the_file_and_the_key() {
        let e = err(&format!("{HEAD}[[sweep]]\nreg.lamda = [1]\n"));
        assert!(
            e.contains("g.toml: sweep[0]: unknown config key `reg.lamda`"),
            "{e}"
        );
        assert!(e.contains("lambda"), "lists the section's keys: {e}");
        let e = err(&format!("{HEAD}[[sweep]]\nreg.k = []\n"));
        assert!(
            e.contains("g.toml: sweep[0]: `reg.k` is an empty list"),
            "{e}"
        );
        let e = err(&format!("{HEAD}[[sweep]]\nreg.k = 3\n"));
        assert!(e.contains("`reg.k` must be a list"), "{e}");
        let e = err(&format!("seedz = [1]\n{HEAD}"));
        assert!(e.contains("g.toml") && e.contains("seedz"), "{e}");
        let e = err(&format!("seeds = []\n{HEAD}"));
        assert!(e.contains("g.toml: `seeds` is an empty list"), "{e}");
        let e = err(&format!("{HEAD}[config.reg]\nkk = 1\n"));
        assert!(e.contains("g.toml: [config]") && e.contains("kk"), "{e}");
        let e = err(&format!("{HEAD}[[sweep]]\nreg.enabled = [true]\n"));
        assert!(e.contains("set by `modes`"), "{e}");
    }

    #[test]
    fn a_fork_without_its_baseline_is_refused() {
        let e = err("modes = [\"semdynreg\"]\n[[scenes]]\nname = \"a\"\nsynth = {}\n");
        assert!(
            e.contains("g.toml: `modes`: `semdynreg` forks from `baseline`"),
            "{e}"
        );
        let e = err("modes = [\"nope\"]\n[[scenes]]\nname = \"a\"\nsynth = {}\n");
        assert!(e.contains("unknown mode `nope`"), "{e}");
    }

    #[test]
    fn scenes_are_checked() {
        let e = err("modes = [\"baseline\"]\nscenes = []\n");
        assert!(e.contains("`scenes` is an empty list"), "{e}");
        let e = err("modes = [\"baseline\"]\n[[scenes]]\nname = \"a\"\n");
        assert!(e.contains("scenes[0] (`a`): give `path`"), "{e}");
        let e = err(
            "modes = [\"baseline\"]\n[[scenes]]\nname = \"a\"\nsynth = { preset = \"scene9\" }\n",
        );
        assert!(e.contains("synth.preset") && e.contains("scene9"), "{e}");
        let e = err("modes = [\"baseline\"]\n[[scenes]]\nname = \"a\"\nsynth = { widht = 3 }\n");
        assert!(e.contains("widht"), "{e}");
    }
}
