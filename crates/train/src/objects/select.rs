//! Objects as units a user acts on: a selection of parts of a trained scene (objects by
//! name or ID, and `background` for the deformable rest) turned into the rows of the model
//! to keep. Render and export apply it the same way: they gather the kept rows into a
//! smaller model with its own object column. Gathering is exact, not an approximation: the
//! field and the trajectories act on each Gaussian alone, so a kept Gaussian is deformed
//! and placed as in the full model, and dropped ones are not drawn at all (rather than
//! drawn with an opacity that is merely tiny).

use super::{RigidObject, NO_OBJECT};
use crate::error::{Result, TrainError};
use crate::model::GaussianModel;

/// The pseudo-name of the deformable rest: every Gaussian of no object.
pub const BACKGROUND: &str = "background";

/// Keep only the named parts, or everything but them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SelectMode {
    Only,
    Without,
}

/// Named parts of a run, resolved against its objects.
#[derive(Clone, Debug, PartialEq)]
pub struct Selection {
    pub mode: SelectMode,
    /// Object-column values named (object IDs; `NO_OBJECT` for the background), in the
    /// run's object order with the background last, each once.
    pub parts: Vec<u8>,
    /// The parts' names as the run spells them, in `parts` order.
    pub names: Vec<String>,
}

impl Selection {
    /// Resolves `names` (object names, object IDs as numbers, or `background`) against
    /// the run's `objects`. A run without objects has nothing to select from, so it is an
    /// error even for `background`; so are unknown names, and a `Without` that names every
    /// part (nothing would be left).
    pub fn resolve(objects: &[RigidObject], mode: SelectMode, names: &[String]) -> Result<Self> {
        if objects.is_empty() {
            return Err(TrainError::NoObjects);
        }
        if names.is_empty() {
            return Err(TrainError::EmptySelection("no object named".into()));
        }
        let mut named = Vec::with_capacity(names.len());
        for n in names {
            let v = part_of(objects, n)?;
            named.push(v);
            // An articulated object's name stands for all its parts.
            let parts = objects.iter().filter(|o| o.is_part() && o.mask == v);
            named.extend(parts.map(|o| o.id));
        }
        let order = objects.iter().map(|o| o.id).chain([NO_OBJECT]);
        let parts: Vec<u8> = order.filter(|v| named.contains(v)).collect();
        if mode == SelectMode::Without && parts.len() == objects.len() + 1 {
            return Err(TrainError::EmptySelection(
                "the selection drops every object and the background: nothing is left".into(),
            ));
        }
        let names = parts.iter().map(|&v| name_of(objects, v)).collect();
        Ok(Self { mode, parts, names })
    }

    /// Whether Gaussians whose object-column value is `value` are kept.
    pub fn keeps(&self, value: u8) -> bool {
        self.parts.contains(&value) == (self.mode == SelectMode::Only)
    }

    /// One flag per Gaussian of `column`: kept or dropped.
    pub fn keep_mask(&self, column: &[u8]) -> Vec<bool> {
        column.iter().map(|&v| self.keeps(v)).collect()
    }

    /// The kept rows of `model` and their object column.
    pub fn apply(&self, model: &GaussianModel, column: &[u8]) -> (GaussianModel, Vec<u8>) {
        let (mut m, mut c) = (model.clone(), column.to_vec());
        let keep = self.keep_mask(column);
        m.retain(&keep);
        crate::model::retain_rows(&mut c, 1, &keep);
        (m, c)
    }

    /// A file-name-safe label, e.g. `only-white-suv` or `without-background+green-suv`,
    /// for output folders that must not overwrite the full renders.
    pub fn label(&self) -> String {
        let mode = match self.mode {
            SelectMode::Only => "only",
            SelectMode::Without => "without",
        };
        let names: Vec<String> = self.names.iter().map(|n| file_safe(n)).collect();
        format!("{mode}-{}", names.join("+"))
    }
}

/// The object-column value `name` stands for: the background, an object's name (exact,
/// else ignoring case), or an object's ID.
fn part_of(objects: &[RigidObject], name: &str) -> Result<u8> {
    let n = name.trim();
    if n.eq_ignore_ascii_case(BACKGROUND) {
        return Ok(NO_OBJECT);
    }
    let by_name = objects
        .iter()
        .find(|o| o.name == n)
        .or_else(|| objects.iter().find(|o| o.name.eq_ignore_ascii_case(n)));
    let by_id = || {
        let id: u8 = n.parse().ok()?;
        objects.iter().find(|o| o.id == id)
    };
    match by_name.or_else(by_id) {
        Some(o) => Ok(o.id),
        None => Err(TrainError::UnknownObject {
            name: name.to_string(),
            known: known(objects),
        }),
    }
}

/// `white-suv (0), yellow-sedan (1)`: the run's objects for error messages.
pub fn known(objects: &[RigidObject]) -> String {
    let items: Vec<String> = objects
        .iter()
        .map(|o| format!("{} ({})", o.name, o.id))
        .collect();
    items.join(", ")
}

