//! Checkpoints of a run: `RUN/checkpoints/iter_NNNNNNN/` holding the canonical Gaussians as
//! a 3DGS PLY, everything else that evolves (the Gaussians' Adam moments and steps,
//! densification statistics, hook rows, the object column, each node's section, epoch
//! order, RNG position) as safetensors, and the resolved config, plus `checksums.json` (a CRC-32 per file and per tensor, verified on every load:
//! [`crate::integrity`]). A checkpoint is written in a hidden folder and renamed into place,
//! then `RUN/checkpoints/latest` is replaced atomically, so an interrupted save is never
//! "latest". A state with a non-finite value is never saved ([`crate::finite`]).

use crate::config::TrainConfig;
use crate::error::{Result, TrainError};
use crate::field::DeformField;
use crate::io::{create_dir_all, write_atomic};
use crate::model::{GaussianModel, ROWS};
use crate::node::{SectionReader, SectionWriter};
use crate::nodes::{NodeInit, Nodes};
use crate::objects::{RigidObject, RigidObjects};
use crate::render::Scene;
use crate::state::{AuxRows, DensifyStats, GaussianState};
use crate::trainer::Trainer;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use safetensors::{Dtype, SafeTensors};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// `-2`: the folder carries `checksums.json`; `-1` still loads, unverified. Each node's
/// section keeps the tensor and metadata names of these formats, so both load.
const FORMAT: &str = "semdynreg-train-2";
const FORMAT_UNVERIFIED: &str = "semdynreg-train-1";
const GROUPS: [&str; 5] = ["means", "quats", "log_scales", "opacity", "sh"];
pub const PLY_NAME: &str = "point_cloud.ply";
pub const STATE_NAME: &str = "state.safetensors";
pub const CONFIG_NAME: &str = "config.toml";

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

type Tensors = Vec<(String, Dtype, Vec<usize>, Vec<u8>)>;

/// Collects the nodes' sections into the state file's tensors and metadata.
struct Sections<'a> {
    tensors: &'a mut Tensors,
    meta: &'a mut HashMap<String, String>,
}

impl SectionWriter for Sections<'_> {
    fn tensor(&mut self, name: String, shape: Vec<usize>, values: &[f32]) {
        self.tensors
            .push((name, Dtype::F32, shape, f32_bytes(values)));
    }

    fn meta(&mut self, key: &str, value: String) {
        self.meta.insert(key.to_string(), value);
    }
}

/// Serializes everything but the Gaussians' parameters (those go to the PLY).
fn state_bytes(tr: &Trainer) -> Result<Vec<u8>> {
    let st = &tr.state;
    let n = st.len();
    let mut tensors: Tensors = Vec::new();
    let mut meta = HashMap::new();
    let mut f = |name: String, shape: Vec<usize>, v: &[f32]| {
        tensors.push((name, Dtype::F32, shape, f32_bytes(v)))
    };
    for ((a, g), r) in st.adam.iter().zip(GROUPS).zip(ROWS) {
        f(format!("adam.{g}.m"), vec![n, r], &a.m);
        f(format!("adam.{g}.v"), vec![n, r], &a.v);
    }
    f("stats.grad_accum".into(), vec![n], &st.stats.grad_accum);
    f("stats.denom".into(), vec![n], &st.stats.denom);
    f("stats.max_radii".into(), vec![n], &st.stats.max_radii);
    for a in &st.aux {
        f(format!("aux.{}", a.name), vec![n, a.cols], &a.data);
    }
    for node in tr.nodes.iter() {
        node.save(&mut Sections {
            tensors: &mut tensors,
            meta: &mut meta,
        });
    }
    tensors.push(("object".into(), Dtype::U8, vec![n], st.object.clone()));
    let order: Vec<u8> = tr.order.iter().flat_map(|x| x.to_le_bytes()).collect();
    tensors.push((
        "epoch.order".into(),
        Dtype::U32,
        vec![tr.order.len()],
        order,
    ));
    tensors.push((
        "rng.seed".into(),
        Dtype::U8,
        vec![32],
        tr.rng.get_seed().to_vec(),
    ));
    meta.insert("format".to_string(), FORMAT.to_string());
    let aux: Vec<&str> = st.aux.iter().map(|a| a.name.as_str()).collect();
    meta.insert("aux".to_string(), aux.join(","));
    meta.insert("train_seconds".to_string(), tr.train_seconds.to_string());
    meta.insert("iteration".to_string(), tr.iteration.to_string());
    meta.insert("sh_degree".to_string(), st.model.sh_degree.to_string());
    meta.insert("cursor".to_string(), tr.cursor.to_string());
    meta.insert("extent".to_string(), tr.extent.to_string());
    meta.insert("rng.stream".to_string(), tr.rng.get_stream().to_string());
    meta.insert(
        "rng.word_pos".to_string(),
        tr.rng.get_word_pos().to_string(),
    );
    let steps: Vec<String> = st.adam.iter().map(|a| a.step.to_string()).collect();
    meta.insert("adam.steps".to_string(), steps.join(","));
    let views: Vec<(String, safetensors::tensor::TensorView)> = tensors
        .iter()
        .map(|(name, dt, shape, data)| {
            let v = safetensors::tensor::TensorView::new(*dt, shape.clone(), data)
                .expect("sizes match by construction");
            (name.clone(), v)
        })
        .collect();
    safetensors::serialize(views, Some(meta))
        .map_err(|e| TrainError::Data(format!("safetensors: {e}")))
}

