//! The per-scene segmentation stage (docs/architecture.md "SemDynReg" 1–4): for every
//! training frame, masks (SAM automatic masks, or the scene's ground-truth masks) and a
//! label per mask (CLIP relevance against the dictionary, or the ground-truth ID the mask
//! overlaps most), painted into an 8-bit object-ID map `SCENE/semantics/<file_path>.png`
//! (255 = background) with a colour preview under `SCENE/semantics/preview/`, and
//! `SCENE/semantics/semantics.json` recording what they were made with. A later run with
//! the same inputs reuses them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::automask::{generate_from_embedding, AutoMasks, MaskGenConfig};
use crate::clip::{ClipError, ClipModel};
use crate::idmap::{color_of, BACKGROUND};
use crate::relevance::{object_ids, DictionaryEmbeddings, RelevanceError};
use crate::sam::{Sam, SamError};
use crate::track::scene::{TrackSpec, TrackSummary};

/// Canonical phrases of the relevance score (LERF).
pub const CANONICAL: [&str; 4] = crate::relevance::CANONICAL_PHRASES;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LabelSource {
    Clip,
    Gt,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskSource {
    Sam,
    Gt,
    /// The frames' alpha channel as one object (id 0): RGBA scenes such as D-NeRF's.
    Alpha,
}

/// Everything that determines the output; serialized into `semantics.json` and compared to
/// decide whether the cache is valid.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SegmentOptions {
    pub dictionary: Vec<String>,
    pub masks: MaskSource,
    pub labels: LabelSource,
    pub sam: PathBuf,
    pub clip: Option<PathBuf>,
    pub tau: f32,
    pub generator: GenConfigKey,
    /// `segment --track`: objects chosen once and tracked (`track/`), instead of masks and
    /// labels per frame. Absent from the record otherwise, so older caches stay valid.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track: Option<TrackSpec>,
}

/// The generator config in a comparable, serializable form.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GenConfigKey(pub serde_json::Value);

