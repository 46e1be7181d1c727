//! Writing a toycars scene: per-frame RGBA image, mask and (with articulated objects)
//! part map, then `transforms_*.json`
//! (D-NeRF: camera-to-world in OpenGL axes) and `objects.json`.

use super::joints::swept_box;
use super::motion::{camera_pose, Layout, Motion, CAMERA_ANGLE_X};
use super::render::{render, Placed, RayCamera, World};
use super::{frame_key, ToycarsConfig};
use crate::objects::{ObjectFrame, ObjectInfo, ObjectsFile, PartInfo};
use crate::{mask_path, part_map_path, save_mask, save_rgba_png, MaskU8, SceneError};
use serde_json::json;
use std::path::Path;

/// What the metadata files need to know about one written frame.
pub struct FrameRecord {
    index: usize,
    time: f32,
    object_to_world: Vec<[[f32; 4]; 4]>,
    /// Per object, its links' link→world matrices (empty for rigid objects).
    part_to_world: Vec<Vec<[[f32; 4]; 4]>>,
}

fn focal(width: u32) -> f32 {
    0.5 * width as f32 / (0.5 * CAMERA_ANGLE_X).tan()
}

/// The frame's camera in the project's conventions (world→camera, OpenCV axes).
pub fn splat_camera(width: u32, height: u32, t: f32) -> splat::Camera {
    let (c, r) = camera_pose(t);
    let mut viewmat = [[0.0f32; 4]; 4];
    for k in 0..3 {
        viewmat[k][..3].copy_from_slice(&r[k]);
        viewmat[k][3] = -(r[k][0] * c[0] + r[k][1] * c[1] + r[k][2] * c[2]);
    }
    viewmat[3][3] = 1.0;
    let f = focal(width);
    splat::Camera {
        width,
        height,
        fx: f,
        fy: f,
        cx: 0.5 * width as f32,
        cy: 0.5 * height as f32,
        viewmat,
    }
}

pub fn render_frame(
    cfg: &ToycarsConfig,
    layout: &Layout,
    keys: (u64, u64),
    t: f32,
    out_dir: &Path,
    index: usize,
) -> Result<FrameRecord, SceneError> {
    // One matrix per object, used both to render and as the recorded ground truth.
    let poses: Vec<[[f32; 4]; 4]> = (0..layout.models.len())
        .map(|i| layout.pose(i, t).matrix())
        .collect();
    let links: Vec<Vec<[[f32; 4]; 4]>> = (0..layout.models.len())
        .map(|i| layout.link_poses(i, t))
        .collect();
    // A link is drawn as a model of its own, posed by its link→world matrix, under the
    // object's mask ID.
    let mut objects = Vec::new();
    for (i, (v, m)) in layout.models.iter().zip(&poses).enumerate() {
        objects.push(Placed::new(v, i as u8, m));
        for (k, (link, lm)) in v.links.iter().zip(&links[i]).enumerate() {
            let mut placed = Placed::new(&link.model, i as u8, lm);
            placed.part = k as u8 + 1;
            objects.push(placed);
        }
    }
    let sun = super::geometry::normalize([0.45, -0.55, 0.85]);
    let world = World {
        objects,
        ground_key: keys.0,
        paint_key: keys.1,
        sun,
        shadows: cfg.shadows,
    };
    let (center, rows) = camera_pose(t);
    let f = focal(cfg.width);
    let cam = RayCamera {
        center,
        rows,
        fx: f,
        fy: f,
        cx: 0.5 * cfg.width as f32,
        cy: 0.5 * cfg.height as f32,
    };
    let frame = render(&world, &cam, cfg.width, cfg.height, cfg.supersample);
    let (rgba, ids) = (frame.rgba, frame.ids);
    let (_, key) = frame_key(index);
    save_rgba_png(
        &out_dir.join(format!("{key}.png")),
        cfg.width,
        cfg.height,
        &rgba,
    )?;
    let mask = MaskU8 {
        width: cfg.width,
        height: cfg.height,
        data: ids,
    };
    save_mask(&mask_path(out_dir, &key), &mask)?;
    // Part maps only for scenes with articulated objects (the presets stay as they were).
    if layout.models.iter().any(|m| !m.links.is_empty()) {
        let parts = MaskU8 {
            width: cfg.width,
            height: cfg.height,
            data: articulated_only(layout, &mask.data, frame.parts),
        };
        save_mask(&part_map_path(out_dir, &key), &parts)?;
    }
    Ok(FrameRecord {
        index,
        time: t,
        object_to_world: poses,
        part_to_world: links,
    })
}

/// The part map keeps the pixels of articulated objects (255 elsewhere): rigid objects have
/// only a body.
fn articulated_only(layout: &Layout, ids: &[u8], mut parts: Vec<u8>) -> Vec<u8> {
    for (p, &id) in parts.iter_mut().zip(ids) {
        let rigid = layout
            .models
            .get(usize::from(id))
            .is_none_or(|m| m.links.is_empty());
        if rigid {
            *p = crate::MASK_BACKGROUND;
        }
    }
    parts
}