/// A file in a checkpoint folder that exempts it from pruning; it says why it is kept.
pub const KEEP_NAME: &str = "KEEP";

/// [`save`], and keep that checkpoint whatever `keep_checkpoints` says (the wall-time
/// marks of `log.checkpoint_minutes`); `why` is written into its `KEEP` file.
pub fn save_kept(tr: &Trainer, run: &Path, why: &str) -> Result<PathBuf> {
    let dir = save(tr, run)?;
    write_atomic(&dir.join(KEEP_NAME), why.as_bytes())?;
    Ok(dir)
}

/// Writes a checkpoint of `tr` under `run/checkpoints/` and points `latest` at it; keeps the
/// newest `tr.cfg.log.keep_checkpoints`, the one at the regularizer's fork point
/// ([`crate::fork`]) when present, and those saved by [`save_kept`]. Returns its folder.
pub fn save(tr: &Trainer, run: &Path) -> Result<PathBuf> {
    // Never a checkpoint of a diverged state: the last good one stays `latest`.
    if let Some(what) = tr.nonfinite() {
        return Err(TrainError::NonFinite {
            iteration: tr.iteration,
            what: format!("{what} (checkpoint not written)"),
        });
    }
    let root = run.join("checkpoints");
    create_dir_all(&root)?;
    remove_partial(&root);
    let name = format!("iter_{:07}", tr.iteration);
    let tmp = root.join(format!(".{name}.tmp"));
    create_dir_all(&tmp)?;
    if let Err(e) = write_files(tr, &tmp) {
        // A full disk or a read-only folder: leave nothing half-written behind.
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    let dst = install(&root, &name, &tmp)?;
    write_atomic(&root.join("latest"), name.as_bytes())?;
    let pinned = tr.cfg.reg.fork_point().map(|i| format!("iter_{i:07}"));
    prune_old(&root, &name, pinned.as_deref(), tr.cfg.log.keep_checkpoints);
    Ok(dst)
}

/// The files of a checkpoint of `tr`, written into the folder `dir`; `checksums.json` last.
fn write_files(tr: &Trainer, dir: &Path) -> Result<()> {
    let ply = crate::ply::to_bytes(&tr.state.model);
    write_atomic(&dir.join(PLY_NAME), &ply)?;
    let state = state_bytes(tr)?;
    write_atomic(&dir.join(STATE_NAME), &state)?;
    let config = tr.cfg.to_toml();
    write_atomic(&dir.join(CONFIG_NAME), config.as_bytes())?;
    crate::integrity::write(
        dir,
        (PLY_NAME, &tr.state.model, &ply),
        &[(STATE_NAME, &state), (CONFIG_NAME, config.as_bytes())],
    )
}

/// The hidden name a checkpoint folder gets on its way out: `why` is `replaced` (a new save
/// of the same iteration takes its name) or `pruned`. Every step of a save is then one
/// atomic rename, and a kill never leaves a half-deleted folder under a visible `iter_N`
/// name, which [`iterations`], `--fork` and `eval --iteration` would take for a checkpoint.
fn aside(root: &Path, name: &str, why: &str) -> PathBuf {
    root.join(format!(".{name}.{why}.tmp"))
}

/// Renames the finished folder `tmp` to `root/name`. An existing `root/name` (a save of the
/// same iteration, e.g. a resumed run's last one) is first moved aside and deleted after.
/// If a kill falls between the two renames, `latest` may name the missing folder:
/// [`restore_replaced`] puts the old one back.
fn install(root: &Path, name: &str, tmp: &Path) -> Result<PathBuf> {
    let dst = root.join(name);
    let old = aside(root, name, "replaced");
    let replacing = dst.exists();
    if replacing {
        let _ = std::fs::remove_dir_all(&old);
        std::fs::rename(&dst, &old).map_err(|e| TrainError::io(&dst, e))?;
    }
    if let Err(e) = std::fs::rename(tmp, &dst) {
        if replacing {
            let _ = std::fs::rename(&old, &dst);
        }
        return Err(TrainError::io(&dst, e));
    }
    if replacing {
        if let Err(e) = std::fs::remove_dir_all(&old) {
            tracing::warn!("could not remove {}: {e}", old.display());
        }
    }
    Ok(dst)
}

/// Puts `root/name` back from its `replaced` copy when a save was killed between moving it
/// aside and renaming the new one in. Returns whether `root/name` exists now.
fn restore_replaced(root: &Path, name: &str) -> bool {
    let dst = root.join(name);
    let old = aside(root, name, "replaced");
    if !dst.exists() && old.is_dir() {
        match std::fs::rename(&old, &dst) {
            Ok(()) => tracing::info!(
                "restored {} (a save of the same iteration was interrupted)",
                dst.display()
            ),
            Err(e) => tracing::warn!("could not restore {}: {e}", dst.display()),
        }
    }
    dst.is_dir()
}

/// Moves `root/name` aside, then deletes it.
fn remove_checkpoint_dir(root: &Path, name: &str) -> std::io::Result<()> {
    let hidden = aside(root, name, "pruned");
    std::fs::rename(root.join(name), &hidden)?;
    std::fs::remove_dir_all(&hidden)
}

/// Removes what an interrupted save left behind: hidden `.iter_*.tmp` folders and
/// `.latest.tmp-PID` files (one trainer writes a run at a time), except a `replaced`
/// folder whose checkpoint is missing, which is restored. Failures only log.
fn remove_partial(root: &Path) {
    let Ok(rd) = std::fs::read_dir(root) else {
        return;
    };
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !(name.starts_with('.') && name.contains(".tmp")) {
            continue;
        }
        if let Some(ck) = name
            .strip_prefix('.')
            .and_then(|n| n.strip_suffix(".replaced.tmp"))
        {
            if !root.join(ck).exists() && restore_replaced(root, ck) {
                continue;
            }
        }
        let p = e.path();
        let r = if p.is_dir() {
            std::fs::remove_dir_all(&p)
        } else {
            std::fs::remove_file(&p)
        };
        match r {
            Ok(()) => tracing::info!("removed {} (left by an interrupted save)", p.display()),
            Err(err) => tracing::warn!("could not remove {}: {err}", p.display()),
        }
    }
}

