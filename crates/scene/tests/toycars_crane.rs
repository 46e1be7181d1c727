//! The articulated crane (`--add crane@…`): objects.json records its parts and each part's
//! pose per frame, the recorded poses chain from the body out through the joints, the
//! rendered boom is where its recorded pose puts it at every frame (in the ID map and the
//! part map; it moves while the body stands still), and a file whose part matrices do not match its parts is refused.

use scene::objects::{apply, ObjectsFile};
use scene::toycars::{generate, Preset, ToycarsConfig};
use scene::{load_dataset, load_mask, part_map_path, LoadOptions};

fn crane_scene() -> ToycarsConfig {
    ToycarsConfig {
        preset: Preset::Scene1,
        width: 240,
        height: 180,
        frames: 9,
        seed: 3,
        supersample: false,
        routes: vec!["-0.9,-0.5;-0.3,-0.5".parse().unwrap()],
        adds: vec!["crane@0.45,0.0,90".parse().unwrap()],
        ..Default::default()
    }
}

fn translation(m: &[[f32; 4]; 4]) -> [f32; 3] {
    [m[0][3], m[1][3], m[2][3]]
}

fn assert_close(a: [f32; 3], b: [f32; 3], what: &str) {
    assert!(
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4),
        "{what}: {a:?} vs {b:?}"
    );
}

#[test]
fn the_crane_records_and_renders_its_parts() {
    let dir = tempfile::tempdir().unwrap();
    generate(&crane_scene(), dir.path(), &|_, _| {}).unwrap();
    let path = dir.path().join("objects.json");
    let objects = ObjectsFile::load(&path).unwrap();
    let crane = &objects.objects[3];
    assert_eq!(
        (crane.name.as_str(), crane.id, crane.moving),
        ("crane", 3, true)
    );
    let parts: Vec<(&str, Option<usize>)> = crane
        .parts
        .iter()
        .map(|p| (p.name.as_str(), p.parent))
        .collect();
    assert_eq!(parts, [("boom", None), ("bucket", Some(0))]);
    assert!(objects.objects[..3].iter().all(|o| o.parts.is_empty()));
    // The swept box holds the base and reaches past it where the boom swings.
    let [lo, hi] = crane.bbox_local;
    assert!(
        lo[0] <= -0.18 && hi[0] > 0.45 && hi[2] > 0.3,
        "{:?}",
        crane.bbox_local
    );

    let ds = load_dataset(dir.path(), &LoadOptions::default()).unwrap();
    let mut frames: Vec<_> = ds.all_frames().collect();
    frames.sort_by(|a, b| a.time.total_cmp(&b.time));
    let (mut tips, mut bucket_seen) = (Vec::new(), false);
    for frame in &frames {
        let rec = objects.frame(&frame.file_path).unwrap();
        assert_eq!(rec.part_to_world.len(), 4);
        assert!(rec.part_to_world[..3].iter().all(Vec::is_empty));
        let (body, boom, bucket) = (
            rec.object_to_world[3],
            rec.part_to_world[3][0],
            rec.part_to_world[3][1],
        );
        assert_eq!(
            body, objects.frames[0].object_to_world[3],
            "the base is parked"
        );
        // Joints: the boom on the turret's top, the bucket at the boom's tip.
        assert_close(
            translation(&boom),
            apply(&body, [0.0, 0.0, 0.19]),
            "boom hinge",
        );
        assert_close(
            translation(&bucket),
            apply(&boom, [0.45, 0.0, 0.035]),
            "bucket hinge",
        );
        // The boom's top face, seen from above, is crane pixels along its whole length,
        // and boom pixels (part 1) in the part map.
        let mask = load_mask(&ds.gt_mask_path(frame)).unwrap();
        let parts = load_mask(&part_map_path(dir.path(), &frame.file_path)).unwrap();
        for x in [0.08, 0.22, 0.36] {
            let (px, _) = frame.camera.project(apply(&boom, [x, 0.0, 0.069])).unwrap();
            let (col, row) = (px[0].floor() as u32, px[1].floor() as u32);
            let what = format!("{} boom top at x = {x}", frame.file_path);
            assert_eq!(mask.get(row, col), 3, "{what} ({col}, {row})");
            assert_eq!(parts.get(row, col), 1, "{what} ({col}, {row})");
        }
        // The part map covers exactly the crane's pixels, and shows its body.
        for (&id, &part) in mask.data.iter().zip(&parts.data) {
            assert_eq!(id == 3, part != 255, "id {id} part {part}");
            assert!(part == 255 || part <= 2);
        }
        assert!(parts.data.contains(&0));
        bucket_seen |= parts.data.contains(&2);
        tips.push(apply(&boom, [0.45, 0.0, 0.07]));
    }
    // The boom swings ±50°: its tip moves by decimetres while the body stands still.
    let reach = tips
        .iter()
        .flat_map(|p| tips.iter().map(move |q| (p[0] - q[0]).hypot(p[1] - q[1])))
        .fold(0.0f32, f32::max);
    assert!(reach > 0.5, "tip moves {reach}");
    assert!(bucket_seen, "the bucket shows in some frame's part map");
}

/// A file whose frames lack a part's matrix, or whose parts do not form a tree, is refused
/// with the object named.
#[test]
fn part_matrices_must_match_the_parts() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = crane_scene();
    (cfg.width, cfg.height, cfg.frames) = (32, 24, 2);
    generate(&cfg, dir.path(), &|_, _| {}).unwrap();
    let path = dir.path().join("objects.json");
    let mut objects = ObjectsFile::load(&path).unwrap();
    objects.frames[1].part_to_world[3].pop();
    objects.save(&path).unwrap();
    let err = ObjectsFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("objects.json") && err.contains("crane has 2 parts but 1 part matrices"),
        "{err}"
    );
    objects.frames[1].part_to_world.clear();
    objects.save(&path).unwrap();
    let err = ObjectsFile::load(&path).unwrap_err().to_string();
    assert!(err.contains("frame 1: `part_to_world` is missing"), "{err}");
    // A part hanging from itself (or from a later part) does not make a tree.
    generate(&cfg, dir.path(), &|_, _| {}).unwrap();
    let mut objects = ObjectsFile::load(&path).unwrap();
    let crane = objects
        .objects
        .iter_mut()
        .find(|o| !o.parts.is_empty())
        .unwrap();
    crane.parts[0].parent = Some(0);
    objects.save(&path).unwrap();
    let err = ObjectsFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("part 0") && err.contains("does not come before it"),
        "{err}"
    );
}
