//! `deformation_consistency_rms` and the rigidity residual of a trained run: the
//! metrics are defined and computed by `train::regularizer::consistency` and
//! `train::regularizer::rigidity`; this file only feeds them from a run folder.
//!
//! Choices: the vehicle groups are built once, at the earliest test frame (`t_ref`), from
//! the top-k (k of the regularizer's default config) of the run's render at `t_ref` and the
//! ground-truth mask of that view; every vehicle (moving and static) is tracked; errors are
//! taken at every test frame with the field evaluated on all Gaussians (rigid objects of an
//! `--objects` run placed by their trajectories). Both metrics use the same groups and the
//! same positions.

use super::parts::{PartAccumulator, PartFollow};
use anyhow::{bail, Context, Result};
use scene::objects::ObjectsFile;
use scene::Frame;
use splat::{Colors, Gaussians, Rasterizer, RenderOptions};
use std::path::Path;
use train::checkpoint::LoadedModel;
use train::model::{GaussianModel, SH_COEFFS};
use train::regularizer::rigidity::Attached;
use train::regularizer::{
    ConsistencyAccumulator, ConsistencyReport, ObjectGroups, ObjectTrack, RegConfig,
    RigidityAccumulator, RigidityReport, TopKView,
};
use train::render::deformed_model;
use train::{checkpoint, run::RunInfo};

/// Top-k ids of a render of `m` (already deformed) from `frame`'s camera.
fn render_topk(
    m: &GaussianModel,
    frame: &Frame,
    background: [f32; 3],
    k: usize,
) -> Result<Vec<u32>> {
    let scales: Vec<f32> = m.log_scales.iter().map(|s| s.exp()).collect();
    let g = Gaussians {
        means: &m.means,
        quats: &m.quats,
        scales: &scales,
        opacity_logits: &m.opacity_logits,
        colors: Colors::Sh {
            coeffs: &m.sh,
            num_coeffs: SH_COEFFS,
            degree: m.sh_degree,
        },
    };
    let opts = RenderOptions {
        background,
        topk: k,
        ..RenderOptions::default()
    };
    let mut raster = Rasterizer::new();
    Ok(raster.forward(&g, &frame.camera, &opts)?.topk_ids.to_vec())
}

/// The Gaussians placed at `t` by the checkpoint's nodes (canonical field rows while the
/// field is still in warm-up, rigid objects by their trajectories).
fn at_time(m: &mut LoadedModel, t: f32) -> GaussianModel {
    deformed_model(m.scene(), t)
}

/// Both vehicle metrics of one run.
pub struct VehicleMetrics {
    /// How far the vehicles' Gaussians stray from the true rigid motion.
    pub consistency: ConsistencyReport,
    /// How rigidly they move together, whatever the motion.
    pub rigidity: RigidityReport,
    /// Runs with rigid objects only: `consistency` again over each group's members split by
    /// whether they belong to that object's node.
    pub node_split: Option<NodeSplit>,
    /// Runs with rigid objects only: what the objects' start decided for each object.
    pub rigid: Vec<RigidStart>,
    /// Scenes with articulated objects only: each part's follow (`report::parts`).
    pub parts: Vec<PartFollow>,
}

/// The start's decision on one object and the confidence of its gauge.
pub struct RigidStart {
    pub id: u8,
    /// `static` (one pose), `moving`, `parts` (articulated: several rigid parts) or
    /// `field` (left to the deformation field).
    pub decision: &'static str,
    /// The gauge's confidence for a mover placed by its cues (`objects::scale`).
    pub scale_confidence: Option<f32>,
}

/// The start's decisions from the checkpoint's start reports, or from the objects
/// themselves for checkpoints written before the reports were kept.
fn rigid_starts(loaded: &train::checkpoint::LoadedModel) -> Vec<RigidStart> {
    let reports = loaded.start_reports();
    if reports.is_empty() {
        return loaded
            .objects()
            .iter()
            .map(|o| RigidStart {
                id: o.id,
                decision: if o.is_static { "static" } else { "moving" },
                scale_confidence: None,
            })
            .collect();
    }
    reports
        .iter()
        .map(|r| RigidStart {
            id: r.id,
            decision: match (r.left_to_field, r.is_static) {
                (true, _) => "field",
                _ if r.parts.is_some_and(|p| p.kept) => "parts",
                (false, true) => "static",
                (false, false) => "moving",
            },
            scale_confidence: r.gauge.map(|g| g.confidence),
        })
        .collect()
}

/// A vehicle's group is whatever the render at `t_ref` drew inside its ground-truth mask. In
/// a run with rigid objects that is mostly the object's own Gaussians (placed by its
/// trajectory), plus background Gaussians the render also drew there: ground seen through
/// thin or semi-transparent parts and along the silhouette, which stay put. `follow` pools
/// both, so it reads low whenever the second kind is numerous; this split says which
/// Gaussians lag.
pub struct NodeSplit {
    /// Members whose object column holds the group's object.
    pub in_node: Option<ConsistencyReport>,
    /// The other members (the deformable background and other objects).
    pub outside: Option<ConsistencyReport>,
    /// Per object: the share of its group's members that are in its node.
    pub share: Vec<(u8, f64)>,
}

