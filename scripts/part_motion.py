#!/usr/bin/env python3
"""How well each recovered part's trajectory moves like a true part (generated scenes).

`semdynreg export RUN --per-object --out DIR` writes each body of an articulated object
(`crane.ply`, `crane-part-1.ply`, ...) in the object's frame with its trajectory. For
every such body this script carries its Gaussians from the first frame to every 4th
frame by the body's own trajectory, and by each true motion the scene's `objects.json`
records for the object (held still, and each part's `part_to_world`), and prints the RMS
distance between the two and the RMS of the true motion, so

    follow = 1 - rms(recovered - true) / rms(true motion)

says how much of a true part's motion the recovered trajectory reproduces, independent of
which Gaussians the renders draw where (what `eval`'s per-part follow measures).

Usage: scripts/part_motion.py SCENE EXPORT_DIR OBJECT   (standard library only)
"""
import json
import math
import os
import struct
import sys


def read_ply_means(path):
    """The x, y, z of every vertex of a binary little-endian 3DGS PLY (all float32)."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        n = int(next(h for h in header if h.startswith("element vertex")).split()[-1])
        props = [h for h in header if h.startswith("property")]
        if any(p.split()[1] != "float" for p in props):
            sys.exit(f"{path}: only float properties are read")
        k = len(props)
        data = f.read(n * 4 * k)
    return [struct.unpack_from("<3f", data, i * 4 * k) for i in range(n)]


def apply(m, x):
    return [sum(m[r][c] * x[c] for c in range(3)) + m[r][3] for r in range(3)]


def inverse(m):
    r = [[m[c][row] for c in range(3)] for row in range(3)]
    t = [-sum(r[row][c] * m[c][3] for c in range(3)) for row in range(3)]
    return [r[0] + [t[0]], r[1] + [t[1]], r[2] + [t[2]], [0.0, 0.0, 0.0, 1.0]]


def compose(a, b):
    return [[sum(a[r][k] * b[k][c] for k in range(4)) for c in range(4)] for r in range(4)]


IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    scene, export, name = sys.argv[1:]
    truth = json.load(open(os.path.join(scene, "objects.json")))
    index = next((i for i, o in enumerate(truth["objects"]) if o["name"] == name), None)
    if index is None:
        sys.exit(f"{scene}/objects.json has no object `{name}`")
    parts = [p["name"] for p in truth["objects"][index].get("parts", [])]
    frames = sorted(truth["frames"], key=lambda f: f["time"])
    true_motion = {round(f["time"], 5): f["part_to_world"][index] for f in frames}
    times = sorted(true_motion)[::4]
    t0 = times[0]
    bodies = sorted(f[:-4] for f in os.listdir(export)
                    if f.endswith(".ply") and (f == f"{name}.ply" or f.startswith(f"{name}-part-")))
    if not bodies:
        sys.exit(f"{export}: no {name}.ply or {name}-part-N.ply (run `semdynreg export RUN --per-object --out {export}`)")
    print(f"{'body':<16} {'Gaussians':>9}  " + "  ".join(f"{'vs ' + t:>22}" for t in ["still"] + parts))
    for body in bodies:
        means = read_ply_means(os.path.join(export, body + ".ply"))[::5]
        track = json.load(open(os.path.join(export, body + ".trajectory.json")))
        pose = {round(f["time"], 5): f["object_to_world"] for f in track["frames"]}
        first = [apply(pose[t0], x) for x in means]
        cells = []
        for k in [None] + list(range(len(parts))):
            err = motion = 0.0
            for t in times:
                ours = compose(pose[t], inverse(pose[t0]))
                true = IDENTITY if k is None else compose(true_motion[t][k], inverse(true_motion[t0][k]))
                for x in first:
                    a, b = apply(ours, x), apply(true, x)
                    err += sum((a[c] - b[c]) ** 2 for c in range(3))
                    motion += sum((b[c] - x[c]) ** 2 for c in range(3))
            n = len(times) * len(first)
            err, motion = math.sqrt(err / n), math.sqrt(motion / n)
            follow = f"{100 * (1 - err / motion):5.0f} %" if motion > 0 else "   -   "
            cells.append(f"{err:.3f} / {motion:.3f} {follow}")
        print(f"{body:<16} {len(means) * 5:>9}  " + "  ".join(f"{c:>22}" for c in cells))
    print("cells: rms(recovered - true) / rms(true motion), follow")


if __name__ == "__main__":
    main()
