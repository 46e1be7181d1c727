//! A checked grid expanded into runs with stable names (`OUT/sweep.json`): one run per
//! scene × seed × override combination × mode, where a mode trained without the
//! regularizer ignores `[reg]` overrides and so shares one run across them (one baseline per
//! scene, seed and non-`[reg]` overrides, as `compare` shares its baseline), and a forked
//! mode names the run it forks from.

use super::grid::{self, Axis, CheckedGrid, Overrides, SceneSpec, SegmentSpec, SynthSpec};
use crate::report::io::write_atomic;
use crate::report::methods::{self, Method};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The plan's file in the sweep folder.
pub const PLAN_FILE: &str = "sweep.json";
/// Each finished run's scores, in its run folder (`compare`'s results.json, one method).
pub const RESULTS_FILE: &str = "results.json";

/// Everything a backend, a task or `--collect` needs, with absolute paths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub grid: PathBuf,
    pub out: PathBuf,
    pub iters: Option<u32>,
    pub downscale: u32,
    pub white_background: bool,
    pub duration_s: f32,
    /// Never fetch the LPIPS weights (each run scores without them when absent).
    pub offline: bool,
    /// The swept config keys: the table's columns.
    pub columns: Vec<String>,
    pub scenes: Vec<ScenePlan>,
    /// Runs that start from scratch first, then the forked ones.
    pub runs: Vec<RunSpec>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScenePlan {
    pub name: String,
    pub dir: PathBuf,
    pub synth: Option<SynthSpec>,
    pub segment: Option<SegmentSpec>,
}

/// One training run of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    pub name: String,
    pub scene: String,
    /// A method key of `report::methods::METHODS`.
    pub mode: String,
    pub seed: u64,
    /// The overrides this run's mode uses (as JSON, by dotted key).
    pub overrides: BTreeMap<String, serde_json::Value>,
    /// The run it forks from (`train --fork`), when its mode forks.
    pub fork_from: Option<String>,
    /// Its training config, as `train --config` reads it.
    pub config: String,
}

impl RunSpec {
    /// 0: trains from scratch; 1: forks from a stage-0 run (Slurm: the second array).
    pub fn stage(&self) -> usize {
        usize::from(self.fork_from.is_some())
    }

    pub fn method(&self) -> Result<&'static Method> {
        methods::method(&self.mode)
            .with_context(|| format!("run {}: unknown mode {}", self.name, self.mode))
    }
}

impl Plan {
    pub fn run_dir(&self, name: &str) -> PathBuf {
        self.out.join("runs").join(name)
    }

    pub fn config_path(&self, name: &str) -> PathBuf {
        self.out.join("configs").join(format!("{name}.toml"))
    }

    pub fn run(&self, name: &str) -> Result<&RunSpec> {
        self.runs
            .iter()
            .find(|r| r.name == name)
            .with_context(|| format!("{} has no run `{name}`", self.out.join(PLAN_FILE).display()))
    }

    pub fn scene(&self, name: &str) -> Result<&ScenePlan> {
        self.scenes
            .iter()
            .find(|s| s.name == name)
            .with_context(|| format!("the plan has no scene `{name}`"))
    }

    /// Whether the run's scores are there (it trained, rendered and was scored).
    pub fn finished(&self, name: &str) -> bool {
        self.run_dir(name).join(RESULTS_FILE).is_file()
    }

    /// Reads `OUT/sweep.json`.
    pub fn read(out: &Path) -> Result<Self> {
        let path = out.join(PLAN_FILE);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "reading {} (is {} a sweep folder? `semdynreg sweep GRID.toml --out DIR` makes one)",
                path.display(),
                out.display()
            )
        })?;
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// Writes `OUT/sweep.json` and each run's config file.
    pub fn write(&self) -> Result<()> {
        for r in &self.runs {
            write_atomic(&self.config_path(&r.name), r.config.as_bytes())?;
        }
        let json = serde_json::to_string_pretty(self).context("serializing the plan")?;
        write_atomic(&self.out.join(PLAN_FILE), json.as_bytes())
    }

    /// Refuses a plan for a folder that holds an earlier one whose runs or scenes of the same
    /// name were made differently (their results would be mixed up); new runs are fine.
    pub fn check_against(&self, old: &Plan) -> Result<()> {
        let fresh = "use another --out, or delete that run's folder";
        for s in &self.scenes {
            if let Some(o) = old.scenes.iter().find(|o| o.name == s.name) {
                if o != s {
                    bail!(
                        "{} holds scene `{}` made from another recipe or folder; {fresh}",
                        self.out.display(),
                        s.name
                    );
                }
            }
        }
        for r in &self.runs {
            if let Some(o) = old.runs.iter().find(|o| o.name == r.name) {
                if o != r {
                    bail!(
                        "{} holds run `{}` planned with other settings (config, fork or overrides); {fresh}",
                        self.out.display(),
                        r.name
                    );
                }
            }
        }
        let same = |a: &Plan| {
            (
                a.iters,
                a.downscale,
                a.white_background,
                a.duration_s.to_bits(),
            )
        };
        if same(self) != same(old) {
            bail!("{} was planned with other `iters`, `downscale`, `white_background` or `duration_s`; {fresh}", self.out.display());
        }
        Ok(())
    }
}

