//! Per-part follow of articulated objects (scenes whose `objects.json` lists `parts`, such
//! as the toycars crane): the Gaussians a render at `t_ref` draws inside each part's
//! pixels of the ground-truth part map (`parts/<file_path>.png`) form that part's group,
//! chosen as the objects' groups are (the paper's top-k, `train::regularizer::grouping`),
//! and every part is scored against its own true motion with the same metric as a whole
//! object (`train::regularizer::consistency`, `follow = 1 − rms/rms_if_still`).

use anyhow::Result;
use scene::objects::{ObjectFrame, ObjectsFile};
use train::regularizer::{ConsistencyAccumulator, ObjectGroups, ObjectTrack, TopKView};

/// One part's members.
struct PartMembers {
    object: u8,
    /// The object's index in `objects.json`.
    index: usize,
    /// The part's index in the object's `parts`; `None`: the body.
    part: Option<usize>,
    members: Vec<u32>,
    /// The members the object's own node holds (its column, parts counted as the object).
    in_node: Vec<u32>,
}

/// The follow of one part of an articulated object.
pub struct PartFollow {
    pub object: u8,
    /// `body` or the part's name.
    pub name: String,
    pub members: usize,
    pub follow: Option<f64>,
    /// Runs with objects: how many members the object's node holds, and their follow.
    pub in_node: usize,
    pub follow_in_node: Option<f64>,
}

/// Collects one test time after another, as `ConsistencyAccumulator` does, per part.
pub struct PartAccumulator {
    parts: Vec<PartMembers>,
    /// Per part: all its members, and those in the object's node.
    acc: Vec<[ConsistencyAccumulator; 2]>,
}

/// One slot per (articulated object, part) seen in the maps: `(object index, part)`.
type Slot = (usize, Option<usize>);

/// The ID map of parts: each pixel of an articulated object gets the index of its
/// (object, part) slot, every other pixel 255.
fn slot_map(ids: &[u8], parts: &[u8], objects: &ObjectsFile) -> (Vec<u8>, Vec<Slot>) {
    let mut slots: Vec<Slot> = Vec::new();
    let map = ids
        .iter()
        .zip(parts)
        .map(|(&id, &p)| {
            let index = objects.objects.iter().position(|o| o.id == id);
            let Some(index) = index.filter(|&i| !objects.objects[i].parts.is_empty()) else {
                return scene::MASK_BACKGROUND;
            };
            let part = match usize::from(p) {
                0 => None,
                k if k <= objects.objects[index].parts.len() => Some(k - 1),
                _ => return scene::MASK_BACKGROUND,
            };
            let slot = slots
                .iter()
                .position(|&s| s == (index, part))
                .unwrap_or_else(|| {
                    slots.push((index, part));
                    slots.len() - 1
                });
            u8::try_from(slot).unwrap_or(scene::MASK_BACKGROUND)
        })
        .collect();
    (map, slots)
}

/// The part→world matrix of `part` (the body's object→world for `None`).
fn matrix(frame: &ObjectFrame, index: usize, part: Option<usize>) -> &[[f32; 4]; 4] {
    match part {
        None => &frame.object_to_world[index],
        Some(k) => &frame.part_to_world[index][k],
    }
}

impl PartAccumulator {
    /// The parts' groups from a render's top-k at `t_ref` (`use_k` of them), the reference
    /// frame's ID map `ids` and part map `parts`; `None` when no articulated object shows.
    /// `column` (the run's object column with parts mapped to their object; empty without
    /// objects) says which members the object's node holds.
    pub fn new(
        topk: TopKView<'_>,
        use_k: usize,
        (ids, parts): (&[u8], &[u8]),
        (objects, column): (&ObjectsFile, &[u8]),
        n_gaussians: usize,
    ) -> Result<Option<Self>> {
        let (map, slots) = slot_map(ids, parts, objects);
        if slots.is_empty() {
            return Ok(None);
        }
        let mut groups = ObjectGroups::new();
        groups.build(topk, use_k, &map, n_gaussians)?;
        let groups = groups.iter().map(|g| (g.object, g.members));
        Ok(Self::from_groups(groups, &slots, (objects, column)))
    }

    /// [`Self::new`] from `(slot, members)` pairs.
    fn from_groups<'a>(
        groups: impl Iterator<Item = (u8, &'a [u32])>,
        slots: &[Slot],
        (objects, column): (&ObjectsFile, &[u8]),
    ) -> Option<Self> {
        let parts: Vec<PartMembers> = groups
            .filter_map(|(slot, members)| {
                let &(index, part) = slots.get(usize::from(slot))?;
                let object = objects.objects[index].id;
                let in_node = members
                    .iter()
                    .copied()
                    .filter(|&m| column.get(m as usize) == Some(&object))
                    .collect();
                Some(PartMembers {
                    object,
                    index,
                    part,
                    members: members.to_vec(),
                    in_node,
                })
            })
            .collect();
        (!parts.is_empty()).then(|| Self {
            acc: vec![[ConsistencyAccumulator::new(), ConsistencyAccumulator::new()]; parts.len()],
            parts,
        })
    }

