#!/usr/bin/env python3
# A figure of one object's crop across methods: rows are test frames, columns the ground
# truth then each run's renders, the crop the object's box in the scene's ground-truth ID
# maps (union over the frames, padded), enlarged.
# Usage: scripts/crop_grid.py SCENE ID OUT.png FRAME[,FRAME…] LABEL=RENDER_DIR…  (pillow)
#   e.g. scripts/crop_grid.py tc_crane 3 docs/img/crane_parts.png r_024,r_072 \
#        baseline=cmp_crane/baseline/renders/test parts=p4b/renders/test
import sys
from PIL import Image, ImageDraw

scene, oid, out, frames = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4].split(",")
runs = [a.rsplit("=", 1) for a in sys.argv[5:]]
zoom, pad = 3, 6


def gt(frame):
    im = Image.open(f"{scene}/test/{frame}.png")
    if im.mode == "RGBA":
        bg = Image.new("RGBA", im.size, (0, 0, 0, 255))
        im = Image.alpha_composite(bg, im)
    return im.convert("RGB")


box = None
for f in frames:
    m = Image.open(f"{scene}/masks/test/{f}.png").convert("L")
    w, h = m.size
    px = m.load()
    xs = [x for y in range(h) for x in range(w) if px[x, y] == oid]
    ys = [y for y in range(h) for x in range(w) if px[x, y] == oid]
    if not xs:
        sys.exit(f"object {oid} is not in {scene}/masks/test/{f}.png")
    b = (min(xs), min(ys), max(xs) + 1, max(ys) + 1)
    box = b if box is None else (min(box[0], b[0]), min(box[1], b[1]), max(box[2], b[2]), max(box[3], b[3]))
box = (max(box[0] - pad, 0), max(box[1] - pad, 0), min(box[2] + pad, w), min(box[3] + pad, h))
cw, ch = (box[2] - box[0]) * zoom, (box[3] - box[1]) * zoom
cols = [("ground truth", gt)] + [(label, lambda f, d=d: Image.open(f"{d}/{f}.png").convert("RGB")) for label, d in runs]
th = 18
g = Image.new("RGB", (cw * len(cols), th + ch * len(frames)), "white")
dr = ImageDraw.Draw(g)
for j, (label, _) in enumerate(cols):
    dr.text((j * cw + 4, 3), label, fill="black")
for i, f in enumerate(frames):
    for j, (_, load) in enumerate(cols):
        crop = load(f).crop(box).resize((cw, ch), Image.NEAREST)
        g.paste(crop, (j * cw, th + i * ch))
g.save(out)
print(out, g.size)