/// Expands `g` into the plan for sweep folder `out` (absolute).
pub fn expand(g: &CheckedGrid, out: &Path, offline: bool) -> Result<Plan> {
    let scenes = g
        .grid
        .scenes
        .iter()
        .enumerate()
        .map(|(i, s)| scene_plan(g, i, s, out))
        .collect::<Result<Vec<_>>>()?;
    let columns = grid::swept_keys(&g.blocks);
    let mut runs: Vec<RunSpec> = Vec::new();
    for scene in &g.grid.scenes {
        for &seed in &g.grid.seeds {
            for combo in combinations(&g.blocks) {
                for mode in &g.grid.modes {
                    let r = run_spec(g, &columns, &scene.name, mode, seed, &combo)?;
                    add_run(g, &mut runs, r)?;
                }
            }
        }
    }
    runs.sort_by_key(RunSpec::stage);
    Ok(Plan {
        grid: g.file.clone(),
        out: out.to_path_buf(),
        iters: g.grid.iters,
        downscale: g.grid.downscale,
        white_background: g.grid.white_background,
        duration_s: g.grid.duration_s,
        offline,
        columns,
        scenes,
        runs,
    })
}

/// Adds `r` unless the same run is there already (a shared baseline); two different runs
/// with one name are an error.
fn add_run(g: &CheckedGrid, runs: &mut Vec<RunSpec>, r: RunSpec) -> Result<()> {
    match runs.iter().find(|o| o.name == r.name) {
        Some(o) if *o == r => Ok(()),
        Some(_) => bail!(
            "{}: two different runs get the name `{}` (values that differ only in characters a folder name cannot hold?)",
            g.file.display(),
            r.name
        ),
        None => {
            runs.push(r);
            Ok(())
        }
    }
}

/// Every override combination: the union of each block's cartesian product, in order,
/// without repeats; one empty combination when there is no block.
fn combinations(blocks: &[Vec<Axis>]) -> Vec<Overrides> {
    if blocks.is_empty() {
        return vec![Overrides::new()];
    }
    let mut all: Vec<Overrides> = Vec::new();
    for block in blocks {
        let mut combos = vec![Overrides::new()];
        for axis in block {
            combos = combos
                .into_iter()
                .flat_map(|c| {
                    axis.values.iter().map(move |v| {
                        let mut c = c.clone();
                        c.insert(axis.key.clone(), v.clone());
                        c
                    })
                })
                .collect();
        }
        for c in combos {
            if !all.contains(&c) {
                all.push(c);
            }
        }
    }
    all
}

/// The run of `mode` for one combination: the overrides its mode uses, its name, config
/// and the run it forks from.
fn run_spec(
    g: &CheckedGrid,
    columns: &[String],
    scene: &str,
    mode: &str,
    seed: u64,
    combo: &Overrides,
) -> Result<RunSpec> {
    let method = methods::method(mode).context("modes are checked")?;
    let used = used_overrides(method, combo);
    let name = run_name(columns, scene, mode, &used, seed);
    let config = run_config(g, &name, method, &used)?;
    let fork_from = method.training.fork_from.map(|from| {
        let base = methods::method(from).expect("METHODS forks from a listed method");
        run_name(columns, scene, from, &used_overrides(base, combo), seed)
    });
    Ok(RunSpec {
        name,
        scene: scene.to_string(),
        mode: mode.to_string(),
        seed,
        overrides: used
            .iter()
            .map(|(k, v)| (k.clone(), grid::to_json(v)))
            .collect(),
        fork_from,
        config,
    })
}

