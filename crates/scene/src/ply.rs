//! Reads the `x y z` (and, when present, `red green blue`) of the `vertex` element of a PLY
//! file (ASCII or binary little-endian, any scalar types), e.g. the `points3d.ply`
//! Deformable-3DGS writes beside D-NeRF scenes or a COLMAP point cloud.

use crate::SceneError;
use std::path::Path;

struct Property {
    name: String,
    size: usize,
    kind: char, // 'i' signed, 'u' unsigned, 'f' float
}

/// The vertex positions of a PLY file.
pub fn read_points(path: &Path) -> Result<Vec<[f32; 3]>, SceneError> {
    Ok(read_points_rgb(path)?.0)
}

/// The vertex positions of a PLY file and their colours in [0, 1] when the vertices have
/// `red green blue` (integer types are divided by their maximum, as 3DGS's `fetchPly`
/// does for `uchar`; float colours are taken as they are, clamped to [0, 1]).
pub fn read_points_rgb(path: &Path) -> Result<PointsRgb, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    let bad = |msg: &str| SceneError::invalid(path, format!("PLY: {msg}"));
    let end = find_header_end(&bytes).ok_or_else(|| bad("no `end_header` line"))?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header is not text"))?;
    let (format, count, props) = parse_header(header).map_err(|m| bad(&m))?;
    let find = |n: &str| props.iter().position(|p| p.name == n);
    let mut idx: Vec<usize> = ["x", "y", "z"]
        .iter()
        .map(|n| find(n).ok_or_else(|| bad(&format!("vertex has no `{n}`"))))
        .collect::<Result<_, _>>()?;
    let rgb: Option<Vec<usize>> = ["red", "green", "blue"].iter().map(|n| find(n)).collect();
    idx.extend(rgb.iter().flatten());
    let body = &bytes[end..];
    let values = match format.as_str() {
        "ascii" => read_ascii(body, count, props.len(), &idx),
        "binary_little_endian" => read_binary(body, count, &props, &idx),
        other => Err(format!("unsupported format `{other}`")),
    }
    .map_err(|m| bad(&m))?;
    if values.iter().any(|v| !v.is_finite()) {
        return Err(bad("non-finite vertex value"));
    }
    let cols = idx.len();
    let points = values
        .chunks_exact(cols)
        .map(|v| [v[0], v[1], v[2]])
        .collect();
    let colors = rgb.map(|rgb| {
        let max: Vec<f32> = rgb.iter().map(|&k| colour_max(&props[k])).collect();
        values
            .chunks_exact(cols)
            .map(|v| std::array::from_fn(|c| (v[3 + c] / max[c]).clamp(0.0, 1.0)))
            .collect()
    });
    Ok((points, colors))
}

