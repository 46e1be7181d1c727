//! Scenes beyond the presets (`--route`, `--add`): objects.json records the routes and
//! props, masks carry the new IDs, and every recorded pose is the one rendered (each
//! object's top centre, moved by its pose and projected, lands on its own ID; no ID pixel
//! lies outside its projected box). Bad settings are refused with the option named.

use scene::objects::{apply, ObjectsFile};
use scene::toycars::{generate, AddSpec, Preset, RouteSpec, ToycarsConfig};
use scene::{load_dataset, load_mask, LoadOptions, MaskU8};

fn tiny(routes: &[&str], adds: &[&str]) -> ToycarsConfig {
    ToycarsConfig {
        preset: Preset::Scene1,
        width: 96,
        height: 72,
        frames: 6,
        seed: 1,
        supersample: false,
        routes: routes.iter().map(|s| s.parse().unwrap()).collect(),
        adds: adds.iter().map(|s| s.parse().unwrap()).collect(),
        ..Default::default()
    }
}

/// Generates `cfg` and checks every frame's mask against objects.json; returns the
/// objects file and the masks in frame order.
fn generate_and_check(cfg: &ToycarsConfig) -> (ObjectsFile, Vec<MaskU8>) {
    let dir = tempfile::tempdir().unwrap();
    generate(cfg, dir.path(), &|_, _| {}).unwrap();
    let ds = load_dataset(dir.path(), &LoadOptions::default()).unwrap();
    let objects = ObjectsFile::load(&dir.path().join("objects.json")).unwrap();
    let mut frames: Vec<_> = ds.all_frames().collect();
    frames.sort_by(|a, b| a.time.total_cmp(&b.time));
    let mut masks = Vec::new();
    for frame in frames {
        let mask = load_mask(&ds.gt_mask_path(frame)).unwrap();
        let poses = objects.frame(&frame.file_path).unwrap();
        for (obj, m) in objects.objects.iter().zip(&poses.object_to_world) {
            let [lo, hi] = obj.bbox_local;
            let top = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] - 1e-3];
            let (px, _) = frame.camera.project(apply(m, top)).unwrap();
            let (col, row) = (px[0].floor() as u32, px[1].floor() as u32);
            let at = mask.get(row, col);
            assert_eq!(at, obj.id, "{} {} top centre", frame.file_path, obj.name);
            assert_pixels_inside_box(&mask, obj.id, &frame.camera, m, obj.bbox_local);
        }
        masks.push(mask);
    }
    (objects, masks)
}

fn assert_pixels_inside_box(
    mask: &MaskU8,
    id: u8,
    cam: &splat::Camera,
    m: &[[f32; 4]; 4],
    b: [[f32; 3]; 2],
) {
    let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
    for c in 0..8 {
        let p = [b[c & 1][0], b[(c >> 1) & 1][1], b[(c >> 2) & 1][2]];
        let (px, _) = cam.project(apply(m, p)).unwrap();
        for k in 0..2 {
            lo[k] = lo[k].min(px[k]);
            hi[k] = hi[k].max(px[k]);
        }
    }
    for row in 0..mask.height {
        for col in 0..mask.width {
            if mask.get(row, col) == id {
                let (x, y) = (col as f32 + 0.5, row as f32 + 0.5);
                assert!(
                    x > lo[0] - 1.0 && x < hi[0] + 1.0 && y > lo[1] - 1.0 && y < hi[1] + 1.0,
                    "id {id} pixel ({row},{col}) outside {lo:?}..{hi:?}"
                );
            }
        }
    }
}

fn count(mask: &MaskU8, id: u8) -> usize {
    mask.data.iter().filter(|&&v| v == id).count()
}

/// Mean row of the pixels of `id` (smaller is higher up in the image).
fn mean_row(mask: &MaskU8, id: u8) -> f32 {
    let rows: Vec<f32> = (0..mask.data.len())
        .filter(|&i| mask.data[i] == id)
        .map(|i| (i / mask.width as usize) as f32)
        .collect();
    rows.iter().sum::<f32>() / rows.len() as f32
}

fn translation(m: &[[f32; 4]; 4]) -> [f32; 3] {
    [m[0][3], m[1][3], m[2][3]]
}

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < tol)
}

