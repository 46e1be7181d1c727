#!/usr/bin/env python3
"""Make the CLIP fixtures of crates/semantics/tests/clip_*.rs with the official OpenCLIP code.

No pretrained CLIP weights are reachable here, so the architecture is proven on SMALL
random-weight models built by `open_clip.model.CLIP` (the class every OpenCLIP and OpenAI
ViT checkpoint is loaded into), with every parameter perturbed so that LayerNorm gains and
biases are not their trivial init. Run once, by hand (needs torch, open_clip_torch==3.3.0,
numpy, pillow, safetensors), from the repository root:

    /work/venv/bin/python scripts/make_clip_fixture.py

Writes crates/semantics/tests/fixtures/clip/:
  tiny_gelu.safetensors       OpenCLIP layout, nn.GELU (as OpenCLIP ViT-B/16 laion2b)
  tiny_gelu.json              its OpenCLIP model config (embed_dim, vision_cfg, text_cfg)
  tiny_quickgelu_hf.safetensors  QuickGELU model (as OpenAI ViT-B/32), keys renamed to the
                              Hugging Face `CLIPModel` layout; config: tiny_quickgelu_hf.json
  reference.safetensors       inputs and expected outputs (see `save_reference`)
  tokens.json                 prompts and the official tokenizer's ids
  preprocess.safetensors      a masked crop and the official CLIP preprocess of it

The token embedding (49,408 rows) is stored as float16 to keep the fixture small; the
reference outputs are computed with those float16-rounded weights, so loading must convert
the dtype and nothing else.
"""

import json
import os

import numpy as np
import open_clip
import torch
from PIL import Image
from safetensors.torch import save_file

OUT = "crates/semantics/tests/fixtures/clip"
PROMPTS = [
    "white SUV",
    "yellow sedan",
    "green SUV",
    "object",
    "things",
    "stuff",
    "texture",
    "a photo of a dog's toy car",
    "Don't  STOP\tbelieving!!!",
    "the year 2024: 3.14 km/h, 100% electric",
    "caf\u00e9 na\u00efve fa\u00e7ade",
    "driver\u2019s seat &amp; &#39;wheel&#39;",
    "hello, world... <end_of_text> later",
    "unbelievably photorealistic hyperparameterization",
    "\u8eca \u00fcber stra\u00dfe",
    "x " * 100,
]

TEXT_CFG = dict(context_length=77, vocab_size=49408, width=8, heads=2, layers=2)


def tiny_config(patch_size, quick_gelu):
    return dict(
        embed_dim=16,
        quick_gelu=quick_gelu,
        vision_cfg=dict(image_size=32, layers=2, width=32, head_width=16, patch_size=patch_size),
        text_cfg=TEXT_CFG,
    )


def build(cfg, seed):
    torch.manual_seed(seed)
    model = open_clip.model.CLIP(
        embed_dim=cfg["embed_dim"],
        vision_cfg=cfg["vision_cfg"],
        text_cfg=cfg["text_cfg"],
        quick_gelu=cfg["quick_gelu"],
    ).eval()
    with torch.no_grad():
        for name, p in model.named_parameters():
            p.add_(0.2 * torch.randn_like(p))
        # Round the token embedding to float16 now, so the reference uses the stored values.
        model.token_embedding.weight.copy_(model.token_embedding.weight.half().float())
    return model


def open_clip_state(model):
    state = {k: v.detach().clone().contiguous() for k, v in model.state_dict().items()}
    state["token_embedding.weight"] = state["token_embedding.weight"].half()
    return state


def hf_state(model):
    """Rename an OpenCLIP state dict into Hugging Face `CLIPModel` keys (what
    `transformers`' convert_clip_original_pytorch_to_hf.py produces)."""
    s = open_clip_state(model)
    out = {}

    def blocks(src, dst, n):
        for i in range(n):
            a, b = f"{src}.resblocks.{i}", f"{dst}.encoder.layers.{i}"
            q, k, v = s[f"{a}.attn.in_proj_weight"].chunk(3)
            qb, kb, vb = s[f"{a}.attn.in_proj_bias"].chunk(3)
            for nm, w, bias in (("q", q, qb), ("k", k, kb), ("v", v, vb)):
                out[f"{b}.self_attn.{nm}_proj.weight"] = w.contiguous()
                out[f"{b}.self_attn.{nm}_proj.bias"] = bias.contiguous()
            out[f"{b}.self_attn.out_proj.weight"] = s[f"{a}.attn.out_proj.weight"]
            out[f"{b}.self_attn.out_proj.bias"] = s[f"{a}.attn.out_proj.bias"]
            for x, y in (("ln_1", "layer_norm1"), ("ln_2", "layer_norm2"), ("mlp.c_fc", "mlp.fc1"), ("mlp.c_proj", "mlp.fc2")):
                out[f"{b}.{y}.weight"] = s[f"{a}.{x}.weight"]
                out[f"{b}.{y}.bias"] = s[f"{a}.{x}.bias"]

    blocks("visual.transformer", "vision_model", 2)
    blocks("transformer", "text_model", 2)
    out["vision_model.embeddings.patch_embedding.weight"] = s["visual.conv1.weight"]
    out["vision_model.embeddings.class_embedding"] = s["visual.class_embedding"]
    out["vision_model.embeddings.position_embedding.weight"] = s["visual.positional_embedding"]
    for x, y in (("visual.ln_pre", "vision_model.pre_layrnorm"), ("visual.ln_post", "vision_model.post_layernorm"), ("ln_final", "text_model.final_layer_norm")):
        out[f"{y}.weight"] = s[f"{x}.weight"]
        out[f"{y}.bias"] = s[f"{x}.bias"]
    out["visual_projection.weight"] = s["visual.proj"].t().contiguous()
    out["text_projection.weight"] = s["text_projection"].t().contiguous()
    out["text_model.embeddings.token_embedding.weight"] = s["token_embedding.weight"]
    out["text_model.embeddings.position_embedding.weight"] = s["positional_embedding"]
    out["logit_scale"] = s["logit_scale"]
    return out


