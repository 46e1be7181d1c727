//! The presets are used by reported experiments: without `--route`/`--add` their output
//! must stay identical. These hashes pin the presets' output as the reported experiments
//! used it; a change here means the presets changed. Images are hashed by their decoded
//! pixels (colour type, size, samples), every other file by its bytes, so that a PNG
//! encoder's different compression of the same pixels is not a change.

use scene::toycars::{generate, Preset, ToycarsConfig};
use std::path::Path;

/// What a file contributes: a PNG's decoded pixels, any other file's bytes.
fn content(p: &Path) -> Vec<u8> {
    if p.extension().is_some_and(|e| e == "png") {
        let img = image::open(p).unwrap();
        let mut v = format!("{:?} {}x{}\0", img.color(), img.width(), img.height()).into_bytes();
        v.extend_from_slice(img.as_bytes());
        v
    } else {
        std::fs::read(p).unwrap()
    }
}

/// FNV-1a over every file's relative path and content, in sorted path order.
fn tree_hash(root: &Path) -> u64 {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(root).unwrap().display().to_string();
                files.push((rel, content(&p)));
            }
        }
    }
    files.sort();
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for (name, bytes) in &files {
        for b in name.bytes().chain([0u8]).chain(bytes.iter().copied()) {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

fn hash_of(cfg: &ToycarsConfig) -> u64 {
    let dir = tempfile::tempdir().unwrap();
    generate(cfg, dir.path(), &|_, _| {}).unwrap();
    tree_hash(dir.path())
}

#[test]
fn presets_are_byte_identical_to_before_routes() {
    let tiny = |preset| ToycarsConfig {
        preset,
        width: 64,
        height: 48,
        frames: 10,
        seed: 3,
        ..Default::default()
    };
    let cases = [
        ("scene1", tiny(Preset::Scene1)),
        ("scene2", tiny(Preset::Scene2)),
        (
            "scene1 drive 0.25, 1 spp, no shadows",
            ToycarsConfig {
                drive: 0.25,
                supersample: false,
                shadows: false,
                ..tiny(Preset::Scene1)
            },
        ),
    ];
    let got: Vec<u64> = cases.iter().map(|(_, c)| hash_of(c)).collect();
    let want: [u64; 3] = [0x6d5ece16713f8850, 0xbe157a3c54a2dcda, 0x19abefc121b237b1];
    for ((name, _), (g, w)) in cases.iter().zip(got.iter().zip(want)) {
        assert_eq!(*g, w, "{name}: output changed ({g:#018x} != {w:#018x})");
    }
}
