//! A wooden toy crane, the articulated prop (`--add crane@…`): a base with a turret, a
//! boom hinged on the turret that swings side to side and dips, and a bucket hinged at the
//! boom's tip that rocks. Three rigid parts with known motion, one object in the ID maps:
//! the case a per-object rigid pose cannot explain and per-part motion can.

use super::joints::{Link, Swing};
use super::model::{Material, Model, Part, Shape};

fn wood(lo: [f32; 3], hi: [f32; 3], base: [f32; 3]) -> Part {
    Part {
        shape: Shape::Box { lo, hi },
        material: Material::Wood { base, marks: true },
    }
}

/// Height of the turret's top, where the boom is hinged.
const TURRET_TOP: f32 = 0.19;
/// The boom's length from its hinge to the bucket's hinge.
const BOOM: f32 = 0.45;

/// The crane: body = base + turret (yellow); links `boom` (red) and `bucket` (blue).
pub fn toy_crane(name: String) -> Model {
    let yellow = [0.86, 0.64, 0.16];
    let base = vec![
        wood([-0.18, -0.14, 0.0], [0.18, 0.14, 0.11], yellow),
        wood([-0.08, -0.08, 0.11], [0.08, 0.08, TURRET_TOP], yellow),
    ];
    let boom = Link {
        name: "boom".into(),
        model: Model::new(
            "boom",
            "crane boom",
            vec![wood(
                [-0.07, -0.04, 0.0],
                [BOOM, 0.04, 0.07],
                [0.78, 0.22, 0.16],
            )],
        ),
        parent: None,
        joint: [0.0, 0.0, TURRET_TOP],
        // ±50° side to side once over the sequence; raised 20° and dipping ±12° twice.
        yaw: Swing {
            rest: 0.0,
            amp: 50f32.to_radians(),
            cycles: 1.0,
        },
        pitch: Swing {
            rest: -20f32.to_radians(),
            amp: 12f32.to_radians(),
            cycles: 2.0,
        },
    };
    let bucket = Link {
        name: "bucket".into(),
        model: Model::new(
            "bucket",
            "crane bucket",
            vec![wood(
                [-0.04, -0.06, -0.12],
                [0.07, 0.06, 0.0],
                [0.24, 0.36, 0.72],
            )],
        ),
        parent: Some(0),
        joint: [BOOM, 0.0, 0.035],
        yaw: Swing::STILL,
        // Rocks ±35° about a 20° tilt, one and a half times.
        pitch: Swing {
            rest: 20f32.to_radians(),
            amp: 35f32.to_radians(),
            cycles: 1.5,
        },
    };
    let mut model = Model::new(name, "wooden toy crane", base);
    model.links = vec![boom, bucket];
    model
}