fn name_of(objects: &[RigidObject], value: u8) -> String {
    objects
        .iter()
        .find(|o| o.id == value)
        .map_or_else(|| BACKGROUND.to_string(), |o| o.name.clone())
}

/// `name` with every character but ASCII letters, digits, `-`, `_` and `.` replaced by
/// `-` (names come from scene files and may hold spaces or slashes), never empty, `.` or `..`.
pub fn file_safe(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '-'
            }
        })
        .collect();
    if s.chars().all(|c| c == '.') {
        format!("unnamed{s}")
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::Trajectory;

    fn objects() -> Vec<RigidObject> {
        let tr = Trajectory::constant(0.0, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
        vec![
            RigidObject::new(0, "white-suv".into(), tr.clone(), false),
            RigidObject::new(2, "green-suv".into(), tr, true),
        ]
    }

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    const COLUMN: [u8; 5] = [NO_OBJECT, 0, 2, 0, NO_OBJECT];

    #[test]
    fn names_ids_and_background_resolve() {
        let o = objects();
        let s = Selection::resolve(&o, SelectMode::Only, &names(&["white-suv"])).unwrap();
        assert_eq!(s.keep_mask(&COLUMN), [false, true, false, true, false]);
        assert_eq!(s.label(), "only-white-suv");
        // An ID, a name in other case and the background: each part once, background last.
        let s = Selection::resolve(
            &o,
            SelectMode::Without,
            &names(&["background", "2", "Green-SUV"]),
        )
        .unwrap();
        assert_eq!(s.parts, [2, NO_OBJECT]);
        assert_eq!(s.names, ["green-suv", "background"]);
        assert_eq!(s.keep_mask(&COLUMN), [false, true, false, true, false]);
        assert_eq!(s.label(), "without-green-suv+background");
        let s = Selection::resolve(&o, SelectMode::Only, &names(&["background"])).unwrap();
        assert_eq!(s.keep_mask(&COLUMN), [true, false, false, false, true]);
    }

    #[test]
    fn an_articulated_objects_name_keeps_its_parts() {
        let mut o = objects();
        let tr = o[0].trajectory.clone();
        let mut boom = RigidObject::new(254, "crane/part-1".into(), tr, false);
        boom.mask = 2;
        o.push(boom);
        let s = Selection::resolve(&o, SelectMode::Only, &names(&["green-suv"])).unwrap();
        assert_eq!(s.parts, [2, 254]);
        assert_eq!(
            s.keep_mask(&[2, 254, 0, NO_OBJECT]),
            [true, true, false, false]
        );
        // The part alone, by its own name.
        let s = Selection::resolve(&o, SelectMode::Only, &names(&["crane/part-1"])).unwrap();
        assert_eq!(s.parts, [254]);
    }

    #[test]
    fn apply_gathers_the_kept_rows_and_their_column() {
        let mut m = crate::init::from_points(&[0.0; 15], &[0.5; 15], 0.1);
        for (i, v) in m.opacity_logits.iter_mut().enumerate() {
            *v = i as f32;
        }
        let s = Selection::resolve(&objects(), SelectMode::Without, &names(&["0"])).unwrap();
        let (kept, column) = s.apply(&m, &COLUMN);
        assert_eq!(kept.opacity_logits, [0.0, 2.0, 4.0]);
        assert_eq!(column, [NO_OBJECT, 2, NO_OBJECT]);
        assert_eq!(kept.means.len(), 9);
        kept.validate().unwrap();
    }

    #[test]
    fn unknown_names_list_the_objects() {
        let e = Selection::resolve(&objects(), SelectMode::Only, &names(&["red-car"]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`red-car`") && e.contains("white-suv (0), green-suv (2)"),
            "{e}"
        );
        assert!(e.contains("background"), "{e}");
        // An ID that no object has is unknown too.
        let e = Selection::resolve(&objects(), SelectMode::Only, &names(&["1"])).unwrap_err();
        assert!(matches!(e, TrainError::UnknownObject { .. }), "{e}");
    }

    #[test]
    fn a_run_without_objects_and_dropping_everything_are_errors() {
        let e = Selection::resolve(&[], SelectMode::Only, &names(&["background"])).unwrap_err();
        assert!(matches!(e, TrainError::NoObjects));
        assert!(e.to_string().contains("trained with --objects"), "{e}");
        let all = names(&["white-suv", "green-suv", "background"]);
        let e = Selection::resolve(&objects(), SelectMode::Without, &all).unwrap_err();
        assert!(e.to_string().contains("nothing is left"), "{e}");
        assert!(Selection::resolve(&objects(), SelectMode::Only, &all).is_ok());
    }

    #[test]
    fn labels_are_file_safe() {
        assert_eq!(file_safe("a car/7 x"), "a-car-7-x");
        assert_eq!(file_safe(".."), "unnamed..");
        assert_eq!(file_safe(""), "unnamed");
        assert_eq!(file_safe("white-suv"), "white-suv");
    }
}