/// Members of `members` whose `column` entry is (`inside`) or is not `object`.
fn members_by_node(members: &[u32], column: &[u8], object: u8, inside: bool) -> Vec<u32> {
    members
        .iter()
        .copied()
        .filter(|&m| (column.get(m as usize) == Some(&object)) == inside)
        .collect()
}

/// Feeds a [`NodeSplit`]: each group's members split once, then the same tracks as the
/// pooled metric over each part.
struct SplitAccumulator {
    /// Per group (in `ObjectGroups` order): [members in the node, the others].
    parts: Vec<[Vec<u32>; 2]>,
    share: Vec<(u8, f64)>,
    acc: [ConsistencyAccumulator; 2],
}

impl SplitAccumulator {
    fn new(groups: &ObjectGroups, column: &[u8]) -> Self {
        let parts: Vec<[Vec<u32>; 2]> = groups
            .iter()
            .map(|g| {
                [true, false].map(|inside| members_by_node(g.members, column, g.object, inside))
            })
            .collect();
        let share = groups
            .iter()
            .zip(&parts)
            .map(|(g, p)| (g.object, p[0].len() as f64 / g.members.len().max(1) as f64))
            .collect();
        Self {
            parts,
            share,
            acc: Default::default(),
        }
    }

    /// `tracks[j]` is the track of group `groups_of[j]`.
    fn add_time(
        &mut self,
        time: f32,
        (tracks, groups_of): (&[ObjectTrack], &[usize]),
        anchor: &[f32],
        deformed: &[f32],
    ) -> Result<()> {
        for (side, acc) in self.acc.iter_mut().enumerate() {
            let sub: Vec<ObjectTrack> = tracks
                .iter()
                .zip(groups_of)
                .map(|(t, &k)| ObjectTrack {
                    members: &self.parts[k][side],
                    ..*t
                })
                .collect();
            acc.add_time(time, &sub, anchor, deformed)?;
        }
        Ok(())
    }

    fn finish(self) -> NodeSplit {
        let [a, b] = self.acc;
        NodeSplit {
            in_node: a.report().ok(),
            outside: b.report().ok(),
            share: self.share,
        }
    }
}

/// The metrics for the latest checkpoint of `run` (or iteration's), over its scene's test
/// frames.
pub fn run_consistency(run: &Path, iteration: Option<u32>) -> Result<VehicleMetrics> {
    let info = RunInfo::load(run)?;
    let ds = info
        .dataset()
        .with_context(|| format!("loading {}", info.scene.display()))?;
    let objects_path = info.scene.join("objects.json");
    let objects = ObjectsFile::load(&objects_path)?;
    let dir = checkpoint::select(run, iteration)?;
    let mut loaded =
        checkpoint::load_model(&dir).with_context(|| format!("loading {}", dir.display()))?;
    let mut test: Vec<&Frame> = ds.test.iter().collect();
    test.sort_by(|a, b| a.time.total_cmp(&b.time));
    let Some(reference) = test.first().copied() else {
        bail!("{} has no test frames", ds.root.display());
    };
    let mask = scene::load_mask(&ds.gt_mask_path(reference))?;
    let k = RegConfig::default().k;
    let anchor = at_time(&mut loaded, reference.time);
    let ids = render_topk(&anchor, reference, ds.background, k)?;
    let mut groups = ObjectGroups::new();
    groups.build(
        TopKView {
            ids: &ids,
            stride: k,
        },
        k,
        &mask.data,
        loaded.model.len(),
    )?;
    let pose = |f: &Frame| {
        objects.frame(&f.file_path).with_context(|| {
            format!(
                "{} has no pose for frame {}",
                objects_path.display(),
                f.file_path
            )
        })
    };
    let pose_ref = pose(reference)?;
    let mut acc = ConsistencyAccumulator::new();
    let mut rigidity = RigidityAccumulator::new();
    // An articulated object's parts count as its node.
    let by_mask = train::objects::column_by_mask(loaded.objects(), &loaded.column);
    let mut split =
        (!loaded.objects().is_empty()).then(|| SplitAccumulator::new(&groups, &by_mask));
    let mut parts = match objects.objects.iter().any(|o| !o.parts.is_empty()) {
        true => {
            let path = scene::part_map_path(&ds.root, &reference.file_path);
            let map = scene::load_mask(&path)?;
            let topk = TopKView {
                ids: &ids,
                stride: k,
            };
            let maps = (&mask.data[..], &map.data[..]);
            let column = (&objects, &by_mask[..]);
            PartAccumulator::new(topk, k, maps, column, loaded.model.len())?
        }
        false => None,
    };
    for f in &test {
        let pose_t = pose(f)?;
        let deformed = at_time(&mut loaded, f.time);
        let (mut tracks, mut groups_of) = (Vec::new(), Vec::new());
        for (k, g) in groups.iter().enumerate() {
            let Some(i) = objects.objects.iter().position(|o| o.id == g.object) else {
                continue; // an ID in the mask that objects.json does not list
            };
            tracks.push(ObjectTrack {
                object: g.object,
                members: g.members,
                pose_ref: &pose_ref.object_to_world[i],
                pose_t: &pose_t.object_to_world[i],
            });
            groups_of.push(k);
        }
        acc.add_time(f.time, &tracks, &anchor.means, &deformed.means)?;
        if let Some(s) = &mut split {
            s.add_time(
                f.time,
                (&tracks, &groups_of),
                &anchor.means,
                &deformed.means,
            )?;
        }
        if let Some(p) = &mut parts {
            p.add_time(f.time, (pose_ref, pose_t), &anchor.means, &deformed.means)?;
        }
        let attached: Vec<Attached> = tracks
            .iter()
            .map(|t| Attached {
                object: t.object,
                members: t.members,
            })
            .collect();
        rigidity.add_time(f.time, &attached, &anchor.means, &deformed.means)?;
    }
    Ok(VehicleMetrics {
        consistency: acc.report()?,
        rigidity: rigidity.report()?,
        node_split: split.map(SplitAccumulator::finish),
        rigid: rigid_starts(&loaded),
        parts: parts.map_or_else(Vec::new, |p| p.finish(&objects)),
    })
}