/// Removes all but the newest `keep` checkpoints (never `current`, `pinned` or one with a
/// `KEEP` file); failures only log.
fn prune_old(root: &Path, current: &str, pinned: Option<&str>, keep: usize) {
    let Ok(rd) = std::fs::read_dir(root) else {
        return;
    };
    let mut names: Vec<String> = rd
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("iter_") && Some(n.as_str()) != pinned)
        .filter(|n| !root.join(n).join(KEEP_NAME).exists())
        .collect();
    names.sort();
    let excess = names.len().saturating_sub(keep.max(1));
    for n in names.into_iter().take(excess).filter(|n| n != current) {
        if let Err(e) = remove_checkpoint_dir(root, &n) {
            tracing::warn!("could not remove old checkpoint {n}: {e}");
        }
    }
}

/// Folder of the latest checkpoint of a run (restoring it first if a save of the same
/// iteration was killed halfway: [`install`]).
pub fn latest(run: &Path) -> Result<PathBuf> {
    let p = run.join("checkpoints").join("latest");
    let name = std::fs::read_to_string(&p).map_err(|e| TrainError::io(&p, e))?;
    let dir = run.join("checkpoints").join(name.trim());
    if !restore_replaced(&run.join("checkpoints"), name.trim()) {
        return Err(TrainError::Checkpoint {
            path: p,
            problem: format!("names `{}`, which does not exist", name.trim()),
        });
    }
    Ok(dir)
}