#[test]
fn two_routes_and_a_crate_are_recorded_and_rendered() {
    let cfg = tiny(
        &["-0.9,-0.5;0.3,-0.5", "green-suv=0.8,0.7;0.8,-0.2"],
        &["crate@-0.6,-0.1,20"],
    );
    let (objects, masks) = generate_and_check(&cfg);
    let names: Vec<(&str, bool, u8)> = objects
        .objects
        .iter()
        .map(|o| (o.name.as_str(), o.moving, o.id))
        .collect();
    assert_eq!(
        names,
        [
            ("white-suv", true, 0),
            ("yellow-sedan", false, 1),
            ("green-suv", true, 2),
            ("crate", false, 3)
        ]
    );
    let crate_box = objects.objects[3].bbox_local;
    assert!(
        close(crate_box[0], [-0.156, -0.116, 0.0], 1e-6),
        "{crate_box:?}"
    );
    assert!(
        close(crate_box[1], [0.156, 0.116, 0.206], 1e-6),
        "{crate_box:?}"
    );
    let (first, last) = (&objects.frames[0], objects.frames.last().unwrap());
    let m = |f: &scene::objects::ObjectFrame, i: usize| f.object_to_world[i];
    assert!(close(translation(&m(first, 0)), [-0.9, -0.5, 0.0], 1e-4));
    assert!(close(translation(&m(last, 0)), [0.3, -0.5, 0.0], 1e-4));
    assert!(close(translation(&m(first, 2)), [0.8, 0.7, 0.0], 1e-4));
    assert!(close(translation(&m(last, 2)), [0.8, -0.2, 0.0], 1e-4));
    // Heading from the tangent: the white SUV faces +x, the green one −y.
    assert!((m(first, 0)[0][0] - 1.0).abs() < 1e-4 && (m(last, 2)[1][0] + 1.0).abs() < 1e-4);
    // The parked crate: 20° and constant.
    let yaw = m(first, 3)[1][0].atan2(m(first, 3)[0][0]).to_degrees();
    assert!((yaw - 20.0).abs() < 1e-3 && m(first, 3) == m(last, 3));
    for mask in &masks {
        assert!((0..4).all(|id| count(mask, id) > 0));
    }
    let gen = &objects.extra["generator"];
    assert_eq!(gen["routes"][0]["object"], "white-suv");
    assert_eq!(gen["routes"][1]["object"], "green-suv");
    assert!((gen["routes"][1]["length"].as_f64().unwrap() - 0.9).abs() < 1e-3);
    assert_eq!(gen["adds"][0]["name"], "crate");
    assert_eq!(gen["adds"][0]["id"], 3);
}

/// The same hover flight at z = 0.3 and on the ground: the pose records z, the mask
/// moves up in the image.
#[test]
fn z_lifts_the_object() {
    let ground = generate_and_check(&tiny(&["-0.6,-0.5;0.4,-0.5"], &[]));
    let lifted = generate_and_check(&tiny(&["-0.6,-0.5,0.3;0.4,-0.5,0.3"], &[]));
    for (k, (a, b)) in ground.1.iter().zip(&lifted.1).enumerate() {
        let (ra, rb) = (mean_row(a, 0), mean_row(b, 0));
        assert!(rb < ra - 3.0, "frame {k}: lifted mask row {rb} vs {ra}");
        let z = lifted.0.frames[k].object_to_world[0][2][3];
        assert!((z - 0.3).abs() < 1e-5, "frame {k}: z {z}");
    }
}

