//! Seeded mutation fuzzing of every file the `scene` crate reads (docs/robustness.md):
//! D-NeRF `transforms_*.json` and its PNG frames, Nerfies `dataset.json`, `metadata.json`,
//! `scene.json`, `camera/*.json` and `points.npy`, COLMAP sparse models (`cameras`,
//! `images`, `points3D`, binary and text), LLFF `poses_bounds.npy` and `precomputed.json`,
//! nerfstudio `transforms.json`, PNG images and object-ID masks on their own,
//! `points3d.ply`, `objects.json`.
//!
//! Property per case (tests/fuzz_common): no panic, no hang, no allocation above the limit,
//! an error that names the file; a loaded data set must also be sane (finite cameras with
//! positive focal lengths, non-empty images of the stated size, finite points).
//!
//! CI runs a few hundred cases per format (`cargo test -p scene --test fuzz_inputs`). The
//! long run is the ignored `fuzz_long_run`, every format with 20× its CI count, or
//! `FUZZ_CASES` each when set; `FUZZ_SEED` picks another stream of cases:
//!
//! ```text
//! cargo test -p scene --test fuzz_inputs -- --ignored --nocapture
//! FUZZ_CASES=100000 FUZZ_SEED=7 cargo test -p scene --test fuzz_inputs -- --ignored
//! ```

#[macro_use]
#[path = "fuzz_common/mod.rs"]
mod fuzz_common;

#[path = "formats_common/mod.rs"]
mod formats_common;

use fuzz_common::{apply, check_load, crc32, finish, mutations, runner, Kind, Mutation, Tally};
use proptest::prelude::*;
use scene::{Dataset, LoadOptions};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A tiny toycars scene (D-NeRF layout, masks, objects.json) plus a `points3d.ply`.
fn dnerf_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let cfg = scene::toycars::ToycarsConfig {
            width: 32,
            height: 24,
            frames: 8,
            supersample: false,
            shadows: false,
            ..Default::default()
        };
        scene::toycars::generate(&cfg, dir.path(), &|_, _| {}).unwrap();
        std::fs::write(dir.path().join("points3d.ply"), binary_ply()).unwrap();
        dir
    })
    .path()
}

fn binary_ply() -> Vec<u8> {
    let mut b = b"ply\nformat binary_little_endian 1.0\ncomment seed\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty double nx\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for i in 0..4 {
        for v in [i as f32, 0.5 * i as f32, -1.0] {
            b.extend(v.to_le_bytes());
        }
        b.extend(0.25f64.to_le_bytes());
        b.extend([10 * i as u8, 200, 255]);
    }
    b
}

fn ascii_ply() -> Vec<u8> {
    b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty short red\nproperty short green\nproperty short blue\nend_header\n0 0 0 1 2 3\n1.5 -2 3e2 32767 0 100\n-1 -1 -1 5 5 5\n".to_vec()
}

/// A scene of 6 frames written by `write` (formats_common), kept for the whole run.
fn layout_seed(
    cell: &'static OnceLock<tempfile::TempDir>,
    write: fn(&Path, &[splat::Camera]),
) -> &'static Path {
    cell.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), &formats_common::arc_cameras(6, 16, 12, 14.0));
        dir
    })
    .path()
}

fn colmap_bin_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    layout_seed(&DIR, |p, c| {
        formats_common::write_colmap(p, c, scene::colmap::ModelFormat::Binary)
    })
}

fn colmap_txt_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    layout_seed(&DIR, |p, c| {
        formats_common::write_colmap(p, c, scene::colmap::ModelFormat::Text)
    })
}

fn llff_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    layout_seed(&DIR, formats_common::write_llff_npy)
}

fn precomputed_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    layout_seed(&DIR, formats_common::write_precomputed)
}

fn nerfstudio_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    layout_seed(&DIR, |p, c| {
        let t: Vec<f64> = (0..c.len()).map(|k| 0.1 * k as f64).collect();
        formats_common::write_nerfstudio(p, c, Some(&t))
    })
}

