#!/usr/bin/env python3
"""Our rasterizer against a PyTorch CPU rasterizer built on gsplat, on the same scene, in one run.

A measurement script, not a dependency: it needs torch and gsplat==1.5.3
(`BUILD_NO_CUDA=1 pip install torch gsplat==1.5.3`, ~4 GB with torch's CUDA wheels) and a
release build of the probe (`cargo build --release -p splat --example raster_probe`).

gsplat 1.5.3 has no complete CPU path: its PyTorch reference (`gsplat.cuda._torch_impl`)
projects (`_fully_fused_projection`), colours (`_spherical_harmonics`) and bins
(`_isect_tiles`, `_isect_offset_encode`) in plain PyTorch, but its `_rasterize_to_pixels`
calls the CUDA kernel `rasterize_to_indices_in_range` and nerfacc's CUDA scans. This script
uses gsplat's PyTorch functions for everything but the compositing, and composites each
16×16 tile densely in PyTorch with the same rules (alpha = min(0.999, o·e^{-σ}), skip
σ < 0 or alpha < 1/255, stop before T·(1 − alpha) ≤ 1e-4, background·T_final); autograd
gives the backward. `--check` renders reference case 03 with it in float64 and compares
with the case's expected image and gradients.

It writes a random scene in the reference cases' input format (FORMAT.md in
crates/splat/tests/fixtures/reference), then alternates rounds: forward + backward of
L = sum(image * weights) in PyTorch (float32), then the same through `raster_probe npz`.
It prints each side's median and the ratio.

    python3 scripts/bench_gsplat_cpu.py [--gaussians 3000] [--width 192] [--height 144]
        [--rounds 3] [--reps 5] [--probe target/release/examples/raster_probe] [--check]
"""
import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np


def make_scene(n, width, height, seed):
    """Gaussians in front of a camera at the origin looking down +z, SH degree 3."""
    rng = np.random.default_rng(seed)
    fx = fy = 0.9 * width
    z = rng.uniform(2.0, 6.0, n)
    means = np.stack(
        [
            rng.uniform(-0.6, 0.6, n) * z * width / fx,
            rng.uniform(-0.6, 0.6, n) * z * height / fy,
            z,
        ],
        axis=1,
    )
    return {
        "means": means,
        "quats": rng.normal(size=(n, 4)),
        "log_scales": rng.uniform(math.log(0.01), math.log(0.08), (n, 3)),
        "opacity_logits": rng.uniform(-2.0, 3.0, n),
        "sh": rng.normal(scale=0.3, size=(n, 16, 3)),
        "sh_degree": np.array(3.0),
        "viewmat": np.eye(4),
        "fx": np.array(fx),
        "fy": np.array(fy),
        "cx": np.array(width / 2),
        "cy": np.array(height / 2),
        "width": np.array(float(width)),
        "height": np.array(float(height)),
        "background": np.array([0.1, 0.2, 0.3]),
        "weights": rng.uniform(-1.0, 1.0, (height, width, 3)),
        "eps2d": np.array(0.3),
        "near_plane": np.array(0.01),
    }


def composite(torch, means2d, conics, colors, opac, w, h, offsets, flatten_ids, bg):
    """Front-to-back compositing of each 16×16 tile, dense over (Gaussians, pixels)."""
    tw, th = offsets.shape[-1], offsets.shape[-2]
    ends = torch.cat([offsets.flatten()[1:], torch.tensor([len(flatten_ids)])])
    rows = []
    for ty in range(th):
        tiles = []
        for tx in range(tw):
            t = ty * tw + tx
            start, end = int(offsets.flatten()[t]), int(ends[t])
            ys = torch.arange(ty * 16, min(ty * 16 + 16, h), dtype=means2d.dtype) + 0.5
            xs = torch.arange(tx * 16, min(tx * 16 + 16, w), dtype=means2d.dtype) + 0.5
            py, px = torch.meshgrid(ys, xs, indexing="ij")
            if end == start:
                tiles.append(bg.expand(len(ys), len(xs), 3))
                continue
            ids = flatten_ids[start:end]
            m, (a, b, c) = means2d[ids], conics[ids].unbind(-1)
            dx = m[:, 0, None, None] - px
            dy = m[:, 1, None, None] - py
            sigma = 0.5 * (a[:, None, None] * dx * dx + c[:, None, None] * dy * dy)
            sigma = sigma + b[:, None, None] * dx * dy
            alpha = torch.clamp_max(opac[ids, None, None] * torch.exp(-sigma), 0.999)
            valid = (sigma >= 0) & (alpha >= 1.0 / 255.0)
            a_eff = torch.where(valid, alpha, torch.zeros_like(alpha))
            t_excl = torch.cumprod(torch.cat([torch.ones_like(a_eff[:1]), 1 - a_eff[:-1]]), 0)
            kept = valid & (t_excl * (1 - a_eff) > 1e-4)
            a_rec = torch.where(kept, a_eff, torch.zeros_like(a_eff))
            t_rec = torch.cumprod(torch.cat([torch.ones_like(a_rec[:1]), 1 - a_rec]), 0)
            wgt = a_rec * t_rec[:-1]
            img = (wgt[..., None] * colors[ids, None, None, :]).sum(0)
            tiles.append(img + t_rec[-1][..., None] * bg)
        rows.append(torch.cat(tiles, dim=1))
    return torch.cat(rows, dim=0)


