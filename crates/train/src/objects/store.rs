//! The rigid objects in a checkpoint's `state.safetensors`: metadata `objects` (JSON: whether
//! they started, per object its ID, name, static flag and knot count, and the start's
//! report on every object it saw, decisions and evidence; for articulated objects each
//! part's mask ID and the joints between parts) and per object
//! slot `s` the tensors `objects.s.times [K]`, `.translations [K, 3]`, `.rotations [K, 4]`
//! and the knots' Adam moments and steps. The per-Gaussian object column is the checkpoint's
//! `object` tensor (written by `checkpoint`).

use super::knots::KnotAdam;
use super::parts::Joint;
use super::start::StartReport;
use super::trajectory::Trajectory;
use super::{RigidObject, RigidObjects};
use crate::adam::Adam;
use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize)]
struct Meta {
    started: bool,
    objects: Vec<ObjectMeta>,
    /// What the start found per object, its decisions and their evidence (absent in
    /// checkpoints written before it was kept).
    #[serde(default)]
    start: Vec<StartReport>,
    /// Joints between the parts of articulated objects (absent: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    joints: Vec<Joint>,
}

#[derive(Serialize, Deserialize)]
struct ObjectMeta {
    id: u8,
    name: String,
    #[serde(rename = "static")]
    is_static: bool,
    knots: usize,
    /// The ID of the maps it is seen in, when it is a part of another object (absent: its
    /// own ID).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mask: Option<u8>,
}

/// The `objects` metadata value.
pub fn metadata(node: &RigidObjects) -> String {
    let m = Meta {
        started: node.started,
        objects: node
            .objects
            .iter()
            .map(|o| ObjectMeta {
                id: o.id,
                name: o.name.clone(),
                is_static: o.is_static,
                knots: o.trajectory.len(),
                mask: o.is_part().then_some(o.mask),
            })
            .collect(),
        start: node.start_reports.clone(),
        joints: node.joints.clone(),
    };
    serde_json::to_string(&m).expect("plain data serializes")
}

/// Hands every tensor of the objects to `put(name, shape, values)`.
pub fn write_tensors(node: &RigidObjects, put: &mut impl FnMut(String, Vec<usize>, &[f32])) {
    for (s, (o, a)) in node.objects.iter().zip(&node.knot_adam).enumerate() {
        let tr = &o.trajectory;
        let k = tr.len();
        let key = |name: &str| format!("objects.{s}.{name}");
        put(key("times"), vec![k], &tr.times);
        put(
            key("translations"),
            vec![k, 3],
            tr.translations.as_flattened(),
        );
        put(key("rotations"), vec![k, 4], tr.rotations.as_flattened());
        for (group, adams, w) in [("t", &a.translation, 3), ("r", &a.rotation, 4)] {
            let m: Vec<f32> = adams.iter().flat_map(|x| x.m.clone()).collect();
            let v: Vec<f32> = adams.iter().flat_map(|x| x.v.clone()).collect();
            let steps: Vec<f32> = adams.iter().map(|x| x.step as f32).collect();
            put(key(&format!("adam.{group}.m")), vec![k, w], &m);
            put(key(&format!("adam.{group}.v")), vec![k, w], &v);
            put(key(&format!("adam.{group}.steps")), vec![k], &steps);
        }
    }
}

/// What a checkpoint holds of the objects.
pub struct Stored {
    pub started: bool,
    pub start_reports: Vec<StartReport>,
    pub objects: Vec<RigidObject>,
    pub knot_adam: Vec<KnotAdam>,
    pub joints: Vec<Joint>,
}