/// A tiny Nerfies scene: 4 ids (3 train, 1 val), cameras, 1x PNGs, scene.json, points.npy.
fn nerfies_seed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let r = dir.path();
        let ids = ["a", "b", "c", "d"];
        let json = |name: &str, v: serde_json::Value| {
            let p = r.join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
        };
        json(
            "dataset.json",
            serde_json::json!({"count": 4, "num_exemplars": 3, "ids": ids,
                "train_ids": ["a", "b", "c"], "val_ids": ["d"]}),
        );
        let meta: serde_json::Map<_, _> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| {
                (
                    id.to_string(),
                    serde_json::json!({"time_id": i, "warp_id": i, "appearance_id": i, "camera_id": 0}),
                )
            })
            .collect();
        json("metadata.json", serde_json::Value::Object(meta));
        json(
            "scene.json",
            serde_json::json!({"scale": 0.5, "center": [0.1, -0.2, 0.3], "near": 0.1, "far": 5.0}),
        );
        for (i, id) in ids.iter().enumerate() {
            json(
                &format!("camera/{id}.json"),
                serde_json::json!({
                    "orientation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                    "position": [0.1 * i as f64, 0.0, -3.0],
                    "focal_length": 40.0,
                    "principal_point": [16.0, 12.0],
                    "skew": 0.0,
                    "pixel_aspect_ratio": 1.0,
                    "radial_distortion": [0.0, 0.0, 0.0],
                    "tangential_distortion": [0.0, 0.0],
                    "image_size": [32, 24]
                }),
            );
            let img = image::RgbImage::from_fn(32, 24, |x, y| {
                image::Rgb([(x * 8) as u8, (y * 10) as u8, 40 * i as u8])
            });
            let p = r.join(format!("rgb/1x/{id}.png"));
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            img.save(p).unwrap();
        }
        let mut npy = Vec::new();
        {
            use npyz::WriterBuilder;
            let mut w = npyz::WriteOptions::<f32>::new()
                .default_dtype()
                .shape(&[5, 3])
                .writer(&mut npy)
                .begin_nd()
                .unwrap();
            w.extend((0..15).map(|k| k as f32 * 0.1)).unwrap();
            w.finish().unwrap();
        }
        std::fs::write(r.join("points.npy"), npy).unwrap();
        dir
    })
    .path()
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// A loaded data set must be usable: finite cameras with positive focal lengths,
/// non-empty images of the camera's size, finite points, colours in [0, 1].
fn sane(ds: &Dataset) -> Result<(), String> {
    for f in ds.all_frames() {
        let c = &f.camera;
        let finite = [c.fx, c.fy, c.cx, c.cy].iter().all(|v| v.is_finite())
            && c.viewmat.iter().flatten().all(|v| v.is_finite());
        if !finite || c.fx <= 0.0 || c.fy <= 0.0 {
            return Err(format!("frame {}: camera {c:?}", f.file_path));
        }
        let (w, h) = (f.image.width, f.image.height);
        if w == 0 || h == 0 || (w, h) != (c.width, c.height) {
            return Err(format!(
                "frame {}: image {w}×{h}, camera {}×{}",
                f.file_path, c.width, c.height
            ));
        }
        if f.image.data.len() != w as usize * h as usize * 3 || !f.time.is_finite() {
            return Err(format!("frame {}: bad buffer or time", f.file_path));
        }
    }
    if ds.train.is_empty() {
        return Err("no training frame".into());
    }
    if let Some(p) = &ds.point_cloud {
        if p.iter().flatten().any(|v| !v.is_finite()) {
            return Err("non-finite point".into());
        }
    }
    if let Some(c) = &ds.point_colors {
        if c.iter().flatten().any(|v| !(0.0..=1.0).contains(v)) {
            return Err("colour outside [0, 1]".into());
        }
    }
    Ok(())
}

/// Mutates `rel` inside a private copy of the scene `seed` and loads the whole scene.
fn fuzz_scene_file(format: &str, seed: &Path, rel: &str, kind: Kind, cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let root = work.path().join("scene");
    copy_dir(seed, &root);
    let target = root.join(rel);
    let original = std::fs::read(&target).unwrap();
    let name = Path::new(rel)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let t = tally.clone();
    let result = r.run(&(mutations(kind), 1u32..=2), |(muts, downscale)| {
        std::fs::write(&target, apply(&original, &muts, kind)).unwrap();
        let root = root.clone();
        let got = check_load(&t, &[&name], move || {
            scene::load_dataset(
                &root,
                &LoadOptions {
                    background: [1.0; 3],
                    downscale,
                },
            )
        });
        std::fs::write(&target, &original).unwrap();
        if let Some(ds) = got? {
            sane(&ds).map_err(|m| TestCaseError::fail(format!("loaded an unusable scene: {m}")))?;
        }
        Ok(())
    });
    finish(format, result, &tally);
}