/// A mode trained without the regularizer is the same run whatever `[reg]` says.
fn used_overrides(method: &Method, combo: &Overrides) -> Overrides {
    combo
        .iter()
        .filter(|(k, _)| method.training.reg || !k.starts_with("reg."))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

/// `<scene>_<mode>[_<key>=<value>]…_s<seed>`, keys by their last dotted part unless two
/// columns share it (then the whole key, dots as `-`).
pub fn run_name(
    columns: &[String],
    scene: &str,
    mode: &str,
    used: &Overrides,
    seed: u64,
) -> String {
    let mut name = format!("{scene}_{mode}");
    for (key, value) in used {
        let last = key.rsplit('.').next().unwrap_or(key);
        let shared = columns
            .iter()
            .filter(|c| c.rsplit('.').next() == Some(last))
            .count()
            > 1;
        let short = if shared {
            key.replace('.', "-")
        } else {
            last.to_string()
        };
        name.push_str(&format!("_{short}={}", value_text(value)));
    }
    name.push_str(&format!("_s{seed}"));
    name
}

/// A value as it appears in run names: TOML's text, unquoted, with any character a
/// folder name should not hold as `-`.
fn value_text(v: &toml::Value) -> String {
    let text = match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    text.chars()
        .map(|c| if grid::name_char(c) { c } else { '-' })
        .collect()
}

/// The run's training config: the grid's `[config]` with its overrides set, checked as
/// `train` would check it (with its mode's switches and `iters`).
fn run_config(g: &CheckedGrid, name: &str, method: &Method, used: &Overrides) -> Result<String> {
    let mut table = g.grid.config.clone();
    for (key, value) in used {
        set_dotted(&mut table, key, value.clone());
    }
    let at = format!("run `{name}`");
    let mut cfg = grid::config_from(&g.file, &table, &at)?;
    cfg.reg.enabled = method.training.reg;
    cfg.objects.enabled = method.training.objects;
    let f = g.file.display();
    cfg.validate().with_context(|| format!("{f}: {at}"))?;
    if let Some(n) = g.grid.iters {
        cfg.rescaled(n)
            .with_context(|| format!("{f}: {at} with iters = {n}"))?;
    }
    toml::to_string(&table).context("writing a run's config")
}

fn set_dotted(table: &mut toml::Table, key: &str, value: toml::Value) {
    let mut t = table;
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        if parts.peek().is_none() {
            t.insert(part.to_string(), value);
            return;
        }
        let entry = t
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if !entry.is_table() {
            *entry = toml::Value::Table(toml::Table::new());
        }
        t = entry.as_table_mut().expect("made a table above");
    }
}

