//! `semdynreg export RUN --per-object --out DIR [--times a:b:step]`: each rigid object of a
//! run as a unit to reuse elsewhere: `DIR/<name>.ply` (its Gaussians in its own frame) and
//! `DIR/<name>.trajectory.json` (train::objects::export::TrajectoryFile; the format is in
//! `export --help` and docs/training.md), plus `DIR/background.ply` (the deformable rest,
//! undeformed). Every file is written atomically (temp file beside it, then rename).

use super::render::LoadedRun;
use anyhow::{bail, Context, Result};
use std::path::Path;
use train::objects::export::{
    background_model, object_model, scene_frames, trajectory_file, SkinningWeights,
};
use train::objects::select::{file_safe, BACKGROUND};
use train::objects::RigidObject;

pub fn write(r: &LoadedRun, run: &Path, out: &Path, times: &[f32]) -> Result<()> {
    if r.objects.is_empty() {
        bail!(
            "{} has no rigid objects to export (train with --objects)",
            run.display()
        );
    }
    let frames = scene_frames(&r.dataset);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (o, stem) in r.objects.iter().zip(file_stems(&r.objects)) {
        let model = object_model(o, &r.model, &r.column);
        let ply = out.join(format!("{stem}.ply"));
        train::ply::write(&ply, &model).with_context(|| format!("writing {}", ply.display()))?;
        let json = out.join(format!("{stem}.trajectory.json"));
        let mut file = trajectory_file(o, model.len(), &frames, times);
        let skin = train::objects::parts::skin::weights_of(&r.objects, &r.column, &r.aux, o.id);
        file.skinning = skin.map(|(parts, weights)| SkinningWeights { parts, weights });
        scene::io::write_json(&json, &file)
            .with_context(|| format!("writing {}", json.display()))?;
        let mut kind = match (&file.skinning, o.is_static) {
            (Some(s), _) => format!("skinned over {} parts", s.parts.len()),
            (None, true) => "static".into(),
            (None, false) => "moving".into(),
        };
        if has_residual(r, o.mask) {
            kind.push_str("; its residual field is not exported: the PLY is its rest shape");
        }
        println!(
            "{} (ID {}, {kind}): {} Gaussians → {}, {} poses → {}",
            o.name,
            o.id,
            model.len(),
            ply.display(),
            frames.len() + times.len(),
            json.display()
        );
    }
    let bg = background_model(&r.model, &r.column);
    let ply = out.join(format!("{BACKGROUND}.ply"));
    train::ply::write(&ply, &bg).with_context(|| format!("writing {}", ply.display()))?;
    println!(
        "{BACKGROUND} (deformable, canonical space): {} Gaussians → {}",
        bg.len(),
        ply.display()
    );
    Ok(())
}

/// Whether object `mask` of the run has a residual field (`[objects] residual`).
fn has_residual(r: &LoadedRun, mask: u8) -> bool {
    let node = r.nodes.get::<train::objects::RigidObjects>();
    let residual = node.and_then(|n| n.residual.as_ref());
    residual.is_some_and(|res| res.fields.iter().any(|f| f.mask == mask))
}

/// One file stem per object: its name made file-safe, with `-<id>` added where two objects
/// would otherwise share a file or an object would take `background.ply`.
fn file_stems(objects: &[RigidObject]) -> Vec<String> {
    let safe: Vec<String> = objects.iter().map(|o| file_safe(&o.name)).collect();
    objects
        .iter()
        .zip(&safe)
        .map(|(o, s)| {
            if s == BACKGROUND || safe.iter().filter(|t| *t == s).count() > 1 {
                format!("{s}-{}", o.id)
            } else {
                s.clone()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use train::objects::Trajectory;

    #[test]
    fn clashing_names_get_their_id() {
        let tr = Trajectory::constant(0.0, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
        let o = |id, name: &str| RigidObject::new(id, name.into(), tr.clone(), true);
        let stems = file_stems(&[o(0, "car"), o(1, "car"), o(2, "a/b"), o(3, "background")]);
        assert_eq!(stems, ["car-0", "car-1", "a-b", "background-3"]);
    }
}