/// The iterations of the checkpoints `run` holds, ascending (an empty list when it has
/// none yet).
pub fn iterations(run: &Path) -> Result<Vec<(u32, PathBuf)>> {
    let root = run.join("checkpoints");
    if !root.is_dir() {
        return Ok(Vec::new());
    }
    let rd = std::fs::read_dir(&root).map_err(|e| TrainError::io(&root, e))?;
    let mut found = Vec::new();
    for e in rd {
        let e = e.map_err(|e| TrainError::io(&root, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(it) = name.strip_prefix("iter_").and_then(|s| s.parse().ok()) {
            found.push((it, e.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// Folder of the checkpoint of `run` at `iteration`, or of its latest when `None`.
pub fn select(run: &Path, iteration: Option<u32>) -> Result<PathBuf> {
    let Some(it) = iteration else {
        return latest(run);
    };
    let held = iterations(run)?;
    if let Some((_, dir)) = held.iter().find(|(i, _)| *i == it) {
        return Ok(dir.clone());
    }
    let list: Vec<String> = held.iter().map(|(i, _)| i.to_string()).collect();
    Err(TrainError::NoSuchCheckpoint {
        folder: run.join("checkpoints"),
        iteration: it,
        held: if list.is_empty() {
            "none".into()
        } else {
            list.join(", ")
        },
    })
}

/// Parsed `state.safetensors`.
struct StateFile<'a> {
    st: SafeTensors<'a>,
    meta: HashMap<String, String>,
    path: PathBuf,
}

impl StateFile<'_> {
    fn err(&self, problem: impl Into<String>) -> TrainError {
        TrainError::Checkpoint {
            path: self.path.clone(),
            problem: problem.into(),
        }
    }

    fn meta<T: std::str::FromStr>(&self, key: &str) -> Result<T> {
        let v = self
            .meta
            .get(key)
            .ok_or_else(|| self.err(format!("metadata `{key}` missing")))?;
        v.parse()
            .map_err(|_| self.err(format!("metadata `{key}` = `{v}` is not valid")))
    }

    /// Like [`StateFile::meta`] for keys that older checkpoints lack: `default` when absent.
    fn meta_or<T: std::str::FromStr>(&self, key: &str, default: T) -> Result<T> {
        match self.meta.contains_key(key) {
            true => self.meta(key),
            false => Ok(default),
        }
    }

    fn bytes(&self, name: &str, dtype: Dtype, len: usize) -> Result<Vec<u8>> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.err(format!("tensor `{name}` missing")))?;
        let n: usize = t.shape().iter().product();
        if t.dtype() != dtype || n != len {
            return Err(self.err(format!(
                "tensor `{name}` is {:?} {:?}, expected {dtype:?} with {len} elements",
                t.dtype(),
                t.shape()
            )));
        }
        Ok(t.data().to_vec())
    }

    /// An f32 tensor of `len` elements, all finite.
    fn f32s(&self, name: &str, len: usize) -> Result<Vec<f32>> {
        let b = self.bytes(name, Dtype::F32, len)?;
        let v: Vec<f32> = b
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(self.err(format!(
                "tensor `{name}` has a non-finite value at element {i}"
            )));
        }
        Ok(v)
    }
}

/// The hook rows listed in metadata `aux` (absent in older checkpoints: none).
fn read_aux(sf: &StateFile<'_>, n: usize) -> Result<Vec<AuxRows>> {
    let names: String = sf.meta_or("aux", String::new())?;
    let mut out = Vec::new();
    for name in names.split(',').filter(|s| !s.is_empty()) {
        let key = format!("aux.{name}");
        let shape = sf
            .st
            .tensor(&key)
            .map_err(|_| sf.err(format!("tensor `{key}` missing")))?
            .shape()
            .to_vec();
        let cols = match shape[..] {
            [rows, cols] if rows == n && cols > 0 => cols,
            _ => {
                return Err(sf.err(format!(
                    "tensor `{key}` has shape {shape:?}, expected [{n}, cols]"
                )))
            }
        };
        out.push(AuxRows {
            name: name.to_string(),
            cols,
            data: sf.f32s(&key, n * cols)?,
        });
    }
    Ok(out)
}

/// The resolved config a checkpoint was trained with (without reading its tensors).
pub fn read_config(dir: &Path) -> Result<TrainConfig> {
    TrainConfig::from_toml_file(&dir.join(CONFIG_NAME))
}

impl SectionReader for StateFile<'_> {
    fn f32s(&self, name: &str, len: usize) -> Result<Vec<f32>> {
        StateFile::f32s(self, name, len)
    }

    fn len_of(&self, name: &str) -> Option<usize> {
        let t = self.st.tensor(name).ok()?;
        Some(t.shape().iter().product())
    }

    fn meta(&self, key: &str) -> Option<&str> {
        self.meta.get(key).map(String::as_str)
    }

    fn problem(&self, what: String) -> TrainError {
        self.err(what)
    }

    fn config_file(&self) -> PathBuf {
        self.path.with_file_name(CONFIG_NAME)
    }
}

/// What render, eval and export need of a checkpoint.
pub struct LoadedModel {
    pub cfg: TrainConfig,
    pub model: GaussianModel,
    pub iteration: u32,
    /// The object column (which node owns each Gaussian) and the nodes that place them.
    pub column: Vec<u8>,
    /// The per-Gaussian rows kept beside the parameters (skinning weights, votes).
    pub aux: Vec<AuxRows>,
    pub nodes: Nodes,
}

impl LoadedModel {
    /// The scene for [`crate::render`].
    pub fn scene(&mut self) -> Scene<'_> {
        Scene {
            model: &self.model,
            column: &self.column,
            aux: &self.aux,
            nodes: &mut self.nodes,
            iteration: self.iteration,
        }
    }

    /// The deformation field (every run has one).
    pub fn field(&self) -> Option<&DeformField> {
        let node = self.nodes.get::<crate::field_node::FieldNode>()?;
        Some(&node.field)
    }

    /// The rigid objects (none for runs without them).
    pub fn objects(&self) -> &[RigidObject] {
        self.nodes
            .get::<RigidObjects>()
            .map_or(&[][..], |n| n.objects.as_slice())
    }

    /// What the rigid objects' start found per object (empty for runs without them, and
    /// for checkpoints written before it was kept).
    pub fn start_reports(&self) -> &[crate::objects::start::StartReport] {
        self.nodes
            .get::<RigidObjects>()
            .map_or(&[][..], |n| n.start_reports.as_slice())
    }

    /// Whether the field was past its warm-up at this checkpoint (before it, δ = 0).
    pub fn field_active(&self) -> bool {
        self.iteration >= self.cfg.field.warm_up
    }
}