/// Camera-to-world in OpenGL axes (D-NeRF `transform_matrix`): the inverse of the
/// world→camera rotation, with the camera y and z columns negated.
fn transform_matrix(t: f32) -> [[f32; 4]; 4] {
    let (c, r) = camera_pose(t);
    let mut m = [[0.0f32; 4]; 4];
    for i in 0..3 {
        m[i] = [r[0][i], -r[1][i], -r[2][i], c[i]];
    }
    m[3][3] = 1.0;
    m
}

pub fn write_metadata(
    cfg: &ToycarsConfig,
    layout: &Layout,
    frames: &[FrameRecord],
    out: &Path,
) -> Result<(), SceneError> {
    let f = focal(cfg.width);
    for split in ["train", "val", "test"] {
        let list: Vec<_> = frames
            .iter()
            .filter(|fr| frame_key(fr.index).0 == split)
            .map(|fr| json!({"file_path": format!("./{}", frame_key(fr.index).1), "time": fr.time, "transform_matrix": transform_matrix(fr.time)}))
            .collect();
        let doc = json!({
            "camera_angle_x": CAMERA_ANGLE_X,
            "fl_x": f, "fl_y": f, "cx": 0.5 * cfg.width as f32, "cy": 0.5 * cfg.height as f32,
            "w": cfg.width, "h": cfg.height,
            "frames": list,
        });
        crate::io::write_json(&out.join(format!("transforms_{split}.json")), &doc)?;
    }
    let objects = layout
        .models
        .iter()
        .enumerate()
        .map(|(i, v)| ObjectInfo {
            id: i as u8,
            name: v.name.clone(),
            prompt: v.prompt.to_string(),
            moving: layout.is_moving(i),
            bbox_local: swept_box(v, cfg.frames),
            parts: v
                .links
                .iter()
                .map(|l| PartInfo {
                    name: l.name.clone(),
                    parent: l.parent,
                    bbox_local: [l.model.bbox_lo, l.model.bbox_hi],
                })
                .collect(),
        })
        .collect();
    let has_parts = layout.models.iter().any(|m| !m.links.is_empty());
    let frames = frames
        .iter()
        .map(|fr| ObjectFrame {
            file_path: frame_key(fr.index).1,
            time: fr.time,
            object_to_world: fr.object_to_world.clone(),
            // Only scenes with parts get the key: the presets' files stay byte-identical.
            part_to_world: if has_parts {
                fr.part_to_world.clone()
            } else {
                Vec::new()
            },
        })
        .collect();
    let mut generator = json!({"name": "semdynreg synth toycars", "preset": cfg.preset.name(), "seed": cfg.seed,
               "drive": cfg.drive, "width": cfg.width, "height": cfg.height, "frames": cfg.frames, "duration_s": 6.0,
               "mask_background": crate::MASK_BACKGROUND, "up_axis": "+z"});
    // Only scenes that use them get the keys: the presets' files stay byte-identical.
    if !cfg.routes.is_empty() {
        generator["routes"] = routes_record(cfg, layout)?;
    }
    if !cfg.adds.is_empty() {
        generator["adds"] = adds_record(cfg, layout);
    }
    let mut extra = serde_json::Map::new();
    extra.insert("generator".into(), generator);
    ObjectsFile {
        objects,
        frames,
        extra,
    }
    .save(&out.join("objects.json"))
}

/// `generator.routes`: per `--route`, the object it moves, its text and its length.
fn routes_record(cfg: &ToycarsConfig, layout: &Layout) -> Result<serde_json::Value, SceneError> {
    let mut out = Vec::new();
    for spec in &cfg.routes {
        let i = layout.route_target(spec)?;
        let length = match &layout.motions[i] {
            Motion::Route(r) => r.length(),
            _ => unreachable!("a routed object moves along its route"),
        };
        let waypoints: Vec<_> = spec
            .waypoints
            .iter()
            .map(|w| json!({"pos": w.pos, "angles_deg": w.angles_deg}))
            .collect();
        out.push(
            json!({"object": layout.models[i].name, "id": i, "spec": spec.text,
                        "length": length, "waypoints": waypoints}),
        );
    }
    Ok(serde_json::Value::Array(out))
}

/// `generator.adds`: per `--add`, the object it created and where.
fn adds_record(cfg: &ToycarsConfig, layout: &Layout) -> serde_json::Value {
    let first = layout.models.len() - cfg.adds.len();
    cfg.adds
        .iter()
        .enumerate()
        .map(|(k, a)| {
            json!({"kind": a.kind.name(), "name": layout.models[first + k].name, "id": first + k,
                              "spec": a.text, "x": a.x, "y": a.y, "yaw_deg": a.yaw_deg})
        })
        .collect()
}
