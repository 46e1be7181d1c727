//! The sweep's scenes, made before any run: a `synth` recipe is generated into
//! `OUT/scenes/<name>` (once; an existing one is reused) and every scene with a `segment`
//! spec gets its object-ID maps (`semdynreg segment`, which reuses a matching cache). Both
//! run as child processes of this executable, as `demo` runs them.

use super::grid::{LabelSource, MaskSource, SegmentSpec, SynthSpec};
use super::plan::{Plan, ScenePlan};
use crate::report::runs::run_self;
use anyhow::{Context, Result};

/// Makes every scene of the plan ready for training.
pub fn prepare(plan: &Plan) -> Result<()> {
    for s in &plan.scenes {
        if let Some(synth) = &s.synth {
            if !s.dir.join("objects.json").is_file() {
                run_self(&synth_args(s, synth))
                    .with_context(|| format!("making scene `{}`", s.name))?;
            }
        }
        if let Some(seg) = &s.segment {
            run_self(&segment_args(s, seg, plan.offline))
                .with_context(|| format!("object-ID maps of scene `{}`", s.name))?;
        }
    }
    Ok(())
}

fn synth_args(s: &ScenePlan, r: &SynthSpec) -> Vec<String> {
    let mut a: Vec<String> = ["synth", "toycars", "--out"].map(String::from).to_vec();
    a.push(s.dir.display().to_string());
    for (flag, value) in [
        ("--preset", r.preset.clone()),
        ("--width", r.width.to_string()),
        ("--height", r.height.to_string()),
        ("--frames", r.frames.to_string()),
        ("--seed", r.seed.to_string()),
        ("--drive", r.drive.to_string()),
    ] {
        a.extend([flag.to_string(), value]);
    }
    for route in &r.route {
        a.extend(["--route".into(), route.clone()]);
    }
    for add in &r.add {
        a.extend(["--add".into(), add.clone()]);
    }
    if r.no_antialias {
        a.push("--no-antialias".into());
    }
    if r.no_shadows {
        a.push("--no-shadows".into());
    }
    a
}

fn segment_args(s: &ScenePlan, g: &SegmentSpec, offline: bool) -> Vec<String> {
    let mut a = vec![
        "segment".to_string(),
        s.dir.display().to_string(),
        "--dict".into(),
        g.dict.join(","),
        "--masks".into(),
        match g.masks {
            MaskSource::Gt => "gt",
            MaskSource::Sam => "sam",
        }
        .into(),
        "--labels".into(),
        match g.labels {
            LabelSource::Gt => "gt",
            LabelSource::Clip => "clip",
        }
        .into(),
    ];
    if let Some(clip) = &g.clip {
        a.extend(["--clip".into(), clip.display().to_string()]);
    }
    if offline {
        a.push("--offline".into());
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recipes_become_the_commands_users_type() {
        let s = ScenePlan {
            name: "a".into(),
            dir: "/o/scenes/a".into(),
            synth: None,
            segment: None,
        };
        let r = SynthSpec {
            route: vec!["0,0;1,1".into()],
            no_shadows: true,
            ..Default::default()
        };
        assert_eq!(
            synth_args(&s, &r).join(" "),
            "synth toycars --out /o/scenes/a --preset scene1 --width 160 --height 120 --frames 96 --seed 0 --drive 1 --route 0,0;1,1 --no-shadows"
        );
        assert_eq!(
            segment_args(&s, &SegmentSpec::default(), true).join(" "),
            "segment /o/scenes/a --dict white SUV,yellow sedan,green SUV --masks gt --labels gt --offline"
        );
    }
}
