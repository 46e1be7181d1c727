#!/usr/bin/env python3
"""Make the MobileSAM reference fixture for crates/semantics/tests/sam_reference.rs.

Run once, by hand (needs torch, torchvision, timm, numpy and mobilesam-mirror==1.0.0, the
official MobileSAM code published on PyPI; the project itself never needs Python):

    /work/venv/bin/python scripts/make_sam_fixture.py weights/mobile_sam.pt \
        crates/semantics/tests/fixtures/sam/mobilesam_ref.npz

The input image is synthetic and defined by integer arithmetic (`synthetic_image`), which the
Rust test reproduces bit for bit, so no image file is stored. Stored (float32 unless noted):
  resized_rows   uint8 (96, 1024, 3)  every 8th row of ResizeLongestSide.apply_image(img)
  embedding_ch   (64, 64, 64)         channels 0, 4, ..., 252 of the image embedding
  points         (P, 2)               prompt points, original-image pixels (label 1)
  iou            (P, 3)               predicted IoU of the three multimask outputs
  low_res        (P, 3, 96, 128)      low-res logits, rows 0..192 / cols 0..256, stride 2
  masks          uint8 (P, 3, H, W)   binary masks at the original size (logits > 0)
"""
import sys

import numpy as np
import torch
from mobile_sam import SamPredictor, sam_model_registry

H, W = 180, 240


def synthetic_image():
    """Gradient background with a white box, a yellow ellipse and a green box (integer math)."""
    img = np.zeros((H, W, 3), dtype=np.uint8)
    for y in range(H):
        for x in range(W):
            r = (x * 255 // (W - 1)) // 3 + 40
            g = (y * 255 // (H - 1)) // 3 + 60
            b = 90 + (x + y) % 32
            if 30 <= x < 90 and 40 <= y < 100:
                r, g, b = 230, 230, 235
            elif (x - 160) ** 2 * 22**2 + (y - 60) ** 2 * 35**2 <= 35**2 * 22**2:
                r, g, b = 220, 200, 30
            elif 120 <= x < 200 and 110 <= y < 160:
                r, g, b = 40, 160, 60
            img[y, x] = (r, g, b)
    return img


def main():
    ckpt, out = sys.argv[1], sys.argv[2]
    torch.manual_seed(0)
    sam = sam_model_registry["vit_t"](checkpoint=ckpt).eval()
    pred = SamPredictor(sam)
    img = synthetic_image()
    resized = pred.transform.apply_image(img)
    assert resized.shape == (768, 1024, 3), resized.shape
    with torch.no_grad():
        pred.set_image(img)
        emb = pred.get_image_embedding()[0].numpy()
        points = np.array([[60, 70], [160, 60], [160, 135], [10, 170]], dtype=np.float32)
        ious, lows, masks = [], [], []
        for p in points:
            m, iou, low = pred.predict(
                point_coords=p[None], point_labels=np.array([1]), multimask_output=True, return_logits=True
            )
            ious.append(iou)
            lows.append(low[:, 0:192:2, 0:256:2])
            masks.append((m > 0).astype(np.uint8))
    np.savez_compressed(
        out,
        resized_rows=resized[::8].copy(),
        embedding_ch=emb[::4].astype(np.float32),
        points=points,
        iou=np.stack(ious).astype(np.float32),
        low_res=np.stack(lows).astype(np.float32),
        masks=np.stack(masks),
    )
    print("wrote", out, "iou", np.stack(ious))


if __name__ == "__main__":
    main()
