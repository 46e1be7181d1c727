//! What `semdynreg export --per-object` writes for each object: its Gaussians in its own
//! frame (the rows the checkpoint stores for it, unplaced), and its pose over time as a
//! [`TrajectoryFile`], so that a user can move, drop or re-time the object elsewhere.

use super::{RigidObject, Selection, NO_OBJECT};
use crate::model::GaussianModel;
use serde::{Deserialize, Serialize};

/// The object's pose at one time, three ways that agree: `x_world = R(q)·x_object + p` with
/// `p = translation` and `q = quaternion_wxyz` (unit, scalar first: w, x, y, z), and
/// `x_world = object_to_world · [x_object, 1]`, a row-major 4×4 matrix (toycars'
/// objects.json convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseAt {
    /// The scene frame this pose is for (absent for times asked with `--times`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub split: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file_path: Option<String>,
    pub time: f32,
    pub translation: [f32; 3],
    /// Unit quaternion, w first.
    pub quaternion_wxyz: [f32; 4],
    pub object_to_world: [[f32; 4]; 4],
}

impl PoseAt {
    /// The pose of `o` at `time` (for a scene frame when `frame` is given).
    pub fn of(o: &RigidObject, time: f32, frame: Option<&FrameRef>) -> Self {
        let pose = o.trajectory.pose(time);
        Self {
            split: frame.map(|f| f.split.clone()),
            file_path: frame.map(|f| f.file_path.clone()),
            time,
            translation: pose.p,
            quaternion_wxyz: pose.q,
            object_to_world: pose.to_matrix(),
        }
    }
}

/// `<name>.trajectory.json`: one object's identity and poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryFile {
    pub id: u8,
    pub name: String,
    /// A static object holds one pose at all times.
    #[serde(rename = "static")]
    pub is_static: bool,
    /// Rows of `<name>.ply`.
    pub gaussians: usize,
    /// The times of the trajectory's knots (poses between them are interpolated,
    /// beyond them extrapolated at constant velocity).
    pub knot_times: Vec<f32>,
    /// One pose per frame of the run's scene, every split, in time order.
    pub frames: Vec<PoseAt>,
    /// One pose per time asked for (empty unless `--times` was given).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub times: Vec<PoseAt>,
    /// For a part of an articulated object trained with skinning: how each of its
    /// Gaussians blends the parts' poses (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skinning: Option<SkinningWeights>,
}

/// A skinned part's weights: Gaussian i of `<name>.ply` is placed at
/// `x_world(t) = Σ_k weights[i][k] · pose_{parts[k]}(t) · x_i`, each part's pose from its
/// own trajectory file (its rotation by the normalized blend of the parts' quaternions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkinningWeights {
    /// The object's parts (their names, as their trajectory files give them), in the order
    /// of each row's weights.
    pub parts: Vec<String>,
    /// One row per Gaussian of the PLY, in its order; each row sums to 1.
    pub weights: Vec<Vec<f32>>,
}

/// A frame of the scene as the trajectory file names it.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRef {
    pub split: String,
    pub file_path: String,
    pub time: f32,
}

/// Every frame of `ds` (train, val, test) in time order; frames at the same time keep
/// that split order.
pub fn scene_frames(ds: &scene::Dataset) -> Vec<FrameRef> {
    let splits = [("train", &ds.train), ("val", &ds.val), ("test", &ds.test)];
    let mut out: Vec<FrameRef> = splits
        .iter()
        .flat_map(|(split, frames)| {
            frames.iter().map(|f| FrameRef {
                split: split.to_string(),
                file_path: f.file_path.clone(),
                time: f.time,
            })
        })
        .collect();
    out.sort_by(|a, b| a.time.total_cmp(&b.time));
    out
}

/// The object's Gaussians in its own frame (its rows of `model`).
pub fn object_model(o: &RigidObject, model: &GaussianModel, column: &[u8]) -> GaussianModel {
    part_model(o.id, &o.name, model, column)
}

/// The background's Gaussians (every row of no object) in the canonical space of the
/// deformation field, i.e. undeformed.
pub fn background_model(model: &GaussianModel, column: &[u8]) -> GaussianModel {
    part_model(NO_OBJECT, super::select::BACKGROUND, model, column)
}

fn part_model(value: u8, name: &str, model: &GaussianModel, column: &[u8]) -> GaussianModel {
    let only = Selection {
        mode: super::SelectMode::Only,
        parts: vec![value],
        names: vec![name.to_string()],
    };
    only.apply(model, column).0
}

/// The trajectory file of `o` at `frames` and at the extra `times`.
pub fn trajectory_file(
    o: &RigidObject,
    gaussians: usize,
    frames: &[FrameRef],
    times: &[f32],
) -> TrajectoryFile {
    TrajectoryFile {
        id: o.id,
        name: o.name.clone(),
        is_static: o.is_static,
        gaussians,
        knot_times: o.trajectory.times.clone(),
        frames: frames
            .iter()
            .map(|f| PoseAt::of(o, f.time, Some(f)))
            .collect(),
        times: times.iter().map(|&t| PoseAt::of(o, t, None)).collect(),
        skinning: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::Trajectory;

    #[test]
    fn poses_follow_the_trajectory_and_object_rows_are_unplaced() {
        let tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.0; 3], [1.0, 2.0, 0.0]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        };
        let o = RigidObject::new(3, "crate".into(), tr, false);
        let frames = [FrameRef {
            split: "test".into(),
            file_path: "test/r_001".into(),
            time: 0.5,
        }];
        let f = trajectory_file(&o, 7, &frames, &[1.0]);
        assert_eq!(f.frames[0].object_to_world[0][3], 0.5);
        assert_eq!(f.frames[0].object_to_world[1][3], 1.0);
        assert_eq!(f.times[0].object_to_world[1][3], 2.0);
        assert_eq!(f.times[0].file_path, None);
        assert_eq!(f.frames[0].translation, [0.5, 1.0, 0.0]);
        assert_eq!(f.frames[0].quaternion_wxyz, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(f.frames[0].split.as_deref(), Some("test"));
        let json = serde_json::to_value(&f).unwrap();
        assert_eq!(json["static"], false);
        assert_eq!(json["knot_times"].as_array().unwrap().len(), 2);
        assert!(
            json.get("skinning").is_none(),
            "a rigid object's file has no weights"
        );

        let m = crate::init::from_points(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[0.5; 6], 0.1);
        let rows = object_model(&o, &m, &[NO_OBJECT, 3]);
        assert_eq!(rows.means, [4.0, 5.0, 6.0]);
        let bg = background_model(&m, &[NO_OBJECT, 3]);
        assert_eq!(bg.means, [1.0, 2.0, 3.0]);
    }
}
