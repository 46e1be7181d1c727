//! Per-part follow of articulated objects (scenes whose `objects.json` lists `parts`, such
//! as the toycars crane): each object's group is split by the part that holds each member
//! at `t_ref`, and every part is scored against its own true motion with the same metric
//! as the whole object (`train::regularizer::consistency`, `follow = 1 − rms/rms_if_still`).
//!
//! A member belongs to the part whose box (in the part's frame at `t_ref`, grown by
//! [`MARGIN`] since Gaussians sit on and just off the surface) holds its anchor, the
//! nearest such box where several do; members in no part's box belong to the body.

use anyhow::Result;
use scene::objects::{ObjectFrame, ObjectsFile};
use train::objects::truth::inv_apply;
use train::regularizer::{ConsistencyAccumulator, ObjectGroups, ObjectTrack};

/// How far outside a part's box (world units) a member still counts as the part's.
pub const MARGIN: f32 = 0.01;

/// One part's members of an object's group.
struct PartMembers {
    object: u8,
    /// The object's index in `objects.json`.
    index: usize,
    /// The part's index in the object's `parts`; `None`: the body.
    part: Option<usize>,
    members: Vec<u32>,
}

/// The follow of one part of an articulated object.
pub struct PartFollow {
    pub object: u8,
    /// `body` or the part's name.
    pub name: String,
    pub members: usize,
    pub follow: Option<f64>,
}

/// Collects one test time after another, as `ConsistencyAccumulator` does, per part.
pub struct PartAccumulator {
    parts: Vec<PartMembers>,
    acc: Vec<ConsistencyAccumulator>,
}

/// How far `p` lies outside the box `b` (0 inside).
fn outside(b: &[[f32; 3]; 2], p: [f32; 3]) -> f32 {
    let d: [f32; 3] = std::array::from_fn(|k| (b[0][k] - p[k]).max(p[k] - b[1][k]).max(0.0));
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// The part holding world point `a` at the reference frame (`None`: the body).
fn part_of(
    object: &scene::objects::ObjectInfo,
    mats: &[[[f32; 4]; 4]],
    a: [f32; 3],
) -> Option<usize> {
    object
        .parts
        .iter()
        .zip(mats)
        .enumerate()
        .map(|(k, (p, m))| (k, outside(&p.bbox_local, inv_apply(m, a))))
        .filter(|&(_, d)| d <= MARGIN)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(k, _)| k)
}

/// The part→world matrix of `part` (the body's object→world for `None`).
fn matrix(frame: &ObjectFrame, index: usize, part: Option<usize>) -> &[[f32; 4]; 4] {
    match part {
        None => &frame.object_to_world[index],
        Some(k) => &frame.part_to_world[index][k],
    }
}

impl PartAccumulator {
    /// Splits every group of an object with parts; `None` when no group has one.
    pub fn new(
        groups: &ObjectGroups,
        objects: &ObjectsFile,
        pose_ref: &ObjectFrame,
        anchor: &[f32],
    ) -> Option<Self> {
        let groups = groups.iter().map(|g| (g.object, g.members));
        Self::from_groups(groups, objects, pose_ref, anchor)
    }

    /// [`Self::new`] from `(object, members)` pairs.
    fn from_groups<'a>(
        groups: impl Iterator<Item = (u8, &'a [u32])>,
        objects: &ObjectsFile,
        pose_ref: &ObjectFrame,
        anchor: &[f32],
    ) -> Option<Self> {
        let mut parts = Vec::new();
        for (object, members) in groups {
            let Some(index) = objects.objects.iter().position(|o| o.id == object) else {
                continue;
            };
            let info = &objects.objects[index];
            if info.parts.is_empty() {
                continue;
            }
            let mats = &pose_ref.part_to_world[index];
            let mut split: Vec<Vec<u32>> = vec![Vec::new(); info.parts.len() + 1];
            for &m in members {
                let a = std::array::from_fn(|c| anchor[3 * m as usize + c]);
                split[part_of(info, mats, a).map_or(0, |k| k + 1)].push(m);
            }
            for (slot, members) in split.into_iter().enumerate() {
                let part = slot.checked_sub(1);
                parts.push(PartMembers {
                    object,
                    index,
                    part,
                    members,
                });
            }
        }
        (!parts.is_empty()).then(|| Self {
            acc: vec![ConsistencyAccumulator::new(); parts.len()],
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
            if p.members.is_empty() {
                continue;
            }
            let track = ObjectTrack {
                object: p.object,
                members: &p.members,
                pose_ref: matrix(pose_ref, p.index, p.part),
                pose_t: matrix(pose_t, p.index, p.part),
            };
            acc.add_time(time, &[track], anchor, deformed)?;
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
                follow: acc
                    .report()
                    .ok()
                    .and_then(|r| r.per_object.first().and_then(|o| o.follow())),
            })
            .collect()
    }
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