/// Mutates a single file and runs `load` on it.
fn fuzz_file<T: Send + 'static>(
    format: &str,
    file_name: &str,
    seeds: Vec<Vec<u8>>,
    kind: Kind,
    cases: u32,
    load: fn(&Path) -> Result<T, scene::SceneError>,
    accept: fn(&T) -> Result<(), String>,
) {
    let work = tempfile::tempdir().unwrap();
    let path = work.path().join(file_name);
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let n = seeds.len();
    let t = tally.clone();
    let result = r.run(&(0..n, mutations(kind)), |(s, muts)| {
        std::fs::write(&path, apply(&seeds[s], &muts, kind)).unwrap();
        let p = path.clone();
        if let Some(v) = check_load(&t, &[file_name], move || load(&p))? {
            accept(&v).map_err(|m| TestCaseError::fail(format!("loaded bad content: {m}")))?;
        }
        Ok(())
    });
    finish(format, result, &tally);
}

fn ply_points(cases: u32) {
    fuzz_file(
        "points3d.ply",
        "points3d.ply",
        vec![binary_ply(), ascii_ply()],
        Kind::Text,
        cases,
        scene::read_ply_points_rgb,
        |(p, c)| {
            let bad = p.iter().flatten().any(|v| !v.is_finite())
                || c.as_ref().is_some_and(|c| {
                    c.len() != p.len() || c.iter().flatten().any(|v| !(0.0..=1.0).contains(v))
                });
            if bad {
                Err("non-finite point or colour outside [0, 1]".into())
            } else {
                Ok(())
            }
        },
    );
}

fn objects_json(cases: u32) {
    let seed = std::fs::read(dnerf_seed().join("objects.json")).unwrap();
    fuzz_file(
        "objects.json",
        "objects.json",
        vec![seed],
        Kind::Json,
        cases,
        scene::objects::ObjectsFile::load,
        |f| {
            let finite = f
                .objects
                .iter()
                .all(|o| o.bbox_local.iter().flatten().all(|v| v.is_finite()));
            if finite {
                Ok(())
            } else {
                Err("non-finite bbox_local".into())
            }
        },
    );
}

// ---- PNG images and masks: structured variants (colour types, bit depths, sizes, header
// lies with valid CRCs) and byte mutations with or without the chunk CRCs repaired.