def gsplat_step(s, torch, T, dtype=None):
    """One forward + backward through gsplat's PyTorch functions (float32 by default, CPU).
    Returns the image and the gradients by input name."""
    if "alpha_weights" in s:
        raise SystemExit("alpha weights are not supported by this benchmark")
    dtype = dtype or torch.float32
    f = lambda k: torch.tensor(s[k], dtype=dtype)
    params = {k: f(k).requires_grad_() for k in ("means", "quats", "log_scales", "opacity_logits")}
    colour_key = "sh" if "sh" in s else "colors"
    params[colour_key] = f(colour_key).requires_grad_()
    means = params["means"]
    w, h = int(s["width"]), int(s["height"])
    K = torch.tensor(
        [[float(s["fx"]), 0, float(s["cx"])], [0, float(s["fy"]), float(s["cy"])], [0, 0, 1]],
        dtype=dtype,
    )
    viewmat = f("viewmat")
    covars, _ = T._quat_scale_to_covar_preci(
        params["quats"], torch.exp(params["log_scales"]), compute_preci=False
    )
    radii, means2d, depths, conics, _ = T._fully_fused_projection(
        means, covars, viewmat[None], K[None], w, h,
        eps2d=float(s["eps2d"]), near_plane=float(s["near_plane"]),
    )
    if colour_key == "sh":
        campos = torch.linalg.inv(viewmat)[:3, 3]
        degree = int(s["sh_degree"])
        colors = T._spherical_harmonics(degree, means - campos, params["sh"])
        colors = torch.clamp_min(colors + 0.5, 0.0)
    else:
        colors = params["colors"]
    tw, th = math.ceil(w / 16), math.ceil(h / 16)
    _, isect_ids, flatten_ids = T._isect_tiles(means2d, radii, depths, 16, tw, th)
    offsets = T._isect_offset_encode(isect_ids, 1, tw, th)[0]
    image = composite(
        torch, means2d[0], conics[0], colors, torch.sigmoid(params["opacity_logits"]),
        w, h, offsets, flatten_ids, f("background"),
    )
    loss = (image * f("weights")).sum()
    loss.backward()
    return image.detach(), {k: v.grad for k, v in params.items()}


def check(torch, T):
    """Case 03 in float64 against its expected image and gradients."""
    base = os.path.join(os.path.dirname(__file__), "..", "crates", "splat", "tests",
                        "fixtures", "reference", "cases", "03_medium_sh3")
    s = dict(np.load(base + ".npz"))
    want = np.load(base + ".expected.npz")
    image, grads = gsplat_step(s, torch, T, torch.float64)
    rel = lambda a, b: float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-30))
    print(f"check, case 03: image rel. L2 error {rel(image.numpy(), want['image']):.2e}")
    for k, name in [("means", "grad_means"), ("quats", "grad_quats"),
                    ("log_scales", "grad_log_scales"), ("sh", "grad_sh"),
                    ("opacity_logits", "grad_opacity_logits")]:
        print(f"  {name}: rel. L2 error {rel(grads[k].numpy(), want[name]):.2e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gaussians", type=int, default=3000)
    ap.add_argument("--width", type=int, default=192)
    ap.add_argument("--height", type=int, default=144)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--probe", default="target/release/examples/raster_probe")
    ap.add_argument("--check", action="store_true", help="only compare with reference case 03")
    a = ap.parse_args()
    if not os.path.exists(a.probe):
        sys.exit(f"{a.probe} not found: cargo build --release -p splat --example raster_probe")
    try:
        import torch
        from gsplat.cuda import _torch_impl as T
    except ImportError as e:
        sys.exit(f"{e}: BUILD_NO_CUDA=1 pip install torch gsplat==1.5.3")
    if a.check:
        return check(torch, T)
    s = make_scene(a.gaussians, a.width, a.height, a.seed)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "scene.npz")
        np.savez_compressed(path, **s)
        ours, theirs = [], []
        gsplat_step(s, torch, T)  # warm-up
        for _ in range(a.rounds):
            for _ in range(a.reps):
                t = time.perf_counter()
                gsplat_step(s, torch, T)
                theirs.append(time.perf_counter() - t)
            out = subprocess.run(
                [a.probe, "npz", path, str(4 * a.reps)],
                check=True,
                capture_output=True,
                text=True,
            ).stdout
            ours.append(float(out.split("forward+backward ")[1].split(" s")[0]))
    g, o = statistics.median(theirs), statistics.median(ours)
    print(
        f"{a.gaussians} Gaussians, SH 3, {a.width}x{a.height}, torch {torch.__version__} "
        f"on {torch.get_num_threads()} threads, {a.rounds} alternated rounds\n"
        f"PyTorch CPU (gsplat functions) forward+backward: {g * 1e3:.1f} ms (median of {len(theirs)})\n"
        f"semdynreg splat forward+backward:                {o * 1e3:.3f} ms (median of the rounds' medians)\n"
        f"ratio: {g / o:.0f}x"
    )


if __name__ == "__main__":
    main()