    pub fn add_time(
        &mut self,
        time: f32,
        (pose_ref, pose_t): (&ObjectFrame, &ObjectFrame),
        anchor: &[f32],
        deformed: &[f32],
    ) -> Result<()> {
        for (p, acc) in self.parts.iter().zip(&mut self.acc) {
            for (members, acc) in [&p.members, &p.in_node].into_iter().zip(acc) {
                if members.is_empty() {
                    continue;
                }
                let track = ObjectTrack {
                    object: p.object,
                    members,
                    pose_ref: matrix(pose_ref, p.index, p.part),
                    pose_t: matrix(pose_t, p.index, p.part),
                };
                acc.add_time(time, &[track], anchor, deformed)?;
            }
        }
        Ok(())
    }

    pub fn finish(self, objects: &ObjectsFile) -> Vec<PartFollow> {
        self.parts
            .into_iter()
            .zip(self.acc)
            .map(|(p, acc)| PartFollow {
                object: p.object,
                name: p.part.map_or_else(
                    || "body".to_string(),
                    |k| objects.objects[p.index].parts[k].name.clone(),
                ),
                members: p.members.len(),
                in_node: p.in_node.len(),
                follow: follow(&acc[0]),
                follow_in_node: follow(&acc[1]),
            })
            .collect()
    }
}

fn follow(acc: &ConsistencyAccumulator) -> Option<f64> {
    let r = acc.report().ok()?;
    r.per_object.first().and_then(|o| o.follow())
}

#[cfg(test)]
mod tests {
    use super::*;
    use scene::objects::{ObjectInfo, PartInfo};

    fn shifted(x: f32) -> [[f32; 4]; 4] {
        [
            [1.0, 0.0, 0.0, x],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// A crane (ID 2, parts boom and bucket) beside a rigid car (ID 0), at two frames: the
    /// body stands still, the boom slides 0.2 along x, the bucket with it.
    fn scene() -> ObjectsFile {
        let part = |name: &str, parent| PartInfo {
            name: name.into(),
            parent,
            bbox_local: [[0.0; 3], [0.1; 3]],
        };
        let info = |id: u8, name: &str, parts: Vec<PartInfo>| ObjectInfo {
            id,
            name: name.into(),
            prompt: String::new(),
            moving: true,
            bbox_local: [[-1.0; 3], [1.0; 3]],
            parts,
        };
        ObjectsFile {
            objects: vec![
                info(0, "car", Vec::new()),
                info(
                    2,
                    "crane",
                    vec![part("boom", None), part("bucket", Some(0))],
                ),
            ],
            frames: [(0.0, 0.0), (1.0, 0.2)]
                .iter()
                .map(|&(time, dx)| ObjectFrame {
                    file_path: format!("test/{time}"),
                    time,
                    object_to_world: vec![shifted(dx), shifted(0.0)],
                    part_to_world: vec![Vec::new(), vec![shifted(0.5 + dx), shifted(0.8 + dx)]],
                })
                .collect(),
            extra: Default::default(),
        }
    }

    /// Pixels of the crane get one slot per part they show, in order of appearance; the
    /// car's pixels, the background and part values the object does not have get none.
    #[test]
    fn each_shown_part_gets_a_slot() {
        let objects = scene();
        let ids = [0u8, 2, 2, 2, 255, 2, 2];
        let parts = [0u8, 2, 0, 2, 255, 1, 9];
        let (map, slots) = slot_map(&ids, &parts, &objects);
        assert_eq!(map, [255, 0, 1, 0, 255, 2, 255]);
        assert_eq!(slots, [(1, Some(1)), (1, None), (1, Some(0))]);
        let (map, slots) = slot_map(&[0, 255], &[0, 255], &objects);
        assert!(slots.is_empty() && map == [255, 255]);
    }

    /// Members that ride with the boom follow all of its motion, the bucket's (left behind)
    /// none, and the still body has no motion to follow.
    #[test]
    fn each_part_is_scored_against_its_own_motion() {
        let objects = scene();
        // Members 0, 1 on the body, 2, 3 on the boom, 4 on the bucket.
        let anchor = [
            -0.2, 0.0, 0.0, 0.1, 0.0, 0.0, 0.52, 0.05, 0.05, 0.58, 0.02, 0.08, 0.85, 0.05, 0.05,
        ];
        let mut moved = anchor;
        moved[6] += 0.2;
        moved[9] += 0.2;
        let slots = [(1, None), (1, Some(0)), (1, Some(1))];
        let members: [&[u32]; 3] = [&[0, 1], &[2, 3], &[4]];
        let groups = (0u8..).zip(members);
        // Members 2 (boom) and 4 (bucket) are the crane's node's (ID 2); 3 is the field's.
        let column = [2u8, 255, 2, 255, 2];
        let mut acc = PartAccumulator::from_groups(groups, &slots, (&objects, &column)).unwrap();
        let (f0, f1) = (&objects.frames[0], &objects.frames[1]);
        acc.add_time(1.0, (f0, f1), &anchor, &moved).unwrap();
        let round = |f: Option<f64>| f.map(|f| (f * 1e6).round() / 1e6);
        type Row = (String, usize, Option<f64>, usize, Option<f64>);
        let got: Vec<Row> = acc
            .finish(&objects)
            .into_iter()
            .map(|p| {
                (
                    p.name,
                    p.members,
                    round(p.follow),
                    p.in_node,
                    round(p.follow_in_node),
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                ("body".into(), 2, None, 1, None),
                ("boom".into(), 2, Some(1.0), 1, Some(1.0)),
                ("bucket".into(), 1, Some(0.0), 1, Some(0.0)),
            ]
        );
    }
}