/// Opens `dir/state.safetensors` after verifying the folder's checksums (checkpoints of
/// format `-1`, from before them, load unverified).
fn open_state(dir: &Path) -> Result<Vec<u8>> {
    let verified = crate::integrity::verify(dir)?;
    let path = dir.join(STATE_NAME);
    let bytes = crate::io::read_file(&path)?;
    let sf = parse_state(&bytes, &path)?;
    if !verified && sf.meta::<String>("format")? == FORMAT {
        let missing = crate::integrity::CHECKSUMS_NAME;
        return Err(sf.err(format!(
            "its folder lacks {missing}: an incomplete or damaged checkpoint"
        )));
    }
    if !verified {
        tracing::warn!(
            "{} predates checkpoint checksums: loaded unverified",
            dir.display()
        );
    }
    Ok(bytes)
}

/// The nodes of `cfg`, each with its section of `sf` read back (and its optimizer state
/// when `dataset` is given: resuming training).
fn read_nodes(
    sf: &StateFile<'_>,
    cfg: &TrainConfig,
    dataset: Option<&scene::Dataset>,
) -> Result<Nodes> {
    // The state comes from the file: a throwaway stream for the constructors.
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut nodes = Nodes::build(NodeInit {
        cfg,
        dataset,
        rng: &mut rng,
    })?;
    for node in nodes.iter_mut() {
        node.load(sf)?;
        if dataset.is_some() {
            node.load_optimizer(sf)?;
        }
    }
    Ok(nodes)
}