/// Where scene `s` lives: `OUT/scenes/<name>` for a recipe, else its folder (relative to
/// the grid file's), which must exist, with object-ID maps when a mode needs them.
fn scene_plan(g: &CheckedGrid, i: usize, s: &SceneSpec, out: &Path) -> Result<ScenePlan> {
    let at = format!("{}: scenes[{i}] (`{}`)", g.file.display(), s.name);
    let (dir, segment) = match &s.path {
        None => (
            out.join("scenes").join(&s.name),
            Some(s.segment.clone().unwrap_or_default()),
        ),
        Some(p) => {
            let base = g.file.parent().unwrap_or(Path::new("."));
            let dir = std::fs::canonicalize(base.join(p))
                .with_context(|| format!("{at}: `path` {}", base.join(p).display()))?;
            (dir, s.segment.clone())
        }
    };
    let needs_ids = g
        .grid
        .modes
        .iter()
        .any(|m| methods::method(m).is_some_and(|m| m.training.reg || m.training.objects));
    if needs_ids && segment.is_none() && !dir.join("semantics").join("semantics.json").is_file() {
        bail!("{at}: the modes need object-ID maps, but {} has no semantics/ (run `semdynreg segment`, or give `segment`)", dir.display());
    }
    Ok(ScenePlan {
        name: s.name.clone(),
        dir,
        synth: s.synth.clone(),
        segment,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(text: &str) -> Plan {
        let g = grid::parse(Path::new("/x/g.toml"), text).unwrap();
        expand(&g, Path::new("/out"), true).unwrap()
    }

    const ABLATION: &str = r#"
modes = ["baseline", "semdynreg"]
[[scenes]]
name = "scene1"
synth = {}
[config.init]
random_points = 20000
[[sweep]]
reg.k = [1, 3, 8]
reg.lambda = [0.1]
[[sweep]]
reg.k = [3]
reg.lambda = [0.01, 0.1, 1.0]
"#;

    #[test]
    fn the_ablation_shares_one_baseline_and_forks_five_runs() {
        let p = plan(ABLATION);
        let names: Vec<&str> = p.runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "scene1_baseline_s0",
                "scene1_semdynreg_k=1_lambda=0.1_s0",
                "scene1_semdynreg_k=3_lambda=0.1_s0",
                "scene1_semdynreg_k=8_lambda=0.1_s0",
                "scene1_semdynreg_k=3_lambda=0.01_s0",
                "scene1_semdynreg_k=3_lambda=1.0_s0",
            ]
        );
        assert!(p.runs[1..]
            .iter()
            .all(|r| r.fork_from.as_deref() == Some("scene1_baseline_s0") && r.stage() == 1));
        assert!(p.runs[0].overrides.is_empty() && p.runs[0].fork_from.is_none());
        let cfg: toml::Table = toml::from_str(&p.runs[4].config).unwrap();
        assert_eq!(cfg["reg"]["lambda"].as_float(), Some(0.01));
        assert_eq!(cfg["init"]["random_points"].as_integer(), Some(20000));
        assert_eq!(p.columns, ["reg.k", "reg.lambda"]);
        assert_eq!(p.scenes[0].dir, Path::new("/out/scenes/scene1"));
    }

    #[test]
    fn the_repository_ablation_grid_is_the_scripts_grid() {
        let text = include_str!("../../../../configs/sweeps/ablation.toml");
        let p = plan(text);
        let names: Vec<&str> = p.runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            plan(ABLATION)
                .runs
                .iter()
                .map(|r| r.name.as_str())
                .collect::<Vec<_>>()
        );
        assert_eq!(p.iters, Some(3000));
        let synth = p.scenes[0].synth.as_ref().unwrap();
        assert_eq!((synth.width, synth.height, synth.frames), (160, 120, 96));
        let short = plan(include_str!(
            "../../../../configs/sweeps/ablation_drive025.toml"
        ));
        assert_eq!(short.runs.len(), 5);
        let groups = plan(include_str!(
            "../../../../configs/sweeps/membership_drive025.toml"
        ));
        assert_eq!(groups.runs.len(), 7);
        assert!(groups.runs.iter().all(|r| r
            .fork_from
            .as_deref()
            .is_none_or(|f| f == "drive025_baseline_s0")));
    }

    #[test]
    fn names_are_stable_and_baselines_split_on_non_reg_keys() {
        let p = plan(
            "modes = [\"semdynreg\", \"baseline\"]\nseeds = [1, 2]\n[[scenes]]\nname = \"a\"\nsynth = {}\n[[sweep]]\nfield.deform_scale = [true, false]\n",
        );
        // Two seeds × two field settings, each with its own baseline.
        assert_eq!(p.runs.len(), 8);
        let fork = p
            .runs
            .iter()
            .find(|r| r.name == "a_semdynreg_deform_scale=false_s2")
            .unwrap();
        assert_eq!(
            fork.fork_from.as_deref(),
            Some("a_baseline_deform_scale=false_s2")
        );
        assert!(p
            .runs
            .iter()
            .any(|r| r.name == "a_baseline_deform_scale=false_s2"));
        // Planning again gives the same plan (names and order do not depend on anything else).
        assert_eq!(p, plan("modes = [\"semdynreg\", \"baseline\"]\nseeds = [1, 2]\n[[scenes]]\nname = \"a\"\nsynth = {}\n[[sweep]]\nfield.deform_scale = [true, false]\n"));
    }

    #[test]
    fn a_bad_value_is_refused_naming_the_run() {
        let g = grid::parse(
            Path::new("g.toml"),
            "modes = [\"baseline\"]\n[[scenes]]\nname = \"a\"\nsynth = {}\n[[sweep]]\ninit.random_points = [\"many\"]\n",
        )
        .unwrap();
        let e = format!("{:#}", expand(&g, Path::new("/out"), true).unwrap_err());
        assert!(
            e.contains("g.toml: run `a_baseline_random_points=many_s0`"),
            "{e}"
        );
    }

    #[test]
    fn a_changed_run_is_refused_in_the_same_folder() {
        let a = plan(ABLATION);
        let b = plan(&ABLATION.replace("20000", "1000"));
        let e = b.check_against(&a).unwrap_err().to_string();
        assert!(e.contains("scene1_baseline_s0"), "{e}");
        a.check_against(&a).unwrap();
    }
}
