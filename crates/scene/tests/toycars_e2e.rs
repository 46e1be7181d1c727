//! End to end: generate a tiny toycars scene, load it back with the D-NeRF loader, and
//! check that each vehicle's roof centre, moved by its pose in objects.json and projected
//! with the loaded camera, lands on that vehicle's ID in the mask. An axis-convention
//! mistake anywhere (generator, transform_matrix, loader, objects.json) breaks this.

use scene::objects::{apply, ObjectsFile};
use scene::toycars::{generate, Preset, ToycarsConfig};
use scene::{load_dataset, load_mask, LoadOptions};
use std::path::Path;

fn tiny(preset: Preset, seed: u64) -> ToycarsConfig {
    ToycarsConfig {
        preset,
        width: 64,
        height: 48,
        frames: 10,
        seed,
        ..Default::default()
    }
}

#[test]
fn roof_centres_project_onto_their_ids() {
    for preset in [Preset::Scene1, Preset::Scene2] {
        let dir = tempfile::tempdir().unwrap();
        generate(&tiny(preset, 3), dir.path(), &|_, _| {}).unwrap();
        let ds = load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!((ds.train.len(), ds.val.len(), ds.test.len()), (6, 2, 2));
        let objects = ObjectsFile::load(&dir.path().join("objects.json")).unwrap();
        assert_eq!(objects.frames.len(), 10);
        let moving: Vec<&str> = objects
            .objects
            .iter()
            .filter(|o| o.moving)
            .map(|o| o.name.as_str())
            .collect();
        assert_eq!(
            moving,
            [if preset == Preset::Scene1 {
                "white-suv"
            } else {
                "yellow-sedan"
            }]
        );
        let mut checked = 0;
        for frame in ds.all_frames() {
            let mask = load_mask(&ds.gt_mask_path(frame)).unwrap();
            let poses = objects
                .frame(&frame.file_path)
                .expect("frame listed in objects.json");
            assert!((poses.time - frame.time).abs() < 1e-6);
            for (obj, m) in objects.objects.iter().zip(&poses.object_to_world) {
                let [lo, hi] = obj.bbox_local;
                let top = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] - 1e-3];
                let (px, _) = frame
                    .camera
                    .project(apply(m, top))
                    .expect("in front of the camera");
                let (col, row) = (px[0].floor() as u32, px[1].floor() as u32);
                assert_eq!(
                    mask.get(row, col),
                    obj.id,
                    "{preset:?} {} {}",
                    frame.file_path,
                    obj.name
                );
                assert_pixels_inside_box(&mask, obj.id, &frame.camera, m, obj.bbox_local);
                checked += 1;
            }
        }
        assert_eq!(checked, 30);
        // The moving vehicle really travels: its centre moves > 1 unit over the sequence.
        let id = objects.objects.iter().position(|o| o.moving).unwrap();
        let (a, b) = (
            &objects.frames[0].object_to_world[id],
            &objects.frames[9].object_to_world[id],
        );
        assert!((a[0][3] - b[0][3]).hypot(a[1][3] - b[1][3]) > 1.0);
        // Its local +x (first column) points where it drives: yaw convention check.
        for w in objects.frames.windows(2) {
            let (m0, m1) = (&w[0].object_to_world[id], &w[1].object_to_world[id]);
            let step = [m1[0][3] - m0[0][3], m1[1][3] - m0[1][3]];
            let cos = (step[0] * m0[0][0] + step[1] * m0[1][0]) / step[0].hypot(step[1]);
            assert!(cos > 0.8, "heading disagrees with motion: cos {cos}");
        }
    }
}

/// Every mask pixel of `id` lies inside the image rectangle spanned by the projection of
/// the object's posed bounding box (1 px margin): catches a renderer posing the object
/// differently (e.g. yaw sign) from what objects.json says.
fn assert_pixels_inside_box(
    mask: &scene::MaskU8,
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

fn read_tree(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(root).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn generation_is_deterministic_for_a_seed() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    generate(&tiny(Preset::Scene2, 7), a.path(), &|_, _| {}).unwrap();
    generate(&tiny(Preset::Scene2, 7), b.path(), &|_, _| {}).unwrap();
    generate(&tiny(Preset::Scene2, 8), c.path(), &|_, _| {}).unwrap();
    let (ta, tb, tc) = (
        read_tree(a.path()),
        read_tree(b.path()),
        read_tree(c.path()),
    );
    assert_eq!(ta.len(), 10 * 2 + 4);
    assert!(ta == tb, "same seed, different bytes");
    assert!(ta != tc, "the seed changes nothing");
}

#[test]
fn bad_config_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = ToycarsConfig {
        frames: 1,
        ..tiny(Preset::Scene1, 0)
    };
    let e = generate(&cfg, dir.path(), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("frame count 1"), "{e}");
}

#[test]
fn drive_fraction_outside_0_1_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for bad in [0.0, -0.5, 1.5, f32::NAN] {
        let cfg = ToycarsConfig {
            drive: bad,
            ..tiny(Preset::Scene1, 0)
        };
        let e = generate(&cfg, dir.path(), &|_, _| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains("drive fraction"), "{bad}: {e}");
    }
}
