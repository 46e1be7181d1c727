#!/usr/bin/env python3
"""Generate the SSIM/PSNR fixtures in crates/metrics/tests/fixtures/ (run once; outputs are
committed): three 8-bit RGB image pairs and `ssim_expected.json` with values computed
independently of our Rust code:

  ssim_skimage: skimage.metrics.structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
                use_sample_covariance=False, data_range=1, channel_axis=-1)
  ssim_3dgs:    a float64 numpy transcription of 3DGS utils/loss_utils.py::ssim (11x11
                Gaussian window sigma 1.5, zero padding, mean over pixels and channels)
  psnr:         10*log10(1/mse) in float64

Needs: pip install numpy scikit-image (Pillow comes with it).
Usage: python3 scripts/make_ssim_fixtures.py crates/metrics/tests/fixtures
"""
import json
import os
import sys

import numpy as np
from PIL import Image
from skimage.metrics import structural_similarity


def gauss_window(size=11, sigma=1.5):
    x = np.arange(size) - size // 2
    g = np.exp(-(x ** 2) / (2 * sigma ** 2))
    g /= g.sum()
    return np.outer(g, g)


def filt(img, win):
    """'same' 2D correlation with zero padding, per channel (img: H, W, C)."""
    r = win.shape[0] // 2
    h, w = img.shape[:2]
    pad = np.pad(img, ((r, r), (r, r), (0, 0)))
    out = np.zeros_like(img)
    for i in range(win.shape[0]):
        for j in range(win.shape[1]):
            out += win[i, j] * pad[i:i + h, j:j + w]
    return out


def ssim_3dgs(a, b):
    win = gauss_window()
    mu1, mu2 = filt(a, win), filt(b, win)
    s11 = filt(a * a, win) - mu1 ** 2
    s22 = filt(b * b, win) - mu2 ** 2
    s12 = filt(a * b, win) - mu1 * mu2
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    m = ((2 * mu1 * mu2 + c1) * (2 * s12 + c2)) / ((mu1 ** 2 + mu2 ** 2 + c1) * (s11 + s22 + c2))
    return float(m.mean())


def make_pairs(rng):
    h, w = 40, 48
    yy, xx = np.mgrid[0:h, 0:w] / np.array([h, w]).reshape(2, 1, 1)
    smooth = np.stack([xx, yy, 0.5 + 0.5 * np.sin(6 * xx * yy)], -1)
    noisy = np.clip(smooth + rng.normal(0, 0.05, smooth.shape), 0, 1)
    shifted = np.roll(smooth, 2, axis=1)
    rand_a = rng.uniform(0, 1, (h, w, 3))
    rand_b = np.clip(rand_a * 0.7 + 0.3 * rng.uniform(0, 1, (h, w, 3)), 0, 1)
    tall = rng.uniform(0, 1, (33, 12, 3))
    tall_b = np.clip(tall + rng.normal(0, 0.1, tall.shape), 0, 1)
    return {"noise": (smooth, noisy), "shift": (smooth, shifted),
            "random": (rand_a, rand_b), "tall": (tall, tall_b)}


def to_u8(x):
    return np.round(x * 255).astype(np.uint8)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "crates/metrics/tests/fixtures"
    os.makedirs(out, exist_ok=True)
    rng = np.random.default_rng(20241122)
    expected = {}
    for name, (a, b) in make_pairs(rng).items():
        a8, b8 = to_u8(a), to_u8(b)
        Image.fromarray(a8).save(os.path.join(out, f"{name}_a.png"))
        Image.fromarray(b8).save(os.path.join(out, f"{name}_b.png"))
        af, bf = a8 / 255.0, b8 / 255.0  # exactly what the PNGs decode to
        expected[name] = {
            "width": int(a8.shape[1]), "height": int(a8.shape[0]),
            "ssim_3dgs": ssim_3dgs(af, bf),
            "ssim_skimage": float(structural_similarity(
                af, bf, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                data_range=1, channel_axis=-1)),
            "psnr": float(10 * np.log10(1 / np.mean((af - bf) ** 2))),
        }
    with open(os.path.join(out, "ssim_expected.json"), "w") as f:
        json.dump(expected, f, indent=2)
    print(json.dumps(expected, indent=2))


if __name__ == "__main__":
    main()