/// Writes `points` (and `colors` in [0, 1], as `uchar red green blue`) as a binary
/// little-endian PLY, atomically: what [`read_points_rgb`] and 3DGS's `fetchPly` read.
pub fn write_points_rgb(
    path: &Path,
    points: &[[f32; 3]],
    colors: Option<&[[f32; 3]]>,
) -> Result<(), SceneError> {
    if colors.is_some_and(|c| c.len() != points.len()) {
        return Err(SceneError::Argument(format!(
            "{} points but {} colours",
            points.len(),
            colors.map_or(0, <[_]>::len)
        )));
    }
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        points.len()
    )
    .into_bytes();
    if colors.is_some() {
        b.extend(b"property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    b.extend(b"end_header\n");
    for (i, p) in points.iter().enumerate() {
        for v in p {
            b.extend(v.to_le_bytes());
        }
        if let Some(c) = colors {
            b.extend(c[i].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    crate::io::write_atomic(path, |w| w.write_all(&b))
}

/// Positions and, when the file has them, colours in [0, 1].
pub type PointsRgb = (Vec<[f32; 3]>, Option<Vec<[f32; 3]>>);

/// The value of a colour property that means full intensity (255 for `uchar`).
fn colour_max(p: &Property) -> f32 {
    match p.kind {
        'f' => 1.0,
        _ => ((1u64 << (8 * p.size - (p.kind == 'i') as usize)) - 1) as f32,
    }
}

fn find_header_end(bytes: &[u8]) -> Option<usize> {
    let key = b"end_header";
    let pos = bytes.windows(key.len()).position(|w| w == key)?;
    let nl = bytes[pos..].iter().position(|&b| b == b'\n')?;
    Some(pos + nl + 1)
}

fn parse_header(header: &str) -> Result<(String, usize, Vec<Property>), String> {
    let mut format = String::new();
    let mut count = None;
    let mut props = Vec::new();
    let mut in_vertex = false;
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, ..] => format = (*f).to_string(),
            ["element", name, n] => {
                in_vertex = *name == "vertex";
                if in_vertex {
                    count = Some(
                        n.parse::<usize>()
                            .map_err(|_| "bad vertex count".to_string())?,
                    );
                } else if count.is_none() {
                    return Err("an element precedes `vertex` (unsupported)".into());
                }
            }
            ["property", "list", ..] if in_vertex => return Err("list property in vertex".into()),
            ["property", ty, name] if in_vertex => props.push(property(ty, name)?),
            _ => {}
        }
    }
    Ok((format, count.ok_or("no `vertex` element")?, props))
}

fn property(ty: &str, name: &str) -> Result<Property, String> {
    let (size, kind) = match ty {
        "char" | "int8" => (1, 'i'),
        "uchar" | "uint8" => (1, 'u'),
        "short" | "int16" => (2, 'i'),
        "ushort" | "uint16" => (2, 'u'),
        "int" | "int32" => (4, 'i'),
        "uint" | "uint32" => (4, 'u'),
        "float" | "float32" => (4, 'f'),
        "double" | "float64" => (8, 'f'),
        other => return Err(format!("unknown property type `{other}`")),
    };
    Ok(Property {
        name: name.to_string(),
        size,
        kind,
    })
}

fn read_ascii(body: &[u8], count: usize, nprops: usize, idx: &[usize]) -> Result<Vec<f32>, String> {
    let text = std::str::from_utf8(body).map_err(|_| "ASCII body is not text")?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let rows: Result<Vec<Vec<f32>>, String> = (0..count)
        .map(|i| {
            let line = lines
                .next()
                .ok_or(format!("only {i} of {count} vertices"))?;
            let v: Vec<f32> = line
                .split_whitespace()
                .take(nprops)
                .map(|s| s.parse().unwrap_or(f32::NAN))
                .collect();
            if v.len() < nprops {
                return Err(format!(
                    "vertex {i} has {} values, expected {nprops}",
                    v.len()
                ));
            }
            Ok(idx.iter().map(|&k| v[k]).collect())
        })
        .collect();
    Ok(rows?.concat())
}

fn read_binary(
    body: &[u8],
    count: usize,
    props: &[Property],
    idx: &[usize],
) -> Result<Vec<f32>, String> {
    let stride: usize = props.iter().map(|p| p.size).sum();
    // Checked: a header may claim any count, and `stride * count` must not wrap around to
    // a size that the body seems to hold.
    if stride
        .checked_mul(count)
        .is_none_or(|need| body.len() < need)
    {
        return Err(format!(
            "body has {} bytes, {count} vertices of {stride} bytes do not fit",
            body.len()
        ));
    }
    let offsets: Vec<usize> = props
        .iter()
        .scan(0, |o, p| {
            let s = *o;
            *o += p.size;
            Some(s)
        })
        .collect();
    let value = |rec: &[u8], k: usize| -> f32 {
        let (p, b) = (&props[k], &rec[offsets[k]..offsets[k] + props[k].size]);
        match (p.kind, p.size) {
            ('f', 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            ('f', _) => f64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as f32,
            ('u', _) => b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x)) as f32,
            _ => {
                let u = b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x));
                let shift = 64 - 8 * p.size as u32;
                (((u << shift) as i64) >> shift) as f32
            }
        }
    };
    Ok(body
        .chunks_exact(stride)
        .take(count)
        .flat_map(|rec| idx.iter().map(move |&k| value(rec, k)))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_binary_and_ascii() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.ply");
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nend_header\n".to_vec();
        for v in [[1.0f32, 2.0, 3.0], [-1.0, 0.5, 0.25]] {
            for x in v {
                b.extend(x.to_le_bytes());
            }
            b.push(7);
        }
        std::fs::write(&p, b).unwrap();
        assert_eq!(
            read_points(&p).unwrap(),
            vec![[1.0, 2.0, 3.0], [-1.0, 0.5, 0.25]]
        );
        assert_eq!(
            read_points_rgb(&p).unwrap().1,
            None,
            "red alone is no colour"
        );
        std::fs::write(&p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nend_header\n1 2 3\n").unwrap();
        assert_eq!(read_points(&p).unwrap(), vec![[1.0, 2.0, 3.0]]);
    }

    /// 3DGS / COLMAP clouds: `uchar` colours become [0, 1]; float colours are kept.
    #[test]
    fn reads_vertex_colours() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.ply");
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n".to_vec();
        for (v, c) in [
            ([1.0f32, 2.0, 3.0], [255u8, 0, 51]),
            ([4.0, 5.0, 6.0], [0, 255, 102]),
        ] {
            for x in v.iter().chain(&[0.0]) {
                b.extend(x.to_le_bytes());
            }
            b.extend(c);
        }
        std::fs::write(&p, b).unwrap();
        let (pts, cols) = read_points_rgb(&p).unwrap();
        assert_eq!(pts, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let cols = cols.expect("colours");
        assert_eq!(cols[0], [1.0, 0.0, 0.2]);
        assert_eq!(cols[1], [0.0, 1.0, 0.4]);
        std::fs::write(&p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float red\nproperty float green\nproperty float blue\nend_header\n1 2 3 0.25 1.5 0.5\n").unwrap();
        assert_eq!(read_points_rgb(&p).unwrap().1, Some(vec![[0.25, 1.0, 0.5]]));
    }
}