impl GenConfigKey {
    pub fn of(cfg: &MaskGenConfig) -> Self {
        Self(serde_json::to_value(cfg).unwrap_or_default())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    #[error(transparent)]
    Scene(#[from] scene::SceneError),
    #[error(transparent)]
    Sam(#[from] SamError),
    #[error(transparent)]
    Clip(#[from] ClipError),
    #[error(transparent)]
    Relevance(#[from] RelevanceError),
    #[error("{path}: {msg}")]
    Io { path: PathBuf, msg: String },
    #[error("{0}")]
    Input(String),
}

/// Per-frame outcome.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    pub file_path: String,
    pub masks: usize,
    pub labelled: usize,
    pub seconds: f64,
}

/// What a run did.
#[derive(Debug, Clone, Serialize)]
pub struct SegmentReport {
    pub cached: bool,
    pub frames: Vec<FrameReport>,
    /// Tracking's record (fresh `--track` runs only).
    pub track: Option<TrackSummary>,
}

#[derive(Serialize)]
struct Record<'a> {
    version: u32,
    options: &'a SegmentOptions,
    sam_checkpoint_bytes: Option<u64>,
    clip_checkpoint_bytes: Option<u64>,
    frames: &'a [FrameReport],
}

/// `SCENE/semantics/semantics.json`.
pub fn record_path(root: &Path) -> PathBuf {
    root.join("semantics").join("semantics.json")
}

/// `SCENE/semantics/preview/<file_path>.png`.
pub fn preview_path(root: &Path, file_path: &str) -> PathBuf {
    root.join("semantics")
        .join("preview")
        .join(format!("{file_path}.png"))
}

fn file_len(p: Option<&Path>) -> Option<u64> {
    p.and_then(|p| std::fs::metadata(p).ok()).map(|m| m.len())
}

pub(crate) fn record_json(opts: &SegmentOptions, frames: &[FrameReport]) -> serde_json::Value {
    let clip = opts
        .clip
        .as_deref()
        .filter(|_| opts.labels == LabelSource::Clip && opts.masks == MaskSource::Sam);
    let sam = Some(opts.sam.as_path()).filter(|_| opts.masks == MaskSource::Sam);
    let rec = Record {
        version: 1,
        options: opts,
        sam_checkpoint_bytes: file_len(sam),
        clip_checkpoint_bytes: file_len(clip),
        frames,
    };
    serde_json::to_value(&rec).unwrap_or_default()
}

/// The cache is valid when `semantics.json` was written with the same options and model
/// files and the ID map of every frame in `file_paths` exists.
pub(crate) fn cached_report(
    root: &Path,
    opts: &SegmentOptions,
    file_paths: &[String],
) -> Option<SegmentReport> {
    let text = std::fs::read_to_string(record_path(root)).ok()?;
    let old: serde_json::Value = serde_json::from_str(&text).ok()?;
    let fresh = record_json(opts, &[]);
    for key in [
        "version",
        "options",
        "sam_checkpoint_bytes",
        "clip_checkpoint_bytes",
    ] {
        if old.get(key) != fresh.get(key) {
            return None;
        }
    }
    if !file_paths
        .iter()
        .all(|f| scene::semantics_path(root, f).is_file())
    {
        return None;
    }
    let reports: Vec<FrameReport> = old
        .get("frames")?
        .as_array()?
        .iter()
        .map(|f| FrameReport {
            file_path: f["file_path"].as_str().unwrap_or_default().to_string(),
            masks: f["masks"].as_u64().unwrap_or(0) as usize,
            labelled: f["labelled"].as_u64().unwrap_or(0) as usize,
            seconds: 0.0,
        })
        .collect();
    Some(SegmentReport {
        cached: true,
        frames: reports,
        track: None,
    })
}

/// Label each SAM mask with the ground-truth ID it overlaps most (background → `None`).
pub fn labels_from_gt(am: &AutoMasks, gt: &[u8]) -> Vec<Option<u8>> {
    let mut counts = vec![[0usize; 256]; am.masks.len()];
    for (&l, &g) in am.labels.iter().zip(gt) {
        if l != u16::MAX {
            counts[l as usize][g as usize] += 1;
        }
    }
    counts
        .iter()
        .map(|c| {
            let best = (0..256)
                .max_by_key(|&v| (c[v], std::cmp::Reverse(v)))
                .unwrap_or(255);
            (best != BACKGROUND as usize).then_some(best as u8)
        })
        .collect()
}

/// Paint per-mask labels through the generator's label map.
pub fn paint_labels(am: &AutoMasks, ids: &[Option<u8>]) -> Vec<u8> {
    am.labels
        .iter()
        .map(|&l| {
            if l == u16::MAX {
                BACKGROUND
            } else {
                ids[l as usize].unwrap_or(BACKGROUND)
            }
        })
        .collect()
}

/// A colour preview: object colours blended over the image, background dimmed.
pub fn preview(img: &scene::ImageU8, ids: &[u8]) -> scene::ImageU8 {
    let mut data = img.data.clone();
    for (px, &id) in data.chunks_exact_mut(3).zip(ids) {
        let col = color_of(id);
        for c in 0..3 {
            let v = f32::from(px[c]);
            px[c] = if id == BACKGROUND {
                (0.4 * v) as u8
            } else {
                (0.4 * v + 0.6 * f32::from(col[c])) as u8
            };
        }
    }
    scene::ImageU8 {
        width: img.width,
        height: img.height,
        data,
    }
}

/// CLIP model plus the encoded dictionary.
pub struct ClipLabeler {
    model: ClipModel,
    text: DictionaryEmbeddings,
    tau: f32,
}

impl ClipLabeler {
    pub fn load(path: &Path, dictionary: &[String], tau: f32) -> Result<Self, SegmentError> {
        if !path.is_file() {
            return Err(SegmentError::Input(format!(
                "CLIP weights {} not found: pass an OpenCLIP ViT-B/16 (or OpenAI ViT-B/32) checkpoint in \
                 safetensors form (open_clip_model.safetensors, with its open_clip_config.json beside it), \
                 or use `--labels gt` on scenes with ground-truth masks",
                path.display()
            )));
        }
        let model = ClipModel::load(path, &Default::default())?;
        let text = model.encode_dictionary(dictionary)?;
        text.validate()?;
        Ok(Self { model, text, tau })
    }

    /// Label each mask by CLIP relevance of its masked crop (docs/architecture.md 2–3).
    pub fn labels(
        &self,
        img: &scene::ImageU8,
        am: &AutoMasks,
    ) -> Result<Vec<Option<u8>>, SegmentError> {
        let rgb = image::RgbImage::from_raw(img.width, img.height, img.data.clone())
            .ok_or_else(|| SegmentError::Input("image buffer smaller than its size".into()))?;
        // One boolean mask per SAM mask, encoded in batches of `clip::MASK_BATCH` crops.
        let masks: Vec<Vec<bool>> = (0..am.masks.len())
            .map(|k| am.labels.iter().map(|&l| l as usize == k).collect())
            .collect();
        let feats = self.model.encode_masks(&rgb, &masks)?;
        Ok(object_ids(&feats, &self.text, self.tau)?)
    }
}

/// Models a run needs, loaded once.
struct Models {
    sam: Option<Sam>,
    clip: Option<ClipLabeler>,
}

fn load_models(opts: &SegmentOptions) -> Result<Models, SegmentError> {
    if opts.masks != MaskSource::Sam {
        return Ok(Models {
            sam: None,
            clip: None,
        });
    }
    let clip = match opts.labels {
        LabelSource::Gt => None,
        LabelSource::Clip => {
            let path = opts.clip.as_ref().ok_or_else(|| {
                SegmentError::Input(
                    "--labels clip needs CLIP weights: pass --clip PATH (OpenCLIP ViT-B/16 safetensors), \
                     or use --labels gt on scenes with ground-truth masks"
                        .into(),
                )
            })?;
            Some(ClipLabeler::load(path, &opts.dictionary, opts.tau)?)
        }
    };
    Ok(Models {
        sam: Some(Sam::load(&opts.sam)?),
        clip,
    })
}

fn frame_ids(
    root: &Path,
    frame: &scene::Frame,
    masks: MaskSource,
    models: &Models,
    gen: &MaskGenConfig,
) -> Result<(Vec<u8>, usize), SegmentError> {
    let img = &frame.image;
    let (w, h) = (img.width as usize, img.height as usize);
    if masks == MaskSource::Alpha {
        let ids = alpha_ids(root, frame)?;
        let n = usize::from(ids.contains(&0));
        return Ok((ids, n));
    }
    let gt = || -> Result<Vec<u8>, SegmentError> {
        let p = scene::mask_path(root, &frame.file_path);
        if !p.is_file() {
            return Err(SegmentError::Io {
                path: p,
                msg: "ground-truth mask missing (needed by --masks gt / --labels gt)".into(),
            });
        }
        let m = scene::load_mask(&p)?;
        if (m.width as usize, m.height as usize) != (w, h) {
            return Err(SegmentError::Io {
                path: p,
                msg: format!("mask is {}×{}, the image {w}×{h}", m.width, m.height),
            });
        }
        Ok(m.data)
    };
    let Some(sam) = &models.sam else {
        let ids = gt()?;
        let n = ids
            .iter()
            .filter(|&&v| v != BACKGROUND)
            .map(|&v| v as usize + 1)
            .max()
            .unwrap_or(0);
        return Ok((ids, n));
    };
    let emb = sam.embed(&img.data, h, w)?;
    let am = generate_from_embedding(sam, &emb, gen)?;
    let labels = match &models.clip {
        Some(c) => c.labels(img, &am)?,
        None => labels_from_gt(&am, &gt()?),
    };
    Ok((paint_labels(&am, &labels), am.masks.len()))
}

/// `--masks alpha`: the frame's own image file read again for its alpha channel (the
/// loaded frame is already composited over the background).
fn alpha_ids(root: &Path, frame: &scene::Frame) -> Result<Vec<u8>, SegmentError> {
    let path = scene::image_file(root, &frame.file_path).ok_or_else(|| {
        SegmentError::Input(format!(
            "{}: no image file for frame {} (--masks alpha reads D-NeRF/Blender layouts, \
             whose file_path names the image)",
            root.display(),
            frame.file_path
        ))
    })?;
    let ids = scene::load_alpha_ids(&path)?;
    if (ids.width, ids.height) != (frame.image.width, frame.image.height) {
        return Err(SegmentError::Io {
            path,
            msg: format!(
                "is {}×{}, the loaded frame {}×{}",
                ids.width, ids.height, frame.image.width, frame.image.height
            ),
        });
    }
    Ok(ids.data)
}

/// Segment every training frame of the scene at `root`; `progress(done, total)` is called
/// after each frame. With `force` the cache is ignored.
pub fn segment_scene(
    root: &Path,
    opts: &SegmentOptions,
    gen: &MaskGenConfig,
    force: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SegmentReport, SegmentError> {
    if let Some(spec) = &opts.track {
        return crate::track::scene::track_scene(root, opts, spec, gen, force, progress);
    }
    if opts.dictionary.is_empty()
        && opts.labels == LabelSource::Clip
        && opts.masks == MaskSource::Sam
    {
        return Err(RelevanceError::EmptyDictionary.into());
    }
    let ds = scene::load_dataset(root, &scene::LoadOptions::default())?;
    if ds.train.is_empty() {
        return Err(SegmentError::Input(format!(
            "{}: the scene has no training frames",
            root.display()
        )));
    }
    if !force {
        let names: Vec<String> = ds.train.iter().map(|f| f.file_path.clone()).collect();
        if let Some(r) = cached_report(root, opts, &names) {
            tracing::info!(
                "semantics cache in {} is up to date",
                record_path(root).display()
            );
            return Ok(r);
        }
    }
    let models = load_models(opts)?;
    let mut frames = Vec::with_capacity(ds.train.len());
    for (i, frame) in ds.train.iter().enumerate() {
        let t0 = Instant::now();
        let (ids, n_masks) = frame_ids(root, frame, opts.masks, &models, gen)?;
        let mask = scene::MaskU8 {
            width: frame.image.width,
            height: frame.image.height,
            data: ids,
        };
        scene::save_mask(&scene::semantics_path(root, &frame.file_path), &mask)?;
        preview(&frame.image, &mask.data).save_png(&preview_path(root, &frame.file_path))?;
        let labelled = {
            let mut seen = [false; 256];
            mask.data.iter().for_each(|&v| seen[v as usize] = true);
            seen[..255].iter().filter(|&&s| s).count()
        };
        frames.push(FrameReport {
            file_path: frame.file_path.clone(),
            masks: n_masks,
            labelled,
            seconds: t0.elapsed().as_secs_f64(),
        });
        progress(i + 1, ds.train.len());
    }
    let json = serde_json::to_string_pretty(&record_json(opts, &frames)).unwrap_or_default();
    scene::io::write_atomic(&record_path(root), |w| w.write_all(json.as_bytes()))?;
    Ok(SegmentReport {
        cached: false,
        frames,
        track: None,
    })
}