/// [`run_consistency`] with object names, as JSON for `semdynreg eval`
/// (`RUN/eval/consistency.json`): `rms`, `per_time`, `rigidity_rms` (pooled),
/// `rigidity_per_time`, and per vehicle `rms`, `rms_if_still`, `follow` (`null` for a
/// vehicle that does not move) and `rigidity_rms`; for runs with rigid objects also
/// `node_share`, `follow_in_node` and `follow_outside` ([`NodeSplit`]); for articulated
/// objects `parts`: per part (`body` first) its `members` and `follow`. `None` when the run's scene has no
/// `objects.json` (not a toycars scene).
pub fn named_consistency(run: &Path, iteration: Option<u32>) -> Result<Option<serde_json::Value>> {
    let info = RunInfo::load(run)?;
    let objects_path = info.scene.join("objects.json");
    if !objects_path.is_file() {
        return Ok(None);
    }
    let objects = ObjectsFile::load(&objects_path)?;
    let VehicleMetrics {
        consistency: r,
        rigidity,
        node_split,
        parts,
        ..
    } = run_consistency(run, iteration)?;
    let follow_in = |rep: &Option<ConsistencyReport>, id: u8| {
        rep.as_ref()
            .and_then(|r| r.per_object.iter().find(|o| o.object == id))
            .and_then(|o| o.follow())
    };
    let rigid_of = |id: u8| {
        rigidity
            .per_object
            .iter()
            .find(|o| o.object == id)
            .map(|o| o.rms)
    };
    let name = |id: u8| {
        objects
            .objects
            .iter()
            .find(|o| o.id == id)
            .map_or_else(|| id.to_string(), |o| o.name.clone())
    };
    let per_object: serde_json::Map<String, serde_json::Value> = r
        .per_object
        .iter()
        .map(|o| {
            let mut v = serde_json::json!({"rms": o.rms, "rms_if_still": o.rms_if_still,
                "follow": o.follow(), "rigidity_rms": rigid_of(o.object)});
            if let Some(ns) = &node_split {
                let share = ns.share.iter().find(|s| s.0 == o.object).map(|s| s.1);
                v["node_share"] = serde_json::json!(share);
                v["follow_in_node"] = serde_json::json!(follow_in(&ns.in_node, o.object));
                v["follow_outside"] = serde_json::json!(follow_in(&ns.outside, o.object));
            }
            let of_object: serde_json::Map<String, serde_json::Value> = parts
                .iter()
                .filter(|p| p.object == o.object)
                .map(|p| {
                    let v = serde_json::json!({"members": p.members, "follow": p.follow,
                        "in_node": p.in_node, "follow_in_node": p.follow_in_node});
                    (p.name.clone(), v)
                })
                .collect();
            if !of_object.is_empty() {
                v["parts"] = serde_json::Value::Object(of_object);
            }
            (name(o.object), v)
        })
        .collect();
    Ok(Some(serde_json::json!({
        "rms": r.rms, "per_object": per_object, "per_time": r.per_time,
        "rigidity_rms": rigidity.rms, "rigidity_per_time": rigidity.per_time,
        "checkpoint": checkpoint::select(run, iteration)?.display().to_string(),
    })))
}

#[cfg(test)]
mod tests {
    use super::members_by_node;

    #[test]
    fn members_split_by_their_object_column() {
        let column = [5u8, 255, 5, 7];
        let members = [0u32, 1, 2, 3];
        assert_eq!(members_by_node(&members, &column, 5, true), [0, 2]);
        assert_eq!(members_by_node(&members, &column, 5, false), [1, 3]);
        assert_eq!(members_by_node(&members, &column, 7, true), [3]);
        // A run without objects has no column: every member is outside.
        assert!(members_by_node(&members, &[], 5, true).is_empty());
        assert_eq!(members_by_node(&members, &[], 5, false), members);
    }
}