/// Reads the objects back; `tensor(name, len)` returns an f32 tensor of `len` finite values
/// or an error naming it. `meta` is the `objects` metadata (None: a run without objects).
pub fn read<E>(
    meta: Option<&str>,
    tensor: impl Fn(&str, usize) -> Result<Vec<f32>, E>,
    bad: impl Fn(String) -> E,
) -> Result<Stored, E> {
    let Some(text) = meta else {
        return Ok(Stored {
            started: false,
            start_reports: Vec::new(),
            objects: Vec::new(),
            knot_adam: Vec::new(),
            joints: Vec::new(),
        });
    };
    let m: Meta = serde_json::from_str(text)
        .map_err(|e| bad(format!("metadata `objects` is not valid: {e}")))?;
    let mut objects = Vec::new();
    let mut knot_adam = Vec::new();
    for (s, om) in m.objects.iter().enumerate() {
        let k = om.knots;
        if k == 0 {
            return Err(bad(format!("object {} has no trajectory knots", om.name)));
        }
        let key = |name: &str| format!("objects.{s}.{name}");
        let times = tensor(&key("times"), k)?;
        if times.windows(2).any(|w| w[1] < w[0]) {
            return Err(bad(format!(
                "object {}: knot times are not ascending",
                om.name
            )));
        }
        let trajectory = Trajectory {
            times,
            translations: rows(&tensor(&key("translations"), k * 3)?),
            rotations: rows(&tensor(&key("rotations"), k * 4)?),
        };
        let mut adam = KnotAdam::zeros(k);
        for (group, adams, w) in [
            ("t", &mut adam.translation, 3),
            ("r", &mut adam.rotation, 4),
        ] {
            let m = tensor(&key(&format!("adam.{group}.m")), k * w)?;
            let v = tensor(&key(&format!("adam.{group}.v")), k * w)?;
            let steps = tensor(&key(&format!("adam.{group}.steps")), k)?;
            for (i, a) in adams.iter_mut().enumerate() {
                *a = Adam {
                    m: m[i * w..(i + 1) * w].to_vec(),
                    v: v[i * w..(i + 1) * w].to_vec(),
                    step: steps[i].max(0.0) as u64,
                };
            }
        }
        let mut body = RigidObject::new(om.id, om.name.clone(), trajectory, om.is_static);
        body.mask = om.mask.unwrap_or(om.id);
        objects.push(body);
        knot_adam.push(adam);
    }
    for j in &m.joints {
        if ![j.a, j.b]
            .iter()
            .all(|id| objects.iter().any(|o| o.id == *id))
        {
            return Err(bad(format!(
                "a joint joins bodies {} and {}, which are not both among its objects",
                j.a, j.b
            )));
        }
    }
    Ok(Stored {
        started: m.started,
        start_reports: m.start,
        objects,
        knot_adam,
        joints: m.joints,
    })
}

fn rows<const W: usize>(v: &[f32]) -> Vec<[f32; W]> {
    v.chunks_exact(W)
        .map(|c| c.try_into().expect("chunks of W"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::ObjectsConfig;
    use std::collections::HashMap;

    fn articulated() -> RigidObjects {
        let mut node = RigidObjects::new(ObjectsConfig::default(), Vec::new(), Vec::new());
        let tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.0; 3], [1.0, 0.0, 0.0]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        };
        let body = RigidObject::new(3, "crane".into(), tr.clone(), true);
        let mut boom = RigidObject::new(254, "crane/part-1".into(), tr, false);
        boom.mask = 3;
        node.objects = vec![body, boom];
        node.knot_adam = vec![KnotAdam::zeros(2), KnotAdam::zeros(2)];
        node.joints = vec![Joint {
            a: 3,
            b: 254,
            point: [0.1, 0.2, 0.3],
            weight: 4.0,
        }];
        node.started = true;
        node
    }

    fn round_trip(meta: &str, node: &RigidObjects) -> Result<Stored, String> {
        let mut tensors = HashMap::new();
        write_tensors(node, &mut |name, _, v| {
            tensors.insert(name, v.to_vec());
        });
        read(Some(meta), |name, _| Ok(tensors[name].clone()), |e| e)
    }

    /// Parts keep their mask ID and the joints come back; a whole object has no `mask` key.
    #[test]
    fn parts_and_joints_survive_a_checkpoint() {
        let node = articulated();
        let meta = metadata(&node);
        assert_eq!(meta.matches("\"mask\"").count(), 1, "{meta}");
        let back = round_trip(&meta, &node).unwrap();
        assert_eq!(back.objects, node.objects);
        assert_eq!(back.joints, node.joints);
        // A joint to a body the checkpoint does not hold is refused.
        let broken = meta.replace("\"b\":254", "\"b\":9");
        let err = round_trip(&broken, &node).err().expect("refused");
        assert!(err.contains("joins bodies 3 and 9"), "{err}");
    }
}