/// The model, nodes and iteration of a checkpoint (for render/eval/export).
pub fn load_model(dir: &Path) -> Result<LoadedModel> {
    let bytes = open_state(dir)?;
    let sf = parse_state(&bytes, &dir.join(STATE_NAME))?;
    let cfg = read_config(dir)?;
    let (model, column) = read_rows(&sf, dir)?;
    let nodes = read_nodes(&sf, &cfg, None)?;
    check_column(&sf, &column, &nodes)?;
    let aux = read_aux(&sf, model.len())?;
    Ok(LoadedModel {
        cfg,
        model,
        iteration: sf.meta("iteration")?,
        column,
        aux,
        nodes,
    })
}

/// The PLY's Gaussians (with the state's SH degree) and the object column.
fn read_rows(sf: &StateFile<'_>, dir: &Path) -> Result<(GaussianModel, Vec<u8>)> {
    let mut model = crate::ply::read(&dir.join(PLY_NAME))?;
    check_count(sf, model.len(), &dir.join(PLY_NAME))?;
    model.sh_degree = sf.meta("sh_degree")?;
    if model.sh_degree > 3 {
        return Err(sf.err("sh_degree > 3"));
    }
    let column = read_column(sf, model.len())?;
    Ok((model, column))
}

/// The state's per-Gaussian rows (`stats.denom`, in every checkpoint) must be as many as
/// the PLY's Gaussians; a mismatch names both files, since either may be the wrong one.
fn check_count(sf: &StateFile<'_>, n: usize, ply: &Path) -> Result<()> {
    let Ok(t) = sf.st.tensor("stats.denom") else {
        return Ok(());
    };
    let rows = t.shape().first().copied().unwrap_or(0);
    if rows != n || t.shape().len() != 1 {
        return Err(sf.err(format!(
            "holds state for {rows} Gaussians (`stats.denom` {:?}) but {} holds {n}",
            t.shape(),
            ply.display()
        )));
    }
    Ok(())
}

/// The per-Gaussian object column (absent in runs from before objects: all the field's).
fn read_column(sf: &StateFile<'_>, n: usize) -> Result<Vec<u8>> {
    if sf.st.tensor("object").is_err() {
        return Ok(vec![crate::state::NO_OBJECT; n]);
    }
    sf.bytes("object", Dtype::U8, n)
}

/// Every object ID in the column belongs to a node of the checkpoint.
fn check_column(sf: &StateFile<'_>, column: &[u8], nodes: &Nodes) -> Result<()> {
    let mut known = [false; 256];
    for id in 0..=255u8 {
        known[id as usize] = nodes.owns(id);
    }
    match column.iter().position(|&id| !known[id as usize]) {
        Some(i) => Err(sf.err(format!(
            "Gaussian {i} belongs to object {}, which the checkpoint does not describe",
            column[i]
        ))),
        None => Ok(()),
    }
}

