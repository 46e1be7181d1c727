#!/usr/bin/env python3
"""Reference Deformable-3DGS training loop in PyTorch on the CPU, for D-NeRF scenes.

A measurement tool, not part of the project: it re-implements the training loop of the
official Deformable-3DGS code (ingra14m/Deformable-3D-Gaussians, `train.py --eval
--is_blender`) with the CUDA rasterizer replaced by gsplat's pure-PyTorch projection and
spherical harmonics plus a PyTorch compositor with the official rasterizer's rules, so
that our Rust trainer can be compared with it on the same data, size and schedule.
docs/fidelity-reference.md lists what it reproduces, where, and what it does not.

Needs torch, gsplat==1.5.3 (its `gsplat.cuda._torch_impl` runs on a CPU), numpy, pillow
and scipy (`BUILD_NO_CUDA=1 pip install torch gsplat==1.5.3 pillow scipy`).

    python3 scripts/deformable3dgs_reference.py /work/shared/data/dnerf-lego \\
        --downscale 8 --iters 3000 --seed 0 --out runs/ref/result.json
    python3 scripts/deformable3dgs_reference.py --self-check   # compositor vs a per-pixel loop

`--iters N` rescales the official 40k schedule exactly as `semdynreg train --iters N`
does (TrainConfig::rescaled: milestones proportional, densification interval floored at
100, opacity-reset interval and the start of the size prune floored at 1,000).
"""
import argparse
import json
import math
import os
import random
import sys
import time

import numpy as np

C0 = 0.28209479177387814


def round_half_up(x):
    """Rust's f64::round for non-negative values (Python's round() is banker's)."""
    return int(math.floor(x + 0.5))


# ---------------------------------------------------------------------------------------
# Schedule: the official constants (arguments/__init__.py at 727de10a, train.py) and the
# rescaling of our `--iters`.
# ---------------------------------------------------------------------------------------
OFFICIAL = dict(
    iterations=40_000,
    warm_up=3_000,
    position_lr_init=0.00016,
    position_lr_final=0.0000016,
    position_lr_max_steps=30_000,
    deform_lr_max_steps=40_000,
    feature_lr=0.0025,
    opacity_lr=0.05,
    scaling_lr=0.001,
    rotation_lr=0.001,
    percent_dense=0.01,
    lambda_dssim=0.2,
    densification_interval=100,
    opacity_reset_interval=3000,
    densify_from_iter=500,
    densify_until_iter=15_000,
    densify_grad_threshold=0.0002,
    sh_interval=1000,
    smooth_term_steps=20_000,
    spatial_lr_scale=5.0,
)


def rescaled_schedule(iters, base=OFFICIAL):
    """The schedule for `iters` iterations, as crates/train/src/config.rs `rescaled`."""
    s = dict(base)
    f = iters / base["iterations"]
    at = lambda v: round_half_up(v * f)
    every = lambda v: 0 if v == 0 else max(at(v), 1)
    window = lambda v, floor: 0 if v == 0 else max(every(v), min(v, floor))
    s["iterations"] = iters
    s["warm_up"] = at(base["warm_up"])
    s["position_lr_max_steps"] = every(base["position_lr_max_steps"])
    s["deform_lr_max_steps"] = every(base["deform_lr_max_steps"])
    s["densify_from_iter"] = at(base["densify_from_iter"])
    s["densify_until_iter"] = at(base["densify_until_iter"])
    s["densification_interval"] = window(base["densification_interval"], 100)
    s["opacity_reset_interval"] = window(base["opacity_reset_interval"], 1000)
    # The official size prune starts at `iteration > opacity_reset_interval`: it follows
    # the (floored) reset interval, as ours does.
    s["sh_interval"] = every(base["sh_interval"])
    s["smooth_term_steps"] = every(base["smooth_term_steps"])
    return s


def expon_lr(lr_init, lr_final, max_steps, step):
    """utils/general_utils.py get_expon_lr_func with lr_delay_steps = 0."""
    if step < 0:
        return 0.0
    t = min(max(step / max_steps, 0.0), 1.0)
    return math.exp(math.log(lr_init) * (1 - t) + math.log(lr_final) * t)


def linear_noise(lr_init, lr_final, max_steps, step):
    """utils/general_utils.py get_linear_noise_func (the time-noise `smooth_term`)."""
    t = min(max(step / max_steps, 0.0), 1.0)
    return lr_init * (1 - t) + lr_final * t