def hf_config(cfg):
    v, t = cfg["vision_cfg"], cfg["text_cfg"]
    act = "quick_gelu" if cfg["quick_gelu"] else "gelu"
    return {
        "projection_dim": cfg["embed_dim"],
        "vision_config": {"hidden_size": v["width"], "num_hidden_layers": v["layers"], "num_attention_heads": v["width"] // v["head_width"], "patch_size": v["patch_size"], "image_size": v["image_size"], "hidden_act": act},
        "text_config": {"hidden_size": t["width"], "num_hidden_layers": t["layers"], "num_attention_heads": t["heads"], "max_position_embeddings": t["context_length"], "vocab_size": t["vocab_size"], "hidden_act": act},
    }


def reference(model, images, tokens):
    with torch.no_grad():
        return (model.encode_image(images, normalize=True), model.encode_text(tokens, normalize=True),
                model.encode_image(images), model.encode_text(tokens))


def preprocess_case():
    """A 40×30 image with an L-shaped mask, cropped and padded as docs/architecture.md
    ("SemDynReg" item 2) describes, then CLIP's own eval transform (bicubic resize, centre
    crop, normalize) at 64 px to keep the fixture small (the Rust side takes the side
    length as a parameter)."""
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, size=(30, 40, 3), dtype=np.uint8)
    mask = np.zeros((30, 40), dtype=bool)
    mask[5:25, 8:14] = True
    mask[20:25, 8:30] = True
    masked = img * mask[..., None]
    ys, xs = np.nonzero(mask)
    crop = masked[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    h, w, _ = crop.shape
    side = max(h, w)
    square = np.zeros((side, side, 3), dtype=np.uint8)
    top, left = (side - h) // 2, (side - w) // 2
    square[top:top + h, left:left + w] = crop
    transform = open_clip.transform.image_transform(64, is_train=False)
    pixels = transform(Image.fromarray(square))
    return {"image": torch.from_numpy(img), "mask": torch.from_numpy(mask.astype(np.uint8)), "pixels": pixels}


def main():
    os.makedirs(OUT, exist_ok=True)
    tokenizer = open_clip.get_tokenizer("ViT-B-16")
    tokens = tokenizer(PROMPTS)
    with open(f"{OUT}/tokens.json", "w") as f:
        json.dump({"context_length": 77, "prompts": PROMPTS, "ids": tokens.tolist()}, f, ensure_ascii=False, indent=0)

    torch.manual_seed(0)
    images = torch.randn(3, 3, 32, 32)
    text_idx = [0, 1, 2, 7, 13]
    ref = {"images": images, "tokens": tokens[text_idx].to(torch.int64)}
    for name, patch, quick, seed, layout in (("tiny_gelu", 8, False, 1, "open_clip"), ("tiny_quickgelu_hf", 16, True, 2, "hf")):
        cfg = tiny_config(patch, quick)
        model = build(cfg, seed)
        img_n, txt_n, img_raw, txt_raw = reference(model, images, ref["tokens"])
        ref[f"{name}.image"], ref[f"{name}.text"] = img_n, txt_n
        ref[f"{name}.image_raw"], ref[f"{name}.text_raw"] = img_raw, txt_raw
        state = open_clip_state(model) if layout == "open_clip" else hf_state(model)
        save_file(state, f"{OUT}/{name}.safetensors")
        with open(f"{OUT}/{name}.json", "w") as f:
            json.dump(cfg if layout == "open_clip" else hf_config(cfg), f, indent=1)
    save_file({k: v.contiguous() for k, v in ref.items()}, f"{OUT}/reference.safetensors")
    save_file({k: v.contiguous() for k, v in preprocess_case().items()}, f"{OUT}/preprocess.safetensors")
    print("wrote", sorted(os.listdir(OUT)))


if __name__ == "__main__":
    main()
