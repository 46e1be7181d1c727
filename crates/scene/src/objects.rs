//! `objects.json`: the ground truth of the toycars scenes — each object's
//! name, text prompt, whether it moves, its local bounding box, and per frame the 4×4
//! row-major matrix taking its local coordinates to world coordinates. Articulated objects
//! add their parts (links): each part's name, parent and box, and per frame each part's
//! part→world matrix (`part_to_world`), written only by scenes that have parts.

use crate::SceneError;
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectsFile {
    pub objects: Vec<ObjectInfo>,
    /// Every frame of every split.
    pub frames: Vec<ObjectFrame>,
    /// Other top-level keys (e.g. the generator's settings), kept as they are.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectInfo {
    /// The value of the object's pixels in the instance masks.
    pub id: u8,
    pub name: String,
    /// Text prompt for the semantic dictionary.
    pub prompt: String,
    pub moving: bool,
    /// `[[xmin, ymin, zmin], [xmax, ymax, zmax]]` in object-local coordinates; for an
    /// articulated object the box its parts sweep over the whole sequence.
    pub bbox_local: [[f32; 3]; 2],
    /// The parts that turn about joints (empty: the object is rigid).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<PartInfo>,
}

/// A part of an articulated object: a rigid link hinged to the body or to another part.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartInfo {
    pub name: String,
    /// Index of the part it hangs from in the object's `parts`; `None`: the body.
    pub parent: Option<usize>,
    /// The part's box in its own frame (origin at its joint).
    pub bbox_local: [[f32; 3]; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectFrame {
    /// Same key as [`crate::Frame::file_path`] (e.g. `train/r_000`).
    pub file_path: String,
    pub time: f32,
    /// One row-major 4×4 local-to-world matrix per object, in `objects` order.
    pub object_to_world: Vec<[[f32; 4]; 4]>,
    /// Per object, one part→world matrix per part (`objects[i].parts` order); empty when no
    /// object has parts.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub part_to_world: Vec<Vec<[[f32; 4]; 4]>>,
}

impl ObjectsFile {
    /// Reads and checks `objects.json` (one finite matrix per object in every frame).
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let f: Self = crate::io::read_json(path)?;
        if let Some(msg) = f.parent_problem() {
            return Err(SceneError::invalid(path, msg));
        }
        for (i, fr) in f.frames.iter().enumerate() {
            if fr.object_to_world.len() != f.objects.len() {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "frame {i} has {} matrices for {} objects",
                        fr.object_to_world.len(),
                        f.objects.len()
                    ),
                ));
            }
            if let Some(msg) = f.parts_problem(fr) {
                return Err(SceneError::invalid(path, format!("frame {i}: {msg}")));
            }
            if fr
                .object_to_world
                .iter()
                .chain(fr.part_to_world.iter().flatten())
                .flatten()
                .flatten()
                .any(|v| !v.is_finite())
                || !fr.time.is_finite()
            {
                return Err(SceneError::invalid(
                    path,
                    format!("frame {i} has a non-finite value"),
                ));
            }
        }
        Ok(f)
    }

    /// A part must hang from the body or from a part listed before it (so the links form a
    /// tree that a walk in list order can pose).
    fn parent_problem(&self) -> Option<String> {
        self.objects.iter().find_map(|o| {
            o.parts.iter().enumerate().find_map(|(j, p)| {
                let bad = p.parent.is_some_and(|q| q >= j);
                bad.then(|| {
                    format!(
                        "part {j} ({}) of {} hangs from part {}, which does not come before it",
                        p.name,
                        o.name,
                        p.parent.unwrap_or_default()
                    )
                })
            })
        })
    }

    /// What is wrong with a frame's part matrices against the objects' parts, if anything.
    fn parts_problem(&self, fr: &ObjectFrame) -> Option<String> {
        let any_parts = self.objects.iter().any(|o| !o.parts.is_empty());
        if fr.part_to_world.is_empty() {
            return any_parts.then(|| "`part_to_world` is missing".to_string());
        }
        if fr.part_to_world.len() != self.objects.len() {
            return Some(format!(
                "`part_to_world` has {} entries for {} objects",
                fr.part_to_world.len(),
                self.objects.len()
            ));
        }
        self.objects
            .iter()
            .zip(&fr.part_to_world)
            .find(|(o, m)| o.parts.len() != m.len())
            .map(|(o, m)| {
                format!(
                    "{} has {} parts but {} part matrices",
                    o.name,
                    o.parts.len(),
                    m.len()
                )
            })
    }

    /// Writes pretty JSON atomically.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        crate::io::write_json(path, self)
    }

    /// The frame with this `file_path`, if any.
    pub fn frame(&self, file_path: &str) -> Option<&ObjectFrame> {
        self.frames.iter().find(|f| f.file_path == file_path)
    }
}

/// `m · [p, 1]` for a row-major 4×4 (affine part).
pub fn apply(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
    let mut out = [0.0f32; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3];
    }
    out
}
