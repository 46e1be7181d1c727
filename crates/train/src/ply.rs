//! The standard 3DGS PLY (`GaussianModel.save_ply` of graphdeco-inria/gaussian-splatting):
//! binary little endian, `x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity scale_0..2
//! rot_0..3`, all float; `f_rest` is channel-major (`features_rest.transpose(1, 2)`), scales
//! are logs, opacity is the logit. Every 3DGS viewer reads it.

use crate::error::{Result, TrainError};
use crate::model::{GaussianModel, SH_COEFFS, SH_FLOATS};
use std::path::Path;

const REST: usize = SH_COEFFS - 1;

fn property_names() -> Vec<String> {
    let mut v: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    v.extend((0..3).map(|c| format!("f_dc_{c}")));
    v.extend((0..3 * REST).map(|c| format!("f_rest_{c}")));
    v.push("opacity".into());
    v.extend((0..3).map(|c| format!("scale_{c}")));
    v.extend((0..4).map(|c| format!("rot_{c}")));
    v
}

/// Serializes `m` as a 3DGS PLY.
pub fn to_bytes(m: &GaussianModel) -> Vec<u8> {
    let names = property_names();
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        m.len()
    );
    for n in &names {
        out.push_str(&format!("property float {n}\n"));
    }
    out.push_str("end_header\n");
    let mut bytes = out.into_bytes();
    bytes.reserve(m.len() * names.len() * 4);
    let mut row = Vec::with_capacity(names.len());
    for i in 0..m.len() {
        row.clear();
        row.extend_from_slice(&m.means[i * 3..i * 3 + 3]);
        row.extend_from_slice(&[0.0; 3]);
        let sh = &m.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS];
        row.extend_from_slice(&sh[..3]);
        for c in 0..3 {
            row.extend((1..SH_COEFFS).map(|k| sh[k * 3 + c]));
        }
        row.push(m.opacity_logits[i]);
        row.extend_from_slice(&m.log_scales[i * 3..i * 3 + 3]);
        row.extend_from_slice(&m.quats[i * 4..i * 4 + 4]);
        for v in &row {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

pub fn write(path: &Path, m: &GaussianModel) -> Result<()> {
    crate::io::write_atomic(path, &to_bytes(m))
}

struct Header {
    n: usize,
    /// (name, byte size, is_double) per vertex property.
    props: Vec<(String, usize, bool)>,
    body: usize,
}

fn parse_header(bytes: &[u8], err: &dyn Fn(String) -> TrainError) -> Result<Header> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| err("no `end_header` line".into()))?;
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| err("header is not UTF-8".into()))?;
    let mut lines = text.lines();
    if lines.next() != Some("ply") {
        return Err(err("does not start with `ply`".into()));
    }
    let (mut n, mut props, mut in_vertex) = (None, Vec::new(), false);
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] if *f != "binary_little_endian" => {
                return Err(err(format!(
                    "format `{f}` unsupported (need binary_little_endian)"
                )))
            }
            ["element", "vertex", c] => {
                n = Some(
                    c.parse::<usize>()
                        .map_err(|_| err(format!("bad vertex count `{c}`")))?,
                );
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", ty, name] if in_vertex => {
                let (size, dbl) = match *ty {
                    "float" | "float32" => (4, false),
                    "double" | "float64" => (8, true),
                    t => {
                        return Err(err(format!(
                            "property `{name}` has type `{t}`; only float/double"
                        )))
                    }
                };
                props.push((name.to_string(), size, dbl));
            }
            _ => {}
        }
    }
    let n = n.ok_or_else(|| err("no `element vertex`".into()))?;
    Ok(Header {
        n,
        props,
        body: end + 11,
    })
}

