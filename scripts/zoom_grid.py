#!/usr/bin/env python3
# Builds the docs' figures from a compare/demo output's images/ folder: one row per method
# (ground truth, baseline, SemDynReg, rigid objects), one column per t = 0…5 s.
# Usage: scripts/zoom_grid.py OUT_DIR/images docs/img/NAME.png [zoom_|'']   (needs pillow)
import sys
from PIL import Image, ImageDraw
d, out = sys.argv[1], sys.argv[2]
kind = sys.argv[3] if len(sys.argv) > 3 else "zoom_"
rows = [("ground truth", "gt"), ("baseline", "baseline"), ("SemDynReg (paper)", "semdynreg"), ("rigid objects", "rigid")]
cols = [f"t{i}s" for i in range(6)]
ims = [[Image.open(f"{d}/{c}_{kind}{r}.png").convert("RGB") for c in cols] for _, r in rows]
w, h = ims[0][0].size
lw, th = 130, 18
g = Image.new("RGB", (lw + w * len(cols), th + h * len(rows)), "white")
dr = ImageDraw.Draw(g)
for j, c in enumerate(cols):
    dr.text((lw + j * w + w // 2 - 8, 3), f"t = {c[1]} s", fill="black")
for i, (name, _) in enumerate(rows):
    dr.text((4, th + i * h + h // 2 - 5), name, fill="black")
    for j in range(len(cols)):
        g.paste(ims[i][j], (lw + j * w, th + i * h))
g.save(out)
print(out, g.size)