/// Recomputes every chunk's CRC, so that a mutation reaches the decoder's checks of the
/// content instead of stopping at a checksum.
fn fix_crcs(png: &mut [u8]) {
    let mut p = 8;
    while p + 12 <= png.len() {
        let len = u32::from_be_bytes(png[p..p + 4].try_into().unwrap()) as usize;
        let Some(end) = (p + 8).checked_add(len).filter(|&e| e + 4 <= png.len()) else {
            return;
        };
        let crc = crc32(&png[p + 4..end]);
        png[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        p = end + 4;
    }
}

#[derive(Clone, Debug)]
struct PngCase {
    color: u8,
    width: u32,
    height: u32,
    /// IHDR width/height replaced (CRC repaired): the header lies about the size.
    lie: Option<(u32, u32)>,
    muts: Vec<Mutation>,
    fix_crc: bool,
}

fn png_case() -> impl Strategy<Value = PngCase> {
    (
        0u8..8,
        1u32..48,
        1u32..48,
        prop::option::weighted(
            0.2,
            (
                prop_oneof![
                    Just(0u32),
                    Just(1),
                    Just(1 << 16),
                    Just(1 << 24),
                    Just(u32::MAX),
                    1u32..100_000
                ],
                prop_oneof![
                    Just(0u32),
                    Just(1),
                    Just(1 << 16),
                    Just(1 << 24),
                    Just(u32::MAX),
                    1u32..100_000
                ],
            ),
        ),
        prop::option::weighted(0.7, mutations(Kind::Binary)),
        any::<bool>(),
    )
        .prop_map(|(color, width, height, lie, muts, fix_crc)| PngCase {
            color,
            width,
            height,
            lie,
            muts: muts.unwrap_or_default(),
            fix_crc,
        })
}

fn encode_png(c: &PngCase) -> Vec<u8> {
    use image::{DynamicImage, ImageBuffer};
    let (w, h) = (c.width, c.height);
    let v8 = |x: u32, y: u32, k: u32| ((x * 31 + y * 17 + k * 101) % 256) as u8;
    let v16 = |x: u32, y: u32, k: u32| ((x * 3001 + y * 1703 + k * 10007) % 65536) as u16;
    let img = match c.color {
        0 => DynamicImage::ImageLuma8(ImageBuffer::from_fn(w, h, |x, y| {
            image::Luma([v8(x, y, 0)])
        })),
        1 => DynamicImage::ImageLumaA8(ImageBuffer::from_fn(w, h, |x, y| {
            image::LumaA([v8(x, y, 0), v8(x, y, 1)])
        })),
        2 => DynamicImage::ImageRgb8(ImageBuffer::from_fn(w, h, |x, y| {
            image::Rgb([v8(x, y, 0), v8(x, y, 1), v8(x, y, 2)])
        })),
        3 => DynamicImage::ImageRgba8(ImageBuffer::from_fn(w, h, |x, y| {
            image::Rgba([v8(x, y, 0), v8(x, y, 1), v8(x, y, 2), v8(x, y, 3)])
        })),
        4 => DynamicImage::ImageLuma16(ImageBuffer::from_fn(w, h, |x, y| {
            image::Luma([v16(x, y, 0)])
        })),
        5 => DynamicImage::ImageLumaA16(ImageBuffer::from_fn(w, h, |x, y| {
            image::LumaA([v16(x, y, 0), v16(x, y, 1)])
        })),
        6 => DynamicImage::ImageRgb16(ImageBuffer::from_fn(w, h, |x, y| {
            image::Rgb([v16(x, y, 0), v16(x, y, 1), v16(x, y, 2)])
        })),
        _ => DynamicImage::ImageRgba16(ImageBuffer::from_fn(w, h, |x, y| {
            image::Rgba([v16(x, y, 0), v16(x, y, 1), v16(x, y, 2), v16(x, y, 3)])
        })),
    };
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .unwrap();
    if let Some((lw, lh)) = c.lie {
        // IHDR data starts at byte 16 (8 signature + 4 length + 4 type).
        bytes[16..20].copy_from_slice(&lw.to_be_bytes());
        bytes[20..24].copy_from_slice(&lh.to_be_bytes());
        fix_crcs(&mut bytes);
    }
    let mut bytes = apply(&bytes, &c.muts, Kind::Binary);
    if c.fix_crc {
        fix_crcs(&mut bytes);
    }
    bytes
}

fn fuzz_png<T: Send + 'static>(
    format: &str,
    cases: u32,
    load: fn(&Path) -> Result<T, scene::SceneError>,
    accept: fn(&T) -> Result<(), String>,
) {
    let work = tempfile::tempdir().unwrap();
    let path: PathBuf = work.path().join("frame_0001.png");
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let t = tally.clone();
    let result = r.run(&png_case(), |c| {
        std::fs::write(&path, encode_png(&c)).unwrap();
        let p = path.clone();
        if let Some(v) = check_load(&t, &["frame_0001.png"], move || load(&p))? {
            accept(&v).map_err(|m| TestCaseError::fail(format!("loaded bad content: {m}")))?;
        }
        Ok(())
    });
    finish(format, result, &tally);
}

fn png_image(cases: u32) {
    fuzz_png(
        "PNG image",
        cases,
        |p| scene::ImageU8::load(p, [0.5; 3]),
        |i| {
            if i.width > 0
                && i.height > 0
                && i.data.len() == i.width as usize * i.height as usize * 3
            {
                Ok(())
            } else {
                Err(format!(
                    "{}×{} with {} bytes",
                    i.width,
                    i.height,
                    i.data.len()
                ))
            }
        },
    );
}