# ---------------------------------------------------------------------------------------
# Data: D-NeRF blender format, composited and box-downscaled exactly as our loader does
# (crates/scene/src/image.rs: c·a + bg·(1 − a) rounded to u8, then the f×f mean rounded).
# ---------------------------------------------------------------------------------------
def load_split(torch, root, split, downscale, bg):
    from PIL import Image

    with open(os.path.join(root, f"transforms_{split}.json")) as fh:
        meta = json.load(fh)
    fov_x = meta["camera_angle_x"]
    frames = []
    for fr in meta["frames"]:
        path = os.path.join(root, fr["file_path"].lstrip("./") + ".png")
        if not os.path.exists(path):
            path = os.path.join(root, fr["file_path"] + ".png")
        rgba = np.asarray(Image.open(path).convert("RGBA"), dtype=np.float32) / 255.0
        a = rgba[..., 3:4]
        rgb = np.floor((rgba[..., :3] * a + np.float32(bg) * (1 - a)) * 255.0 + 0.5)
        rgb = np.clip(rgb, 0, 255)
        f = downscale
        h, w = rgb.shape[0] // f, rgb.shape[1] // f
        if f > 1:
            rgb = rgb[: h * f, : w * f].reshape(h, f, w, f, 3).sum(axis=(1, 3))
            rgb = np.floor(rgb / (f * f) + 0.5)
        img = torch.tensor(rgb / 255.0, dtype=torch.float32)
        c2w = np.array(fr["transform_matrix"], dtype=np.float64)
        c2w[:3, 1:3] *= -1  # OpenGL → OpenCV axes
        w2c = np.linalg.inv(c2w)
        focal = w / (2.0 * math.tan(0.5 * fov_x))
        K = np.array([[focal, 0, w / 2.0], [0, focal, h / 2.0], [0, 0, 1]])
        frames.append(
            dict(
                name=os.path.basename(fr["file_path"]),
                time=float(fr.get("time", 0.0)),
                image=img,
                viewmat=torch.tensor(w2c, dtype=torch.float32),
                K=torch.tensor(K, dtype=torch.float32),
                campos=torch.tensor(c2w[:3, 3], dtype=torch.float32),
                width=w,
                height=h,
            )
        )
    return frames


def camera_extent(frames):
    """scene/dataset_readers.py getNerfppNorm: 1.1 × max distance to the mean centre."""
    c = np.stack([fr["campos"].numpy() for fr in frames]).astype(np.float64)
    return float(1.1 * np.linalg.norm(c - c.mean(0), axis=1).max())


# ---------------------------------------------------------------------------------------
# Deformation network (utils/time_utils.py DeformNetwork).
# ---------------------------------------------------------------------------------------
def make_field(torch, depth, width, is_blender, xyz_freqs=10):
    nn = torch.nn
    F = torch.nn.functional

    def embed(x, n):
        out = [x]
        for k in range(n):
            f = 2.0**k
            out += [torch.sin(x * f), torch.cos(x * f)]
        return torch.cat(out, -1)

    class Field(nn.Module):
        def __init__(self):
            super().__init__()
            self.t_freqs = 6 if is_blender else 10
            self.xyz_freqs = xyz_freqs
            xyz_ch = 3 * (1 + 2 * xyz_freqs)
            t_ch = 1 + 2 * self.t_freqs
            self.is_blender = is_blender
            if is_blender:
                # γ(t) → 256 → ReLU → 30, as the official "better for D-NeRF" branch.
                self.timenet = nn.Sequential(nn.Linear(t_ch, 256), nn.ReLU(), nn.Linear(256, 30))
                t_ch = 30
            in_ch = xyz_ch + t_ch
            self.skip = depth // 2
            self.linear = nn.ModuleList(
                [nn.Linear(in_ch, width)]
                + [
                    nn.Linear(width + in_ch if i == self.skip else width, width)
                    for i in range(depth - 1)
                ]
            )
            self.warp = nn.Linear(width, 3)
            self.rotation = nn.Linear(width, 4)
            self.scaling = nn.Linear(width, 3)

        def forward(self, x, t):
            # The official expands t to one row per Gaussian before the time network; every
            # row is the same, so it runs once here and is expanded after (same values and
            # the same summed gradient).
            t_emb = embed(t.reshape(1, 1), self.t_freqs)
            if self.is_blender:
                t_emb = self.timenet(t_emb)
            t_emb = t_emb.expand(x.shape[0], -1)
            x_emb = embed(x, self.xyz_freqs)
            h = torch.cat([x_emb, t_emb], -1)
            for i, layer in enumerate(self.linear):
                h = F.relu(layer(h))
                if i == self.skip:
                    h = torch.cat([x_emb, t_emb, h], -1)
            return self.warp(h), self.rotation(h), self.scaling(h)

    return Field()


# ---------------------------------------------------------------------------------------
# Gaussians and Adam with the official tensor surgery (scene/gaussian_model.py).
# ---------------------------------------------------------------------------------------
GROUPS = ("xyz", "f_dc", "f_rest", "opacity", "scaling", "rotation")