/// Reads a 3DGS PLY. Missing `f_rest_*` means SH degree 0; the active degree is set from
/// how many are present. Extra float properties are ignored.
pub fn read(path: &Path) -> Result<GaussianModel> {
    let bytes = crate::io::read_file(path)?;
    let err = |problem: String| TrainError::Ply {
        path: path.to_path_buf(),
        problem,
    };
    let h = parse_header(&bytes, &err)?;
    let stride: usize = h.props.iter().map(|p| p.1).sum();
    // Checked: the header's count is untrusted, and a product that wraps around could pass
    // the size test and send the reads below out of bounds.
    let need = h.n.checked_mul(stride);
    if need.is_none_or(|need| bytes.len() - h.body < need) {
        return Err(err(format!(
            "truncated: {} vertices of {stride} bytes do not fit in the file's {} bytes of data",
            h.n,
            bytes.len() - h.body
        )));
    }
    let mut offsets = std::collections::HashMap::new();
    let mut off = 0;
    for (name, size, dbl) in &h.props {
        offsets.insert(name.as_str(), (off, *dbl));
        off += size;
    }
    let get = |name: &str| offsets.get(name).copied();
    let need = |name: &str| get(name).ok_or_else(|| err(format!("missing property `{name}`")));
    let value = |row: usize, (o, dbl): (usize, bool)| -> f32 {
        let p = h.body + row * stride + o;
        if dbl {
            f64::from_le_bytes(bytes[p..p + 8].try_into().expect("8 bytes")) as f32
        } else {
            f32::from_le_bytes(bytes[p..p + 4].try_into().expect("4 bytes"))
        }
    };
    let n_rest = (0..3 * REST)
        .take_while(|c| get(&format!("f_rest_{c}")).is_some())
        .count();
    let degree = match n_rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        k => {
            return Err(err(format!(
                "{k} f_rest properties; expected 0, 9, 24 or 45"
            )))
        }
    };
    let per = n_rest / 3;
    let mut m = GaussianModel {
        sh_degree: degree,
        ..Default::default()
    };
    let fixed: Vec<(usize, bool)> = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ]
    .iter()
    .map(|n| need(n))
    .collect::<Result<_>>()?;
    let rest: Vec<(usize, bool)> = (0..n_rest)
        .map(|c| need(&format!("f_rest_{c}")))
        .collect::<Result<_>>()?;
    m.sh = vec![0.0; h.n * SH_FLOATS];
    for i in 0..h.n {
        let f: Vec<f32> = fixed.iter().map(|&p| value(i, p)).collect();
        m.means.extend_from_slice(&f[0..3]);
        m.opacity_logits.push(f[6]);
        m.log_scales.extend_from_slice(&f[7..10]);
        m.quats.extend_from_slice(&f[10..14]);
        let sh = &mut m.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS];
        sh[..3].copy_from_slice(&f[3..6]);
        for c in 0..3 {
            for k in 0..per {
                sh[(k + 1) * 3 + c] = value(i, rest[c * per + k]);
            }
        }
    }
    m.validate().map_err(|e| err(e.to_string()))?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_and_channel_major_rest() {
        let mut m = crate::init::from_points(
            &[0.0, 1.0, 2.0, -1.0, 0.5, 3.0],
            &[0.2, 0.4, 0.6, 1.0, 0.0, 0.5],
            0.1,
        );
        for (k, v) in m.sh.iter_mut().enumerate() {
            *v = k as f32 * 0.01;
        }
        m.sh_degree = 3;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.ply");
        write(&p, &m).unwrap();
        assert_eq!(read(&p).unwrap(), m);
        // f_rest_1 of vertex 0 is coefficient 2, red channel.
        let b = std::fs::read(&p).unwrap();
        let body = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let f_rest_1 = 4 * (6 + 3 + 1);
        let v = f32::from_le_bytes(b[body + f_rest_1..body + f_rest_1 + 4].try_into().unwrap());
        assert_eq!(v, m.sh[2 * 3]);
    }

    #[test]
    fn truncated_and_garbage_files_are_clear_errors() {
        let m = crate::init::from_points(&[0.0, 1.0, 2.0], &[0.2, 0.4, 0.6], 0.1);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.ply");
        let b = to_bytes(&m);
        std::fs::write(&p, &b[..b.len() - 5]).unwrap();
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("t.ply") && e.contains("truncated"), "{e}");
        std::fs::write(&p, b"hello").unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("end_header"));
    }
}