fn png_mask(cases: u32) {
    fuzz_png("PNG object-ID mask", cases, scene::load_mask, |m| {
        if m.width > 0 && m.height > 0 && m.data.len() == m.width as usize * m.height as usize {
            Ok(())
        } else {
            Err(format!(
                "{}×{} with {} bytes",
                m.width,
                m.height,
                m.data.len()
            ))
        }
    });
}

formats! {
    fuzz_dnerf_transforms_json: 500 => |n| fuzz_scene_file("transforms_train.json", dnerf_seed(), "transforms_train.json", Kind::Json, n);
    fuzz_dnerf_test_split_json: 150 => |n| fuzz_scene_file("transforms_test.json", dnerf_seed(), "transforms_test.json", Kind::Json, n);
    fuzz_dnerf_frame_png: 250 => |n| fuzz_scene_file("D-NeRF frame PNG", dnerf_seed(), "train/r_002.png", Kind::Binary, n);
    fuzz_dnerf_points3d_ply: 150 => |n| fuzz_scene_file("points3d.ply in a scene", dnerf_seed(), "points3d.ply", Kind::Text, n);
    fuzz_nerfies_dataset_json: 250 => |n| fuzz_scene_file("Nerfies dataset.json", nerfies_seed(), "dataset.json", Kind::Json, n);
    fuzz_nerfies_metadata_json: 200 => |n| fuzz_scene_file("Nerfies metadata.json", nerfies_seed(), "metadata.json", Kind::Json, n);
    fuzz_nerfies_scene_json: 150 => |n| fuzz_scene_file("Nerfies scene.json", nerfies_seed(), "scene.json", Kind::Json, n);
    fuzz_nerfies_camera_json: 400 => |n| fuzz_scene_file("Nerfies camera/*.json", nerfies_seed(), "camera/b.json", Kind::Json, n);
    fuzz_nerfies_frame_png: 150 => |n| fuzz_scene_file("Nerfies rgb/1x PNG", nerfies_seed(), "rgb/1x/a.png", Kind::Binary, n);
    fuzz_nerfies_points_npy: 300 => |n| fuzz_scene_file("Nerfies points.npy", nerfies_seed(), "points.npy", Kind::Text, n);
    fuzz_colmap_cameras_bin: 300 => |n| fuzz_scene_file("COLMAP cameras.bin", colmap_bin_seed(), "sparse/0/cameras.bin", Kind::Binary, n);
    fuzz_colmap_images_bin: 400 => |n| fuzz_scene_file("COLMAP images.bin", colmap_bin_seed(), "sparse/0/images.bin", Kind::Binary, n);
    fuzz_colmap_points_bin: 300 => |n| fuzz_scene_file("COLMAP points3D.bin", colmap_bin_seed(), "sparse/0/points3D.bin", Kind::Binary, n);
    fuzz_colmap_cameras_txt: 200 => |n| fuzz_scene_file("COLMAP cameras.txt", colmap_txt_seed(), "sparse/0/cameras.txt", Kind::Text, n);
    fuzz_colmap_images_txt: 300 => |n| fuzz_scene_file("COLMAP images.txt", colmap_txt_seed(), "sparse/0/images.txt", Kind::Text, n);
    fuzz_colmap_points_txt: 200 => |n| fuzz_scene_file("COLMAP points3D.txt", colmap_txt_seed(), "sparse/0/points3D.txt", Kind::Text, n);
    fuzz_llff_poses_bounds: 300 => |n| fuzz_scene_file("LLFF poses_bounds.npy", llff_seed(), "poses_bounds.npy", Kind::Text, n);
    fuzz_llff_precomputed: 250 => |n| fuzz_scene_file("LLFF precomputed.json", precomputed_seed(), "precomputed.json", Kind::Json, n);
    fuzz_nerfstudio_transforms: 400 => |n| fuzz_scene_file("nerfstudio transforms.json", nerfstudio_seed(), "transforms.json", Kind::Json, n);
    fuzz_ply_points: 600 => ply_points;
    fuzz_objects_json: 400 => objects_json;
    fuzz_png_image: 600 => png_image;
    fuzz_png_mask: 500 => png_mask;
}