class Gaussians:
    def __init__(self, torch, params, lrs, eps=1e-15):
        self.t = torch
        self.p = {k: v.requires_grad_(True) for k, v in params.items()}
        self.lr = dict(lrs)
        self.eps = eps
        self.m = {k: torch.zeros_like(v) for k, v in self.p.items()}
        self.v = {k: torch.zeros_like(v) for k, v in self.p.items()}
        self.steps = {k: 0 for k in self.p}
        n = len(self.p["xyz"])
        self.accum = torch.zeros(n)
        self.denom = torch.zeros(n)
        self.max_radii = torch.zeros(n)
        self.sh_degree = 0

    def __len__(self):
        return len(self.p["xyz"])

    def step(self, skip=()):
        """torch.optim.Adam (β 0.9/0.999) on each group that has a gradient."""
        t = self.t
        with t.no_grad():
            for k, p in self.p.items():
                if k in skip or p.grad is None:
                    continue
                g = p.grad
                self.steps[k] += 1
                s = self.steps[k]
                self.m[k].mul_(0.9).add_(g, alpha=0.1)
                self.v[k].mul_(0.999).addcmul_(g, g, value=0.001)
                denom = (self.v[k].sqrt() / math.sqrt(1 - 0.999**s)).add_(self.eps)
                p.addcdiv_(self.m[k], denom, value=-self.lr[k] / (1 - 0.9**s))
                p.grad = None

    def zero_grad(self):
        for p in self.p.values():
            p.grad = None

    def _replace(self, new, m, v):
        for k in GROUPS:
            self.p[k] = new[k].detach().requires_grad_(True)
            self.m[k], self.v[k] = m[k], v[k]

    def cat(self, ext):
        """cat_tensors_to_optimizer + densification_postfix: new rows get zero moments;
        the statistics restart at zero for every Gaussian."""
        t = self.t
        new = {k: t.cat([self.p[k].detach(), ext[k]]) for k in GROUPS}
        m = {k: t.cat([self.m[k], t.zeros_like(ext[k])]) for k in GROUPS}
        v = {k: t.cat([self.v[k], t.zeros_like(ext[k])]) for k in GROUPS}
        self._replace(new, m, v)
        n = len(self)
        self.accum, self.denom, self.max_radii = t.zeros(n), t.zeros(n), t.zeros(n)

    def prune(self, mask):
        keep = ~mask
        new = {k: self.p[k].detach()[keep] for k in GROUPS}
        m = {k: self.m[k][keep] for k in GROUPS}
        v = {k: self.v[k][keep] for k in GROUPS}
        self._replace(new, m, v)
        self.accum, self.denom = self.accum[keep], self.denom[keep]
        self.max_radii = self.max_radii[keep]

    def reset_opacity(self):
        """min(σ(o), 0.01) with fresh moments (replace_tensor_to_optimizer)."""
        t = self.t
        with t.no_grad():
            o = t.clamp_max(t.sigmoid(self.p["opacity"]), 0.01)
            self.p["opacity"] = t.logit(o).detach().requires_grad_(True)
        self.m["opacity"] = t.zeros_like(o)
        self.v["opacity"] = t.zeros_like(o)


def build_rotation(torch, q):
    """3DGS build_rotation: normalizes, then the rotation matrix (w, x, y, z)."""
    q = q / q.norm(dim=-1, keepdim=True)
    return quat_matrix(torch, q)


def quat_matrix(torch, q):
    """The rotation formula of the official rasterizer's computeCov3D, applied to q as
    given (its `q = rot; // / glm::length(rot)`: no normalization)."""
    r, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - r * z), 2 * (x * z + r * y),
            2 * (x * y + r * z), 1 - 2 * (x * x + z * z), 2 * (y * z - r * x),
            2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y),
        ],
        -1,
    ).reshape(q.shape[:-1] + (3, 3))


def densify_and_prune(torch, G, grad_thr, min_opacity, extent, max_screen_size, pd):
    t = torch
    with t.no_grad():
        grads = G.accum / G.denom
        grads[grads.isnan()] = 0.0
        # clone
        scales = t.exp(G.p["scaling"])
        sel = (grads >= grad_thr) & (scales.max(1).values <= pd * extent)
        G.cat({k: G.p[k].detach()[sel] for k in GROUPS})
        # split (N = 2); the grads of the clones are padded with 0
        n = len(G)
        padded = t.zeros(n)
        padded[: len(grads)] = grads
        scales = t.exp(G.p["scaling"])
        sel = (padded >= grad_thr) & (scales.max(1).values > pd * extent)
        N = 2
        stds = scales[sel].repeat(N, 1)
        samples = t.normal(t.zeros_like(stds), stds)
        rots = build_rotation(t, G.p["rotation"][sel]).repeat(N, 1, 1)
        new = {
            "xyz": t.bmm(rots, samples[..., None])[..., 0] + G.p["xyz"][sel].repeat(N, 1),
            "scaling": t.log(scales[sel].repeat(N, 1) / (0.8 * N)),
            "rotation": G.p["rotation"][sel].repeat(N, 1),
            "f_dc": G.p["f_dc"][sel].repeat(N, 1, 1),
            "f_rest": G.p["f_rest"][sel].repeat(N, 1, 1),
            "opacity": G.p["opacity"][sel].repeat(N, 1),
        }
        new = {k: v.detach() for k, v in new.items()}
        n_split = int(sel.sum())
        G.cat(new)
        G.prune(t.cat([sel, t.zeros(N * n_split, dtype=t.bool)]))
        # prune
        mask = t.sigmoid(G.p["opacity"])[:, 0] < min_opacity
        if max_screen_size:
            # max_radii was zeroed by the postfix above: the view-space test never fires,
            # exactly as in the official code.
            big_vs = G.max_radii > max_screen_size
            big_ws = t.exp(G.p["scaling"]).max(1).values > 0.1 * extent
            mask = mask | big_vs | big_ws
        G.prune(mask)


