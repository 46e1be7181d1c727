#!/usr/bin/env python3
# A figure of whole frames across runs: rows are frames of one split, columns the ground
# truth (RGBA composited on black, the official D-NeRF protocol) then each run's renders
# (`semdynreg render RUN --split SPLIT`), enlarged ZOOM×, each labelled with its PSNR
# from RUN/eval/metrics_SPLIT.json when that file has the frame.
# Usage: scripts/split_grid.py SCENE SPLIT OUT.png ZOOM FRAME[,FRAME…] LABEL=RUN…  (pillow)
#   e.g. scripts/split_grid.py lego val docs/img/lego_field_parts.png 3 r_1,r_8 \
#        baseline=base0 field-parts=field8
import json, os, sys
from PIL import Image, ImageDraw

scene, split, out, zoom = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
frames = sys.argv[5].split(",")
runs = [a.split("=", 1) for a in sys.argv[6:]]


def gt(frame, size):
    im = Image.open(f"{scene}/{split}/{frame}.png")
    if im.mode == "RGBA":
        im = Image.alpha_composite(Image.new("RGBA", im.size, (0, 0, 0, 255)), im)
    return im.convert("RGB").resize(size, Image.BOX)


def psnr(run, frame):
    p = f"{run}/eval/metrics_{split}.json"
    if not os.path.exists(p):
        return None
    for f in json.load(open(p))["frames"]:
        if (f.get("name") or f.get("file_path")) == f"{split}/{frame}":
            return f["psnr"]
    return None


first = Image.open(f"{runs[0][1]}/renders/{split}/{frames[0]}.png")
w, h = first.size[0] * zoom, first.size[1] * zoom
th = 18
g = Image.new("RGB", (w * (1 + len(runs)), (th + h) * len(frames)), "white")
dr = ImageDraw.Draw(g)
for i, f in enumerate(frames):
    y = i * (th + h)
    cells = [(f"{f}: ground truth", gt(f, first.size))]
    for label, run in runs:
        p = psnr(run, f)
        text = f"{label}" + (f" ({p:.2f} dB)" if p is not None else "")
        cells.append((text, Image.open(f"{run}/renders/{split}/{f}.png").convert("RGB")))
    for j, (text, im) in enumerate(cells):
        dr.text((j * w + 4, y + 3), text, fill="black")
        g.paste(im.resize((w, h), Image.NEAREST), (j * w, y + th))
g.save(out)
print(out, g.size)
