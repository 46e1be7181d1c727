//! What makes a checkpoint trustworthy: a CRC-32 of every file and of
//! every tensor inside it, written last into `checksums.json` and verified on every load,
//! so a flipped bit or a truncated write is refused with the file and tensor named rather
//! than trained on. A bit flip inside an Adam moment is finite and would otherwise go
//! unnoticed; CRC-32 detects every single-bit error and every burst up to 32 bits.
//!
//! Checkpoints written before this file existed (state format `semdynreg-train-1`) load
//! unverified, with a warning; a newer one without it is refused as incomplete.

use crate::error::{Result, TrainError};
use crate::model::GaussianModel;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

pub const CHECKSUMS_NAME: &str = "checksums.json";
const FORMAT: &str = "crc32-1";

/// `checksums.json`: per file its CRC, and per file the CRC of each tensor it holds (the
/// PLY's parameter groups, the safetensors' tensors).
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checksums {
    pub format: String,
    pub files: BTreeMap<String, String>,
    pub tensors: BTreeMap<String, BTreeMap<String, String>>,
}

pub fn crc_hex(bytes: &[u8]) -> String {
    format!("{:08x}", crc32fast::hash(bytes))
}

/// CRC of `v`'s little-endian bytes, streamed (no copy of the whole array).
fn crc_f32(v: &[f32]) -> String {
    let mut h = crc32fast::Hasher::new();
    let mut buf = Vec::with_capacity(4 * 4096);
    for chunk in v.chunks(4096) {
        buf.clear();
        buf.extend(chunk.iter().flat_map(|x| x.to_le_bytes()));
        h.update(&buf);
    }
    format!("{:08x}", h.finalize())
}

/// The parameter groups of the Gaussians as the PLY stores them (read back bit-exactly).
pub fn model_groups(m: &GaussianModel) -> BTreeMap<String, String> {
    [
        ("means", &m.means),
        ("quats", &m.quats),
        ("log_scales", &m.log_scales),
        ("opacity_logits", &m.opacity_logits),
        ("sh", &m.sh),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), crc_f32(v)))
    .collect()
}

/// The CRC of each tensor of a safetensors file.
pub fn safetensors_tensors(bytes: &[u8]) -> Option<BTreeMap<String, String>> {
    let st = safetensors::SafeTensors::deserialize(bytes).ok()?;
    Some(
        st.tensors()
            .into_iter()
            .map(|(name, view)| (name, crc_hex(view.data())))
            .collect(),
    )
}

fn bad(dir: &Path, file: &str, problem: String) -> TrainError {
    TrainError::Checkpoint {
        path: dir.join(file),
        problem,
    }
}

/// The first tensor whose CRC differs from `want`, or one that is missing.
fn first_bad_tensor(
    got: &BTreeMap<String, String>,
    want: &BTreeMap<String, String>,
) -> Option<String> {
    want.iter().find_map(|(name, crc)| match got.get(name) {
        Some(c) if c == crc => None,
        Some(c) => Some(format!(
            "tensor `{name}` fails its checksum (CRC-32 {c}, written as {crc}): a flipped bit or a damaged copy"
        )),
        None => Some(format!("tensor `{name}` is missing")),
    })
}

/// Names what in `file` (whose whole-file CRC failed) is damaged.
fn locate(dir: &Path, file: &str, bytes: &[u8], sums: &Checksums) -> String {
    let want = sums.tensors.get(file);
    let got = if file.ends_with(".safetensors") {
        safetensors_tensors(bytes)
    } else if file.ends_with(".ply") {
        crate::ply::read(&dir.join(file))
            .ok()
            .map(|m| model_groups(&m))
    } else {
        None
    };
    match (want, got) {
        (Some(w), Some(g)) => first_bad_tensor(&g, w).unwrap_or_else(|| {
            "fails its checksum outside the tensors (header or metadata damaged)".into()
        }),
        (Some(_), None) => "fails its checksum and no longer parses".into(),
        _ => "fails its checksum".into(),
    }
}

/// Verifies every file `checksums.json` lists in the checkpoint folder `dir`; `false` when
/// the folder has no `checksums.json` (the caller accepts that only from checkpoints
/// written before checksums existed).
pub fn verify(dir: &Path) -> Result<bool> {
    let path = dir.join(CHECKSUMS_NAME);
    if !path.is_file() {
        return Ok(false);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| TrainError::io(&path, e))?;
    let sums: Checksums = serde_json::from_str(&text)
        .map_err(|e| bad(dir, CHECKSUMS_NAME, format!("not readable: {e}")))?;
    if sums.format != FORMAT {
        return Err(bad(
            dir,
            CHECKSUMS_NAME,
            format!("format `{}`, expected `{FORMAT}`", sums.format),
        ));
    }
    for (file, want) in &sums.files {
        let p = dir.join(file);
        let bytes = crate::io::read_file(&p)?;
        if &crc_hex(&bytes) != want {
            return Err(bad(dir, file, locate(dir, file, &bytes, &sums)));
        }
    }
    Ok(true)
}

/// Writes `checksums.json` into `dir` for the files just written there, from their bytes
/// in memory: each file's CRC and its tensors' (the PLY's groups from `ply.1`).
pub fn write(
    dir: &Path,
    ply: (&str, &GaussianModel, &[u8]),
    files: &[(&str, &[u8])],
) -> Result<()> {
    let mut sums = Checksums {
        format: FORMAT.into(),
        ..Default::default()
    };
    sums.files.insert(ply.0.into(), crc_hex(ply.2));
    sums.tensors.insert(ply.0.into(), model_groups(ply.1));
    for (name, bytes) in files {
        sums.files.insert(name.to_string(), crc_hex(bytes));
        if let Some(t) = safetensors_tensors(bytes) {
            sums.tensors.insert(name.to_string(), t);
        }
    }
    let text = serde_json::to_string_pretty(&sums).expect("plain data serializes");
    crate::io::write_atomic(&dir.join(CHECKSUMS_NAME), text.as_bytes())
}