    /// Points go to the part whose box holds them (within the margin), the nearer of two,
    /// and to the body otherwise.
    #[test]
    fn members_go_to_the_part_that_holds_them() {
        let part = |name: &str| PartInfo {
            name: name.into(),
            parent: None,
            bbox_local: [[0.0; 3], [0.1; 3]],
        };
        let object = ObjectInfo {
            id: 4,
            name: "crane".into(),
            prompt: String::new(),
            moving: true,
            bbox_local: [[-1.0; 3], [1.0; 3]],
            parts: vec![part("boom"), part("bucket")],
        };
        let mats = [shifted(0.5), shifted(0.6)];
        assert_eq!(part_of(&object, &mats, [0.55, 0.05, 0.05]), Some(0));
        // Where the grown boxes overlap, the box the point is inside wins.
        assert_eq!(part_of(&object, &mats, [0.595, 0.05, 0.05]), Some(0));
        assert_eq!(part_of(&object, &mats, [0.605, 0.05, 0.05]), Some(1));
        // Just past the boom's top but within the margin; past the bucket's far end.
        assert_eq!(part_of(&object, &mats, [0.55, 0.05, 0.105]), Some(0));
        assert_eq!(part_of(&object, &mats, [0.705, 0.05, 0.05]), Some(1));
        assert_eq!(part_of(&object, &mats, [0.3, 0.05, 0.05]), None);
        assert_eq!(part_of(&object, &mats, [0.55, 0.05, 0.2]), None);
    }

    /// A body that stands still, a boom that slides 0.2 along x and a bucket that stays
    /// behind: members that ride with the boom follow all of its motion, the bucket's none,
    /// and the body has no motion to follow.
    #[test]
    fn each_part_is_scored_against_its_own_motion() {
        let part = |name: &str, parent| PartInfo {
            name: name.into(),
            parent,
            bbox_local: [[0.0; 3], [0.1; 3]],
        };
        let objects = ObjectsFile {
            objects: vec![ObjectInfo {
                id: 2,
                name: "crane".into(),
                prompt: String::new(),
                moving: true,
                bbox_local: [[-1.0; 3], [1.0; 3]],
                parts: vec![part("boom", None), part("bucket", Some(0))],
            }],
            frames: [(0.0, 0.0), (1.0, 0.2)]
                .iter()
                .map(|&(time, dx)| ObjectFrame {
                    file_path: format!("test/{time}"),
                    time,
                    object_to_world: vec![shifted(0.0)],
                    part_to_world: vec![vec![shifted(0.5 + dx), shifted(0.8 + dx)]],
                })
                .collect(),
            extra: Default::default(),
        };
        // Members 0, 1 on the body, 2, 3 on the boom, 4 on the bucket.
        let anchor = [
            -0.2, 0.0, 0.0, 0.1, 0.0, 0.0, 0.52, 0.05, 0.05, 0.58, 0.02, 0.08, 0.85, 0.05, 0.05,
        ];
        let mut moved = anchor;
        moved[6] += 0.2;
        moved[9] += 0.2;
        let members = [0u32, 1, 2, 3, 4];
        let (f0, f1) = (&objects.frames[0], &objects.frames[1]);
        let groups = std::iter::once((2u8, &members[..]));
        let mut acc = PartAccumulator::from_groups(groups, &objects, f0, &anchor).unwrap();
        acc.add_time(1.0, (f0, f1), &anchor, &moved).unwrap();
        let got: Vec<(String, usize, Option<f64>)> = acc
            .finish(&objects)
            .into_iter()
            .map(|p| (p.name, p.members, p.follow.map(|f| (f * 1e6).round() / 1e6)))
            .collect();
        assert_eq!(
            got,
            [
                ("body".into(), 2, None),
                ("boom".into(), 2, Some(1.0)),
                ("bucket".into(), 1, Some(0.0)),
            ]
        );
        // A scene without parts has nothing to split.
        let mut rigid = objects.clone();
        rigid.objects[0].parts.clear();
        let groups = std::iter::once((2u8, &members[..]));
        assert!(PartAccumulator::from_groups(groups, &rigid, f0, &anchor).is_none());
    }
}