# ---------------------------------------------------------------------------------------
# Rendering: gsplat's PyTorch world→camera, perspective Jacobian and SH; the rest follows
# the official rasterizer (diff-gaussian-rasterization: cov2D + 0.3 I, radius
# ceil(3·√λmax), near cull z ≤ 0.2, α = min(0.99, o·e^{−σ}), skip α < 1/255, stop once
# T·(1 − α) < 1e-4, background · T_final).
# ---------------------------------------------------------------------------------------
def render(torch, T, G, cam, deform, bg, want_grad2d=False):
    t = torch
    W, H = cam["width"], cam["height"]
    xyz = G.p["xyz"]
    if deform is None:
        dx, dr, ds = 0.0, 0.0, 0.0
    else:
        dx, dr, ds = deform
    means = xyz + dx
    scales = t.exp(G.p["scaling"]) + ds
    rots = t.nn.functional.normalize(G.p["rotation"], dim=-1) + dr
    R = quat_matrix(t, rots)
    M = R * scales[:, None, :]  # R · diag(s)
    covars = M @ M.transpose(1, 2)
    means_c, covars_c = T._world_to_cam(means, covars, cam["viewmat"][None])
    means2d, cov2d = T._persp_proj(means_c, covars_c, cam["K"][None], W, H)
    means2d, cov2d, depth = means2d[0], cov2d[0], means_c[0, :, 2]
    if want_grad2d:
        means2d.retain_grad()
    a = cov2d[:, 0, 0] + 0.3
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + 0.3
    det = a * c - b * b
    with t.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + t.sqrt(t.clamp_min(mid * mid - det, 0.1))
        radius = t.ceil(3.0 * t.sqrt(lam))
        # getRect on 16×16 tiles, in the official rasterizer's pixel frame (centre − 0.5)
        p = means2d.detach() - 0.5
        gx, gy = (W + 15) // 16, (H + 15) // 16
        x0 = t.clamp(t.trunc((p[:, 0] - radius) / 16), 0, gx)
        x1 = t.clamp(t.trunc((p[:, 0] + radius + 15) / 16), 0, gx)
        y0 = t.clamp(t.trunc((p[:, 1] - radius) / 16), 0, gy)
        y1 = t.clamp(t.trunc((p[:, 1] + radius + 15) / 16), 0, gy)
        visible = (depth > 0.2) & (det > 0) & ((x1 - x0) * (y1 - y0) > 0)
        radii = t.where(visible, radius, t.zeros_like(radius))
    inv_det = 1.0 / t.where(visible, det, t.ones_like(det))
    conic = t.stack([c * inv_det, -b * inv_det, a * inv_det], -1)
    sh = t.cat([G.p["f_dc"], G.p["f_rest"]], 1)
    colors = T._spherical_harmonics(G.sh_degree, means - cam["campos"], sh)
    colors = t.clamp_min(colors + 0.5, 0.0)
    opac = t.sigmoid(G.p["opacity"])[:, 0]

    # Compositing per pixel, on a sparse list of (Gaussian, pixel) pairs. A pair exists
    # where the official rasterizer would evaluate it (the pixel lies in a 16×16 tile
    # that the Gaussian's 3σ rect touches) and where α ≥ 1/255 can hold (inside the box
    # of the ellipse σ ≤ ln(255·o)); pairs with α < 1/255 or σ < 0 are dropped, the rest
    # sorted by (pixel, depth), and the front-to-back transmittance is a segmented
    # cumulative sum of log(1 − α) in float64. A first pass without autograd finds the
    # pairs composited before T·(1 − α) < 1e-4 stops the pixel; autograd then runs on
    # those pairs only (the same values and gradients as compositing them all).
    n = len(depth)
    with t.no_grad():
        o = opac.detach()
        s_max = t.log(t.clamp_min(255.0 * o, 1e-30))
        live = visible & (s_max > 0)
        ext_x = t.sqrt(2 * t.clamp_min(s_max, 0) * a.detach())
        ext_y = t.sqrt(2 * t.clamp_min(s_max, 0) * c.detach())
        m = means2d.detach()
        # pixel j covers centre j + 0.5; tile rect [16·x0, 16·x1)
        px0 = t.maximum(t.ceil(m[:, 0] - 0.5 - ext_x), x0 * 16).clamp(0, W)
        px1 = t.minimum(t.floor(m[:, 0] - 0.5 + ext_x) + 1, x1 * 16).clamp(0, W)
        py0 = t.maximum(t.ceil(m[:, 1] - 0.5 - ext_y), y0 * 16).clamp(0, H)
        py1 = t.minimum(t.floor(m[:, 1] - 0.5 + ext_y) + 1, y1 * 16).clamp(0, H)
        nx = (px1 - px0).clamp_min(0).long()
        ny = (py1 - py0).clamp_min(0).long()
        cnt = t.where(live, nx * ny, t.zeros_like(nx))
        gid = t.repeat_interleave(t.arange(n), cnt)
        sel = lambda v, i: v.index_select(0, i)
        first_of = t.cumsum(cnt, 0) - cnt
        local = t.arange(len(gid)) - sel(first_of, gid)
        nxg = sel(nx, gid)
        pyl = t.div(local, nxg, rounding_mode="floor")
        pxi = sel(px0.long(), gid) + (local - pyl * nxg)
        pyi = sel(py0.long(), gid) + pyl
        del local, nxg, first_of, pyl
        cg = sel(conic.detach(), gid)
        dxp = sel(m[:, 0].contiguous(), gid) - (pxi.float() + 0.5)
        dyp = sel(m[:, 1].contiguous(), gid) - (pyi.float() + 0.5)
        sig = 0.5 * (cg[:, 0] * dxp * dxp + cg[:, 2] * dyp * dyp) + cg[:, 1] * dxp * dyp
        alp = t.clamp_max(sel(o, gid) * t.exp(-sig), 0.99)
        ok = ((sig >= 0) & (alp >= 1.0 / 255.0)).nonzero().squeeze(1)
        pix = sel(pyi * W + pxi, ok)
        gid, alp = sel(gid, ok), sel(alp, ok)
        del cg, dxp, dyp, sig, ok, pxi, pyi
        rank = t.empty(n, dtype=t.long)
        rank[t.argsort(depth.detach())] = t.arange(n)
        order = t.argsort(pix * n + sel(rank, gid))
        gid, pix, alp = sel(gid, order), sel(pix, order), sel(alp, order)
        first = t.ones(len(pix), dtype=t.bool)
        first[1:] = pix[1:] != pix[:-1]
        ar = t.arange(len(pix))
        seg = t.cummax(t.where(first, ar, t.zeros_like(ar)), 0).values
        L0 = t.log1p(-alp.double())
        C0x = t.cumsum(L0, 0) - L0
        kept = (t.exp(C0x - sel(C0x, seg)) * (1 - alp.double()) >= 1e-4).nonzero().squeeze(1)
        gid, pix = sel(gid, kept), sel(pix, kept)
        first = t.ones(len(pix), dtype=t.bool)
        first[1:] = pix[1:] != pix[:-1]
        ar = t.arange(len(pix))
        seg = t.cummax(t.where(first, ar, t.zeros_like(ar)), 0).values
        pxf = (pix % W).float() + 0.5
        pyf = (pix // W).float() + 0.5
    m2 = means2d.index_select(0, gid)
    cg = conic.index_select(0, gid)
    dxp = m2[:, 0] - pxf
    dyp = m2[:, 1] - pyf
    sigma = 0.5 * (cg[:, 0] * dxp * dxp + cg[:, 2] * dyp * dyp) + cg[:, 1] * dxp * dyp
    alpha = t.clamp_max(opac.index_select(0, gid) * t.exp(-sigma), 0.99)
    L = t.log1p(-alpha.double())
    C_excl = t.cumsum(L, 0) - L
    T_excl = t.exp(C_excl - C_excl.index_select(0, seg))
    wgt = (alpha.double() * T_excl).float()
    rgb = t.zeros(H * W, 3).index_add_(0, pix, wgt[:, None] * colors.index_select(0, gid))
    logT = t.zeros(H * W, dtype=t.float64).index_add_(0, pix, L)
    img = (rgb + t.exp(logT).float()[:, None] * bg).reshape(H, W, 3)
    render.last_pairs = len(pix)
    return img, means2d, radii, visible


# ---------------------------------------------------------------------------------------
# Loss (utils/loss_utils.py) and metrics (utils/image_utils.py).
# ---------------------------------------------------------------------------------------
def ssim(torch, img1, img2, window_size=11):
    F = torch.nn.functional
    g = torch.tensor([math.exp(-((x - window_size // 2) ** 2) / (2 * 1.5**2)) for x in range(window_size)])
    g = (g / g.sum())[:, None]
    win = (g @ g.t())[None, None].expand(3, 1, window_size, window_size).contiguous()
    a = img1.permute(2, 0, 1)[None]
    b = img2.permute(2, 0, 1)[None]
    pad = window_size // 2
    mu1 = F.conv2d(a, win, padding=pad, groups=3)
    mu2 = F.conv2d(b, win, padding=pad, groups=3)
    mu1_sq, mu2_sq, mu12 = mu1 * mu1, mu2 * mu2, mu1 * mu2
    s1 = F.conv2d(a * a, win, padding=pad, groups=3) - mu1_sq
    s2 = F.conv2d(b * b, win, padding=pad, groups=3) - mu2_sq
    s12 = F.conv2d(a * b, win, padding=pad, groups=3) - mu12
    C1, C2 = 0.01**2, 0.03**2
    m = ((2 * mu12 + C1) * (2 * s12 + C2)) / ((mu1_sq + mu2_sq + C1) * (s1 + s2 + C2))
    return m.mean()


def psnr(torch, a, b):
    mse = ((a - b) ** 2).mean()
    return float(20 * torch.log10(1.0 / torch.sqrt(mse)))


# ---------------------------------------------------------------------------------------
# Training (train.py) and evaluation.
# ---------------------------------------------------------------------------------------
def random_init(torch, n, seed):
    """scene/dataset_readers.py for a scene without points3d.ply: U[−1.3, 1.3]³ points,
    colours SH2RGB(U[0,1)/255) written to and read back from a u8 PLY (so 127/255), then
    gaussian_model.py create_from_pcd: 3-NN scale, identity rotation, opacity 0.1."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    xyz = rng.random((n, 3)) * 2.6 - 1.3
    shs = rng.random((n, 3)) / 255.0
    rgb_u8 = np.floor((shs * C0 + 0.5) * 255.0)  # storePly's u1 cast truncates
    dc = (rgb_u8 / 255.0 - 0.5) / C0
    d, _ = cKDTree(xyz.astype(np.float32)).query(xyz.astype(np.float32), k=4)
    dist2 = np.maximum((d[:, 1:] ** 2).mean(1), 1e-7)
    f = lambda a: torch.tensor(a, dtype=torch.float32)
    return {
        "xyz": f(xyz),
        "f_dc": f(dc)[:, None, :],
        "f_rest": torch.zeros(n, 15, 3),
        "opacity": torch.full((n, 1), math.log(0.1 / 0.9)),
        "scaling": f(np.log(np.sqrt(dist2)))[:, None].repeat(1, 3),
        "rotation": torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
    }


def evaluate(torch, T, G, field, frames, bg, active):
    out = []
    with torch.no_grad():
        for fr in frames:
            deform = None
            if active:
                tt = torch.tensor(fr["time"], dtype=torch.float32)
                deform = field(G.p["xyz"], tt)
            img, _, _, _ = render(torch, T, G, fr, deform, bg)
            img = img.clamp(0, 1)
            gt = fr["image"]
            out.append(
                dict(name=fr["name"], time=fr["time"], psnr=psnr(torch, img, gt),
                     ssim=float(ssim(torch, img, gt)))
            )
    mean = lambda k: float(np.mean([o[k] for o in out])) if out else None
    return dict(mean=dict(psnr=mean("psnr"), ssim=mean("ssim")), frames=out)


def self_check(torch, T):
    """The sparse compositor against a per-pixel loop over depth-sorted Gaussians with the
    official rasterizer's rules (16×16 tile membership, α clamp, 1/255 skip, early stop),
    on a random scene: image and the gradients of every parameter."""
    torch.manual_seed(0)
    W, H, n, fx = 36, 20, 300, 30.0
    cam = dict(width=W, height=H, viewmat=torch.eye(4), campos=torch.zeros(3),
               K=torch.tensor([[fx, 0, W / 2], [0, fx, H / 2], [0, 0, 1.0]]))
    z = torch.rand(n) * 3 + 2
    P = {"xyz": torch.stack([(torch.rand(n) - .5) * z * 0.9 * W / fx,
                             (torch.rand(n) - .5) * z * 0.9 * H / fx, z], 1),
         "f_dc": torch.randn(n, 1, 3) * 0.5, "f_rest": torch.randn(n, 15, 3) * 0.1,
         "opacity": torch.randn(n, 1) * 2 + 4, "scaling": torch.log(torch.rand(n, 3) * 0.15 + 0.01),
         "rotation": torch.randn(n, 4)}
    G = Gaussians(torch, P, {k: 1.0 for k in P})
    G.sh_degree = 2
    bg = torch.tensor([0.2, 0.3, 0.4])
    wts = torch.randn(H, W, 3)
    img, _, _, _ = render(torch, T, G, cam, None, bg)
    (img * wts).sum().backward()
    fast = {k: v.grad.clone() for k, v in G.p.items()}
    G.zero_grad()
    sc = torch.exp(G.p["scaling"])
    M = quat_matrix(torch, torch.nn.functional.normalize(G.p["rotation"], dim=-1)) * sc[:, None, :]
    mc, cc = T._world_to_cam(G.p["xyz"], M @ M.transpose(1, 2), cam["viewmat"][None])
    mm, c2 = T._persp_proj(mc, cc, cam["K"][None], W, H)
    mm, c2, d = mm[0], c2[0], mc[0, :, 2]
    a, b, c = c2[:, 0, 0] + 0.3, c2[:, 0, 1], c2[:, 1, 1] + 0.3
    det = a * c - b * b
    con = torch.stack([c / det, -b / det, a / det], -1)
    col = torch.clamp_min(T._spherical_harmonics(2, G.p["xyz"], torch.cat([G.p["f_dc"], G.p["f_rest"]], 1)) + 0.5, 0)
    op = torch.sigmoid(G.p["opacity"])[:, 0]
    with torch.no_grad():
        mid = 0.5 * (a + c)
        r = torch.ceil(3 * torch.sqrt(mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.1))))
        p = mm - 0.5
        gx, gy = (W + 15) // 16, (H + 15) // 16
        x0 = torch.clamp(torch.trunc((p[:, 0] - r) / 16), 0, gx)
        x1 = torch.clamp(torch.trunc((p[:, 0] + r + 15) / 16), 0, gx)
        y0 = torch.clamp(torch.trunc((p[:, 1] - r) / 16), 0, gy)
        y1 = torch.clamp(torch.trunc((p[:, 1] + r + 15) / 16), 0, gy)
        vis = (d > 0.2) & (det > 0) & ((x1 - x0) * (y1 - y0) > 0)
    order = torch.argsort(d.detach()).tolist()
    px_out = []
    stopped = 0
    for yy in range(H):
        for xx in range(W):
            Tt, acc = torch.ones(()), torch.zeros(3)
            for i in order:
                if not (vis[i] and x0[i] <= xx // 16 < x1[i] and y0[i] <= yy // 16 < y1[i]):
                    continue
                dx, dy = mm[i, 0] - (xx + 0.5), mm[i, 1] - (yy + 0.5)
                s = 0.5 * (con[i, 0] * dx * dx + con[i, 2] * dy * dy) + con[i, 1] * dx * dy
                if s < 0:
                    continue
                al = torch.clamp_max(op[i] * torch.exp(-s), 0.99)
                if al < 1 / 255:
                    continue
                if Tt * (1 - al) < 1e-4:
                    stopped += 1
                    break
                acc, Tt = acc + al * Tt * col[i], Tt * (1 - al)
            px_out.append(acc + Tt * bg)
    ref = torch.stack(px_out).reshape(H, W, 3)
    (ref * wts).sum().backward()
    err = float((ref.detach() - img.detach()).abs().max())
    print(f"self-check: {render.last_pairs} pairs, {stopped} pixels stopped early; "
          f"image max |diff| {err:.1e}")
    worst = 0.0
    for k, v in G.p.items():
        e = float((v.grad - fast[k]).norm() / v.grad.norm().clamp_min(1e-12))
        worst = max(worst, e)
        print(f"  d/d{k}: relative error {e:.1e}")
    return 0 if err < 1e-5 and worst < 1e-4 else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("data", nargs="?", help="D-NeRF scene folder (transforms_*.json)")
    ap.add_argument("--self-check", action="store_true",
                    help="only compare the compositor with a per-pixel loop (no data needed)")
    ap.add_argument("--iters", type=int, default=40_000)
    ap.add_argument("--downscale", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--depth", type=int, default=8, help="MLP depth (official 8)")
    ap.add_argument("--width", type=int, default=256, help="MLP width (official 256)")
    ap.add_argument("--out", help="result JSON path")
    ap.add_argument("--white-background", action="store_true")
    ap.add_argument("--no-is-blender", dest="is_blender", action="store_false",
                    help="no time network, t with 10 frequencies, time noise on (real scenes)")
    ap.add_argument("--init-points", type=int, default=100_000)
    ap.add_argument("--grad-threshold", type=float, default=OFFICIAL["densify_grad_threshold"])
    ap.add_argument("--eval-split", default="val")
    ap.add_argument("--log-every", type=int, default=100)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()

    import torch
    from gsplat.cuda import _torch_impl as T

    torch.set_num_threads(a.threads)
    if a.self_check:
        return self_check(torch, T)
    if not a.data or not a.out:
        ap.error("DATA and --out are required")
    torch.manual_seed(a.seed)
    pyrng = random.Random(a.seed)
    S = rescaled_schedule(a.iters)
    bgv = [1.0, 1.0, 1.0] if a.white_background else [0.0, 0.0, 0.0]
    bg = torch.tensor(bgv)
    t0 = time.time()
    train = load_split(torch, a.data, "train", a.downscale, bgv)
    evalf = load_split(torch, a.data, a.eval_split, a.downscale, bgv)
    extent = camera_extent(train)
    print(f"{len(train)} train / {len(evalf)} {a.eval_split} frames at "
          f"{train[0]['width']}x{train[0]['height']}, extent {extent:.3f}, "
          f"loaded in {time.time() - t0:.1f} s", flush=True)
    print("schedule:", json.dumps(S), flush=True)

    sls = S["spatial_lr_scale"]
    lrs = dict(xyz=S["position_lr_init"] * sls, f_dc=S["feature_lr"], f_rest=S["feature_lr"] / 20.0,
               opacity=S["opacity_lr"], scaling=S["scaling_lr"] * sls, rotation=S["rotation_lr"])
    G = Gaussians(torch, random_init(torch, a.init_points, a.seed), lrs)
    field = make_field(torch, a.depth, a.width, a.is_blender)
    deform_lr0 = S["position_lr_init"] * sls  # 8e-4
    opt = torch.optim.Adam(field.parameters(), lr=deform_lr0, eps=1e-15)

    stack = []
    log = []
    t_train = time.time()
    cpu0 = time.process_time()
    ema = 0.0
    for it in range(1, S["iterations"] + 1):
        if it % S["sh_interval"] == 0 and G.sh_degree < 3:
            G.sh_degree += 1
        if not stack:
            stack = list(range(len(train)))
        time_interval = 1.0 / len(stack)  # official: measured before the pop
        cam = train[stack.pop(pyrng.randint(0, len(stack) - 1))]
        active = it >= S["warm_up"]
        deform = None
        if active:
            tt = torch.tensor(cam["time"], dtype=torch.float32)
            if not a.is_blender:
                tt = tt + torch.randn(()) * time_interval * linear_noise(
                    0.1, 1e-15, S["smooth_term_steps"], it)
            deform = field(G.p["xyz"].detach(), tt)
        img, means2d, radii, visible = render(torch, T, G, cam, deform, bg,
                                              want_grad2d=it < S["densify_until_iter"])
        gt = cam["image"]
        l1 = (img - gt).abs().mean()
        loss = (1.0 - S["lambda_dssim"]) * l1 + S["lambda_dssim"] * (1.0 - ssim(torch, img, gt))
        loss.backward()
        with torch.no_grad():
            ema = 0.4 * loss.item() + 0.6 * ema
            G.max_radii[visible] = torch.maximum(G.max_radii[visible], radii[visible])
            refined = reset = False
            if it < S["densify_until_iter"]:
                g2 = means2d.grad
                # the rasterizer's means2D gradient is per NDC unit: × (W/2, H/2)
                gn = torch.sqrt((g2[:, 0] * cam["width"] * 0.5) ** 2 + (g2[:, 1] * cam["height"] * 0.5) ** 2)
                G.accum[visible] += gn[visible]
                G.denom[visible] += 1
                if it > S["densify_from_iter"] and it % S["densification_interval"] == 0:
                    size_thr = 20 if it > S["opacity_reset_interval"] else None
                    densify_and_prune(torch, G, a.grad_threshold, 0.005, extent, size_thr,
                                      S["percent_dense"])
                    refined = True
                if it % S["opacity_reset_interval"] == 0 or (
                        a.white_background and it == S["densify_from_iter"]):
                    G.reset_opacity()
                    reset = True
            if it < S["iterations"]:
                # New tensors (after densification) and the reset opacity have no
                # gradient, so Adam skips them that iteration.
                if not refined:
                    G.step(skip=("opacity",) if reset else ())
                G.zero_grad()
                G.lr["xyz"] = expon_lr(S["position_lr_init"] * sls, S["position_lr_final"] * sls,
                                       S["position_lr_max_steps"], it)
                opt.step()
                opt.zero_grad()
                for group in opt.param_groups:
                    group["lr"] = expon_lr(deform_lr0, S["position_lr_final"],
                                           S["deform_lr_max_steps"], it)
        if it % a.log_every == 0 or it == 1 or it == S["iterations"]:
            p = psnr(torch, img.detach().clamp(0, 1), gt)
            rec = dict(iteration=it, loss=loss.item(), ema_loss=ema, l1=l1.item(), psnr=p,
                       gaussians=len(G), elapsed_s=time.time() - t_train)
            log.append(rec)
            print(json.dumps(rec), flush=True)
    wall = time.time() - t_train
    cpu_train = time.process_time() - cpu0
    active = S["iterations"] >= S["warm_up"]
    field.eval()
    ev = evaluate(torch, T, G, field, evalf, bg, active)
    tr = evaluate(torch, T, G, field, train, bg, active)
    result = dict(
        script="scripts/deformable3dgs_reference.py",
        args=vars(a),
        schedule=S,
        extent=extent,
        background=bgv,
        resolution=[train[0]["width"], train[0]["height"]],
        gaussians=len(G),
        wall_train_s=wall,
        cpu_train_s=cpu_train,
        wall_total_s=time.time() - t0,
        torch=torch.__version__,
        threads=torch.get_num_threads(),
        eval_split=a.eval_split,
        val=ev,
        train=tr,
        gap_db=tr["mean"]["psnr"] - ev["mean"]["psnr"],
        log=log,
    )
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    with open(a.out, "w") as fh:
        json.dump(result, fh, indent=1)
    print(f"{a.eval_split} PSNR {ev['mean']['psnr']:.2f}  train-view PSNR {tr['mean']['psnr']:.2f}  "
          f"gap {result['gap_db']:.2f} dB  {len(G)} Gaussians  {wall / 60:.1f} min", flush=True)


if __name__ == "__main__":
    sys.exit(main())
