#!/usr/bin/env python3
"""Make the MobileSAM box / multi-point prompt fixture for
crates/semantics/tests/sam_prompts.rs (the prompts the tracker sends: boxes, positive and
negative points, SAM's single output).

Run once, by hand, with the same environment as scripts/make_sam_fixture.py (torch,
torchvision, timm, numpy and mobilesam-mirror==1.0.0, the official MobileSAM code on PyPI):

    /work/venv/bin/python scripts/make_sam_prompt_fixture.py weights/mobile_sam.pt \
        crates/semantics/tests/fixtures/sam/mobilesam_prompts.npz

The image is make_sam_fixture.py's synthetic one. Stored (float32 unless noted), P prompts:
  point_coords  (P, 3, 2)          original-image pixels; rows past n_points unused
  point_labels  int32 (P, 3)       1 positive, 0 negative, -10 unused
  boxes         (P, 4)             XYXY original-image pixels; all -1 when the prompt has none
  iou           (P, 1)             predicted IoU of SAM's single output (multimask_output=False)
  low_res       (P, 1, 96, 128)    its low-res logits, rows 0..192 / cols 0..256, stride 2
  masks         uint8 (P, 1, H, W) its binary mask at the original size (logits > 0)
"""
import sys

import numpy as np
import torch
from mobile_sam import SamPredictor, sam_model_registry

from make_sam_fixture import synthetic_image

# (points [(x, y, label)], box or None)
PROMPTS = [
    ([], [25, 35, 95, 105]),
    ([(160, 60, 1), (60, 70, 0)], [115, 20, 205, 100]),
    ([(150, 130, 1), (180, 140, 1), (60, 70, 0)], None),
    ([(160, 60, 0)], [120, 110, 200, 160]),
]


def main():
    ckpt, out = sys.argv[1], sys.argv[2]
    torch.manual_seed(0)
    sam = sam_model_registry["vit_t"](checkpoint=ckpt).eval()
    pred = SamPredictor(sam)
    img = synthetic_image()
    coords = np.full((len(PROMPTS), 3, 2), -1, dtype=np.float32)
    labels = np.full((len(PROMPTS), 3), -10, dtype=np.int32)
    boxes = np.full((len(PROMPTS), 4), -1, dtype=np.float32)
    ious, lows, masks = [], [], []
    with torch.no_grad():
        pred.set_image(img)
        for i, (points, box) in enumerate(PROMPTS):
            kw = {}
            if points:
                pc = np.array([[x, y] for x, y, _ in points], dtype=np.float32)
                pl = np.array([l for _, _, l in points])
                coords[i, : len(points)] = pc
                labels[i, : len(points)] = pl
                kw.update(point_coords=pc, point_labels=pl)
            if box is not None:
                boxes[i] = box
                kw.update(box=np.array(box, dtype=np.float32))
            m, iou, low = pred.predict(multimask_output=False, return_logits=True, **kw)
            ious.append(iou)
            lows.append(low[:, 0:192:2, 0:256:2])
            masks.append((m > 0).astype(np.uint8))
    np.savez_compressed(
        out,
        point_coords=coords,
        point_labels=labels,
        boxes=boxes,
        iou=np.stack(ious).astype(np.float32),
        low_res=np.stack(lows).astype(np.float32),
        masks=np.stack(masks),
    )
    print("wrote", out, "iou", np.stack(ious).ravel(), "areas", np.stack(masks).sum(axis=(1, 2, 3)))


if __name__ == "__main__":
    main()