fn parse_state<'a>(bytes: &'a [u8], path: &Path) -> Result<StateFile<'a>> {
    let bad = |e: safetensors::SafeTensorError| TrainError::Checkpoint {
        path: path.to_path_buf(),
        problem: format!("not a readable safetensors file: {e}"),
    };
    let (_, m) = SafeTensors::read_metadata(bytes).map_err(bad)?;
    let meta = m.metadata().clone().unwrap_or_default();
    let st = SafeTensors::deserialize(bytes).map_err(bad)?;
    let sf = StateFile {
        st,
        meta,
        path: path.to_path_buf(),
    };
    let format: String = sf.meta("format")?;
    if format != FORMAT && format != FORMAT_UNVERIFIED {
        return Err(sf.err(format!(
            "format `{format}`, expected `{FORMAT}` (or the older `{FORMAT_UNVERIFIED}`)"
        )));
    }
    Ok(sf)
}

/// Rebuilds a trainer from a checkpoint folder so that training continues bit-identically.
pub fn load_trainer(dir: &Path, dataset: scene::Dataset) -> Result<Trainer> {
    let bytes = open_state(dir)?;
    let path = dir.join(STATE_NAME);
    let sf = parse_state(&bytes, &path)?;
    let cfg = read_config(dir)?;
    let (model, column) = read_rows(&sf, dir)?;
    let nodes = read_nodes(&sf, &cfg, Some(&dataset))?;
    check_column(&sf, &column, &nodes)?;
    let n = model.len();
    let mut seed = [0u8; 32];
    seed.copy_from_slice(&sf.bytes("rng.seed", Dtype::U8, 32)?);
    let mut rng = ChaCha8Rng::from_seed(seed);
    rng.set_stream(sf.meta("rng.stream")?);
    rng.set_word_pos(sf.meta("rng.word_pos")?);
    let extent: f32 = sf.meta("extent")?;
    let mut tr = Trainer::assemble(cfg, dataset, model, nodes, rng, extent);
    tr.iteration = sf.meta("iteration")?;
    read_store(&sf, &mut tr.state, n)?;
    tr.state.object = column;
    // Checkpoints from before this key existed resume with the clock at zero.
    tr.train_seconds = sf.meta_or("train_seconds", 0.0f64)?;
    if !(tr.train_seconds.is_finite() && tr.train_seconds >= 0.0) {
        return Err(sf.err("metadata `train_seconds` must be finite and ≥ 0"));
    }
    read_epoch(&sf, &mut tr)?;
    Ok(tr)
}

/// The Gaussians' Adam moments and steps, densification statistics and hook rows.
fn read_store(sf: &StateFile<'_>, state: &mut GaussianState, n: usize) -> Result<()> {
    let steps: String = sf.meta("adam.steps")?;
    let steps: Vec<u64> = steps.split(',').filter_map(|s| s.parse().ok()).collect();
    if steps.len() != 5 {
        return Err(sf.err("metadata `adam.steps` must list 5 integers"));
    }
    for (((a, g), r), s) in state.adam.iter_mut().zip(GROUPS).zip(ROWS).zip(steps) {
        a.m = sf.f32s(&format!("adam.{g}.m"), n * r)?;
        a.v = sf.f32s(&format!("adam.{g}.v"), n * r)?;
        a.step = s;
    }
    state.stats = DensifyStats {
        grad_accum: sf.f32s("stats.grad_accum", n)?,
        denom: sf.f32s("stats.denom", n)?,
        max_radii: sf.f32s("stats.max_radii", n)?,
    };
    state.aux = read_aux(sf, n)?;
    Ok(())
}