/// Given angles (with pitch and roll) are honoured and rendered as recorded: a tilted,
/// turning, lifted barrel and a crate, both moving, next to the parked vehicles.
#[test]
fn given_angles_with_pitch_and_roll_are_rendered_as_recorded() {
    let cfg = tiny(
        &[
            "crate=-0.5,-0.4,0.1@0,15,-10;0.1,-0.5,0.15@90,-10,15;0.5,-0.2,0.1@180,0,0",
            "barrel=0.6,0.5;0.3,0.3,0.1@45,20,0",
        ],
        &["crate@-0.5,-0.4", "barrel@0.6,0.5"],
    );
    let (objects, masks) = generate_and_check(&cfg);
    let id = |n: &str| objects.objects.iter().find(|o| o.name == n).unwrap().id as usize;
    let (c, b) = (id("crate"), id("barrel"));
    assert_eq!((c, b), (3, 4));
    for f in &objects.frames {
        for i in [c, b] {
            let r = f.object_to_world[i];
            for p in 0..3 {
                for q in 0..3 {
                    let dot: f32 = (0..3).map(|k| r[k][p] * r[k][q]).sum();
                    assert!((dot - f32::from(p == q)).abs() < 1e-5, "not a rotation");
                }
            }
        }
    }
    // Yaw 0 → 180 via 90 at the middle waypoint: the crate ends facing −x.
    let end = objects.frames.last().unwrap().object_to_world[c];
    assert!((end[0][0] + 1.0).abs() < 1e-4, "{end:?}");
    // Pitch 15° at the start: local +x tips down (positive pitch lowers the nose).
    let start = objects.frames[0].object_to_world[c];
    assert!((start[2][0] + 15f32.to_radians().sin()).abs() < 1e-5);
    assert!(masks.iter().all(|m| count(m, 3) > 0 && count(m, 4) > 0));
}

#[test]
fn drive_applies_to_routes() {
    let cfg = ToycarsConfig {
        drive: 0.5,
        ..tiny(&["-0.6,-0.5;0.4,-0.5"], &[])
    };
    let (objects, _) = generate_and_check(&cfg);
    let end = translation(&objects.frames.last().unwrap().object_to_world[0]);
    assert!(close(end, [-0.1, -0.5, 0.0], 1e-3), "{end:?}");
}

fn refused(cfg: &ToycarsConfig) -> String {
    let dir = tempfile::tempdir().unwrap();
    generate(cfg, dir.path(), &|_, _| {})
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_routes_and_adds_are_refused_with_the_option_named() {
    for (routes, adds, want) in [
        (
            &["tractor=0,0;1,0"][..],
            &[][..],
            "no object named `tractor`",
        ),
        (&["crate=0,0;0.5,0"], &[], "no object named `crate`"),
        (
            &["0,-0.5;0.5,-0.5", "white-suv=0,0;0.5,0"],
            &[],
            "white-suv already has --route `0,-0.5;0.5,-0.5`",
        ),
        (&["0,0;0,0;1,0"], &[], "waypoints 1 and 2 coincide"),
        (
            &["-0.5,-0.5;1.2,-0.5"],
            &[],
            "white-suv leaves [−1.3, 1.3]³ at t = 1.000 (frame 5)",
        ),
        (
            &["-0.5,-0.5;0.5,-0.5,1.2"],
            &[],
            "leaves [−1.3, 1.3]³ at t = 1.000",
        ),
        (
            &[],
            &["crate@1.2,0"],
            "--add `crate@1.2,0`: crate leaves [−1.3, 1.3]³ at t = 0.000",
        ),
    ] {
        let e = refused(&tiny(routes, adds));
        assert!(e.contains(want), "{routes:?} {adds:?}: {e}");
        assert!(e.contains("--route") || e.contains("--add"), "{e}");
    }
}

#[test]
fn second_prop_of_a_kind_is_numbered() {
    let cfg = tiny(
        &["crate-2=0.2,-0.3;0.5,-0.3"],
        &["crate@-0.5,-0.3", "crate@0.2,-0.3", "barrel@0.6,0.4"],
    );
    let dir = tempfile::tempdir().unwrap();
    generate(&cfg, dir.path(), &|_, _| {}).unwrap();
    let objects = ObjectsFile::load(&dir.path().join("objects.json")).unwrap();
    let names: Vec<(&str, bool)> = objects.objects[3..]
        .iter()
        .map(|o| (o.name.as_str(), o.moving))
        .collect();
    assert_eq!(
        names,
        [("crate", false), ("crate-2", true), ("barrel", false)]
    );
}

#[test]
fn spec_types_parse_from_text() {
    assert!("white-suv=0,0;1,1".parse::<RouteSpec>().is_ok());
    assert!("crate@0,0".parse::<AddSpec>().is_ok());
}
