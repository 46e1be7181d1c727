#!/usr/bin/env python3
"""Print one `--prompt NAME@x,y@FRAME` per vehicle of a toycars scene: the pixel deepest
inside its ground-truth mask on the first frame (in time order) that shows it, as
`semdynreg demo --id-maps sam` clicks. Used to measure `segment --track` against the ground
truth (docs/semantics.md); standard library only.

    semdynreg segment SCENE --track $(python3 scripts/gt_clicks.py SCENE)
"""
import json
import struct
import sys
import zlib
from pathlib import Path


def read_png_gray(path):
    """8-bit greyscale (or the first channel of 8-bit RGB/RGBA) PNG → (w, h, rows)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG")
    pos, idat, w = 8, b"", None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            if depth != 8 or ctype not in (0, 2, 6) or body[12] != 0:
                sys.exit(f"{path}: only non-interlaced 8-bit grey/RGB/RGBA PNGs")
            ch = {0: 1, 2: 3, 6: 4}[ctype]
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, stride, rows, prev = zlib.decompress(idat), w * ch, [], bytearray(w * ch)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - ch] if i >= ch else 0
            b, c = prev[i], (prev[i - ch] if i >= ch else 0)
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line[::ch]))
        prev = line
    return w, h, rows


def deepest(w, h, rows, value):
    """The pixel of `value` farthest (chessboard distance) from any other pixel."""
    big = w + h
    d = [[0 if rows[y][x] != value else big for x in range(w)] for y in range(h)]
    for y in range(h):
        for x in range(w):
            if d[y][x]:
                up = d[y - 1][x] if y else 0
                left = d[y][x - 1] if x else 0
                d[y][x] = min(d[y][x], up + 1, left + 1)
    best = None
    for y in reversed(range(h)):
        for x in reversed(range(w)):
            if d[y][x]:
                down = d[y + 1][x] if y + 1 < h else 0
                right = d[y][x + 1] if x + 1 < w else 0
                d[y][x] = min(d[y][x], down + 1, right + 1)
                if best is None or d[y][x] >= best[0]:
                    best = (d[y][x], x, y)
    return best


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    scene = Path(sys.argv[1])
    objects = json.loads((scene / "objects.json").read_text())["objects"]
    frames = []
    for split in ("train", "val", "test"):
        t = scene / f"transforms_{split}.json"
        if t.exists():
            frames += json.loads(t.read_text())["frames"]
    frames.sort(key=lambda f: f["time"])
    out = []
    for o in objects:
        for i, f in enumerate(frames):
            mask = scene / "masks" / (f["file_path"].removeprefix("./") + ".png")
            hit = deepest(*read_png_gray(mask), o["id"])
            if hit:
                out += ["--prompt", f"{o['name']}@{hit[1] + 0.5:.1f},{hit[2] + 0.5:.1f}@{i}"]
                break
        else:
            sys.exit(f"object {o['id']} ({o['name']}) is in no ground-truth mask")
    print(" ".join(out))


if __name__ == "__main__":
    main()