/// The epoch's frame order and the position in it.
fn read_epoch(sf: &StateFile<'_>, tr: &mut Trainer) -> Result<()> {
    let len = sf
        .st
        .tensor("epoch.order")
        .map(|t| t.shape().iter().product())
        .unwrap_or(0);
    tr.order = sf
        .bytes("epoch.order", Dtype::U32, len)?
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    tr.cursor = sf.meta("cursor")?;
    let n_train = tr.dataset.train.len() as u32;
    if tr.cursor > tr.order.len() || tr.order.iter().any(|&i| i >= n_train) {
        return Err(sf.err(format!(
            "epoch order does not fit the data set's {n_train} training frames"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkpoint-like folder holding one file with `text`.
    fn folder(path: &Path, text: &str) {
        std::fs::create_dir_all(path).unwrap();
        std::fs::write(path.join("f"), text).unwrap();
    }

    fn read(path: &Path) -> String {
        std::fs::read_to_string(path.join("f")).unwrap()
    }

    fn names(root: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(root)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_save_of_the_same_iteration_replaces_the_folder_and_leaves_nothing_hidden() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        folder(&root.join("iter_0000010"), "old");
        folder(&root.join(".iter_0000010.tmp"), "new");
        let dst = install(root, "iter_0000010", &root.join(".iter_0000010.tmp")).unwrap();
        assert_eq!(read(&dst), "new");
        assert_eq!(names(root), ["iter_0000010"]);
        // A first save of an iteration renames only.
        folder(&root.join(".iter_0000020.tmp"), "b");
        install(root, "iter_0000020", &root.join(".iter_0000020.tmp")).unwrap();
        assert_eq!(names(root), ["iter_0000010", "iter_0000020"]);
    }

    #[test]
    fn a_save_killed_between_its_renames_is_restored_and_prunes_leave_no_visible_half() {
        let run = tempfile::tempdir().unwrap();
        let root = run.path().join("checkpoints");
        // Killed after moving the old folder aside, before renaming the new one in:
        // `latest` names a missing folder.
        folder(&aside(&root, "iter_0000010", "replaced"), "old");
        folder(&root.join(".iter_0000010.tmp"), "half-written");
        std::fs::write(root.join("latest"), "iter_0000010").unwrap();
        let dir = latest(run.path()).unwrap();
        assert_eq!(read(&dir), "old", "the last complete save is back");
        // Killed while deleting a pruned folder: only a hidden name is left.
        folder(&aside(&root, "iter_0000005", "pruned"), "x");
        // A stale `replaced` copy of a folder that exists is junk.
        folder(&root.join("iter_0000007"), "new");
        folder(&aside(&root, "iter_0000007", "replaced"), "old");
        let its: Vec<u32> = iterations(run.path())
            .unwrap()
            .iter()
            .map(|p| p.0)
            .collect();
        assert_eq!(its, [7, 10], "hidden folders are not checkpoints");
        remove_partial(&root);
        assert_eq!(names(&root), ["iter_0000007", "iter_0000010", "latest"]);
        assert_eq!(read(&root.join("iter_0000007")), "new");
        // Pruning goes through a hidden name too.
        remove_checkpoint_dir(&root, "iter_0000007").unwrap();
        assert_eq!(names(&root), ["iter_0000010", "latest"]);
    }

    #[test]
    fn select_finds_a_held_iteration_and_lists_them_otherwise() {
        let run = tempfile::tempdir().unwrap();
        assert!(iterations(run.path()).unwrap().is_empty(), "no folder yet");
        let root = run.path().join("checkpoints");
        for name in ["iter_0000020", "iter_0000005", ".iter_0000030.tmp"] {
            std::fs::create_dir_all(root.join(name)).unwrap();
        }
        std::fs::write(root.join("latest"), "iter_0000020").unwrap();
        let its: Vec<u32> = iterations(run.path())
            .unwrap()
            .iter()
            .map(|p| p.0)
            .collect();
        assert_eq!(
            its,
            [5, 20],
            "sorted; the unfinished temporary one is not a checkpoint"
        );
        assert_eq!(select(run.path(), None).unwrap(), root.join("iter_0000020"));
        assert_eq!(
            select(run.path(), Some(5)).unwrap(),
            root.join("iter_0000005")
        );
        let err = select(run.path(), Some(30)).unwrap_err().to_string();
        assert!(
            err.contains("no checkpoint of iteration 30 (it holds: 5, 20)"),
            "{err}"
        );
    }
}
