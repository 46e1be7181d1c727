# Diagnostic (docs/regularizer.md, "Flip-book"): do the Gaussians that draw a toycars vehicle
# ride with it, or does the model show different Gaussians at different times? Needs numpy.
#
#   semdynreg export RUN --times 0:1:0.1 --out EXPORT_DIR
#   python3 scripts/flipbook.py SCENE EXPORT_DIR [OBJECT_ID]      (0 = the moving white SUV)
#
# Prints, per exported time, how many Gaussians (opacity > 0.05) lie inside the vehicle's
# true box (padded 0.03), how many times each of them is inside, how far the ones inside at
# the middle time follow the vehicle's motion to the first and last time, and how their
# size changes. `semdynreg eval` reports the follow share over all test times in Rust
# (RUN/eval/consistency.json); this script shows the mechanism behind a low value.
import json, sys, glob, os
import numpy as np

def read_ply(p):
    with open(p, 'rb') as f:
        names = []
        n = 0
        while True:
            line = f.readline().decode().strip()
            if line.startswith('element vertex'):
                n = int(line.split()[-1])
            elif line.startswith('property'):
                names.append(line.split()[-1])
            elif line == 'end_header':
                break
        a = np.frombuffer(f.read(n * 4 * len(names)), dtype='<f4').reshape(n, len(names))
    return {k: a[:, i] for i, k in enumerate(names)}

scene, expdir, obj = sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 0
meta = json.load(open(os.path.join(scene, 'objects.json')))
box = np.array(meta['objects'][obj]['bbox_local']); pad = 0.03
frames = sorted(meta['frames'], key=lambda f: f['time'])
def pose(t):
    f = min(frames, key=lambda f: abs(f['time'] - t))
    return np.array(f['object_to_world'][obj])
files = sorted(glob.glob(os.path.join(expdir, 't_*.ply')))
inside = []
for p in files:
    t = float(os.path.basename(p)[2:-4])
    g = read_ply(p)
    x = np.stack([g['x'], g['y'], g['z'], np.ones_like(g['x'])], 1)
    loc = (np.linalg.inv(pose(t)) @ x.T).T[:, :3]
    op = 1 / (1 + np.exp(-g['opacity']))
    s = np.exp(np.maximum.reduce([g['scale_0'], g['scale_1'], g['scale_2']]))
    ins = np.all((loc >= box[0] - pad) & (loc <= box[1] + pad), 1) & (op > 0.05)
    inside.append((t, ins, s, loc))
n = len(inside[0][1])
ever = np.zeros(n, bool)
for t, ins, s, loc in inside:
    ever |= ins
print(f"object {meta['objects'][obj]['name']}: {ever.sum()} Gaussians inside its box at some time")
for t, ins, s, _ in inside:
    print(f"t={t:.1f}: inside {ins.sum():5d}  median max-scale inside {np.median(s[ins]) if ins.any() else 0:.4f}"
          f"  (of ever-inside: {ins[ever].mean():.2f})")
# How many times is each ever-inside Gaussian inside?
cnt = sum(ins.astype(int) for _, ins, _, _ in inside)
h = np.bincount(cnt[ever], minlength=len(inside) + 1)
print("times inside (of", len(inside), "):", {i: int(c) for i, c in enumerate(h) if c})
# Of the Gaussians inside at the middle time, how far do they follow the vehicle's motion?
# follow = (Δx_gaussian · Δx_vehicle) / |Δx_vehicle|² between the middle time and each end
# (1: rides along; 0: stays where it was).
mid = len(inside) // 2
tm, ins_m, _, _ = inside[mid]
def world(p):
    g = read_ply(p)
    return np.stack([g['x'], g['y'], g['z']], 1)
X = [world(p) for p in files]
for j in (0, len(files) - 1):
    t = inside[j][0]
    c_mid = pose(tm)[:3, 3]; c_j = pose(t)[:3, 3]
    dv = c_j - c_mid
    if np.linalg.norm(dv) < 1e-6:
        print(f"t {tm:.1f}→{t:.1f}: the vehicle does not move")
        continue
    dg = X[j][ins_m] - X[mid][ins_m]
    f = dg @ dv / (dv @ dv)
    print(f"t {tm:.1f}→{t:.1f}: vehicle moves {np.linalg.norm(dv):.3f}; its Gaussians follow "
          f"median {np.median(f):.2f}, quartiles {np.percentile(f, 25):.2f}/{np.percentile(f, 75):.2f}")
# And how do they vanish when the vehicle has left? Their size (mean of the three scales)
# at each end relative to the middle time.
def sizes(p):
    g = read_ply(p)
    return np.exp((g['scale_0'] + g['scale_1'] + g['scale_2']) / 3)
S = [sizes(p) for p in files]
for j in (0, len(files) - 1):
    r = S[j][ins_m] / S[mid][ins_m]
    print(f"size at t={inside[j][0]:.1f} / at t={tm:.1f}: median {np.median(r):.2f}, quartiles "
          f"{np.percentile(r, 25):.2f}/{np.percentile(r, 75):.2f}; below 0.2×: {(r < 0.2).mean():.2f}")
# Where do they go instead? Displacement of the middle-time Gaussians to each end, split
# into the component along the vehicle's motion and the rest (z = up in toycars).
for j in (0, len(files) - 1):
    d = X[j][ins_m] - X[mid][ins_m]
    n = np.linalg.norm(d, axis=1)
    print(f"t {tm:.1f}→{inside[j][0]:.1f}: their displacement median {np.median(n):.3f}, "
          f"z median {np.median(d[:, 2]):+.3f} (quartiles {np.percentile(d[:, 2], 25):+.3f}/"
          f"{np.percentile(d[:, 2], 75):+.3f})")
# Do they turn instead (a flat Gaussian seen edge-on disappears)? Angle between their
# rotations at the middle time and each end, and how flat they are (smallest/largest scale).
def rots(p):
    g = read_ply(p)
    q = np.stack([g['rot_0'], g['rot_1'], g['rot_2'], g['rot_3']], 1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)
Q = [rots(p) for p in files]
g_mid = read_ply(files[mid])
sc = np.exp(np.stack([g_mid['scale_0'], g_mid['scale_1'], g_mid['scale_2']], 1))[ins_m]
flat = sc.min(1) / sc.max(1)
print(f"flatness (min/max scale) at t={tm:.1f}: median {np.median(flat):.2f}")
for j in (0, len(files) - 1):
    dot = np.abs(np.sum(Q[j][ins_m] * Q[mid][ins_m], 1)).clip(0, 1)
    ang = np.degrees(2 * np.arccos(dot))
    print(f"t {tm:.1f}→{inside[j][0]:.1f}: rotation change median {np.median(ang):.0f}°, "
          f"quartiles {np.percentile(ang, 25):.0f}°/{np.percentile(ang, 75):.0f}°")
