"""Train the known-answer prior: a small text-to-image model and an inpainting model, laid out like the hub
repositories (unet/, vae/, text_encoder/, tokenizer/, scheduler/, model_index.json), from images drawn by
devtools/prior_data.py under fixed seeds. `make prior` runs it; `python -m scenefit.devtools.train_prior --out DIR`
writes DIR/base and DIR/inpaint, and does nothing when DIR already holds weights made by these sources.

The steps (minutes on two CPU cores): an AutoencoderKL that halves 32-px images once (its scaling factor
set so latents have unit spread), then the text encoder (a tiny CLIP whose tokenizer makes each colour word
one token) with the base UNet on the local images' latents (one prompt in ten emptied, so classifier-free
guidance has an unconditional model), then the inpainting UNet, started from the base UNet with its
five extra input channels at zero (as SD2-inpainting was made from SD2), on the global images.

A measuring instrument for the adapt stage (docs/engineers/testing.md), never a model for artists' work.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "prior"
SOURCES = ("train_prior.py", "prior_data.py", "known_prior.py", "tiny_models.py")
STAMP = "SOURCES.sha256"
SEED = 0
# Sizes and steps: what fits ~10 minutes on two shared CPU cores.
LOCAL_IMAGES, GLOBAL_IMAGES = 3000, 3000
VAE_STEPS, BASE_STEPS, INPAINT_STEPS, BATCH = 300, 700, 350, 32
EMPTY_PROMPT_P = 0.1
# The timesteps trained: score distillation samples t in [30, 990] (most runs [500, 990]); below 300
# the noise only hides edges, which no known answer needs, and training there slowed the colour's learning.
T_MIN = 300
LR = 2e-3
# Prompts padded to 24 tokens, not CLIP's 77: a random-start cross-attention spread over 77 mostly padding
# tokens learnt nothing of the colour word in 800 steps (the loss did not depend on the prompt).
MAX_TOKENS = 24
# One torch thread: on two cores shared with other work, two threads spin against each other (5x slower here).
THREADS = 1
# GroupNorm over 4 channels (as SD's 128 / 32), not one: a norm per channel would remove each channel's
# mean, which is where a flat object's colour lives.
SHAPE = dict(sample_size=16, block_out_channels=(16, 32), cross_attention_dim=32, layers_per_block=1,
             vae_block_out_channels=(8, 16), vae_layers_per_block=1, text_layers=2, text_heads=4,
             norm_groups=4, vae_norm_groups=2)


def sources_hash() -> str:
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update(name.encode())
        digest.update((HERE / name).read_bytes())
    return digest.hexdigest()


def up_to_date(out: Path) -> bool:
    stamp = out / STAMP
    return stamp.is_file() and stamp.read_text().strip() == sources_hash() and all(
        (out / role / "model_index.json").is_file() for role in ("base", "inpaint"))


def _log(started: float, message: str) -> None:
    print(f"[{time.perf_counter() - started:6.1f} s] {message}", flush=True)


def _data(started: float):
    from .prior_data import global_sample, local_sample

    rng = np.random.default_rng(SEED)
    local = [local_sample(rng) for _ in range(LOCAL_IMAGES)]
    glob = [global_sample(rng) for _ in range(GLOBAL_IMAGES)]
    _log(started, f"drew {len(local)} local and {len(glob)} global images")
    return local, glob


def _nchw(images) -> "torch.Tensor":  # noqa: F821
    import torch

    return torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).contiguous()


def _train_vae(vae, images, started: float) -> None:
    """As a plain autoencoder on the posterior mean (what the adapt stage encodes with): sampled latents
    left the decoder grey for hundreds of steps."""
    import torch

    optimizer = torch.optim.AdamW(vae.parameters(), lr=3e-3, weight_decay=0.0)
    generator = torch.Generator().manual_seed(SEED)
    vae.train()
    for step in range(VAE_STEPS):
        x = images[torch.randint(0, len(images), (BATCH,), generator=generator)] * 2 - 1
        loss = (vae.decode(vae.encode(x).latent_dist.mean).sample - x).abs().mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if step % 100 == 0 or step == VAE_STEPS - 1:
            _log(started, f"vae {step}: L1 {float(loss.detach()):.4f}")
    vae.eval()


def _latents(vae, images) -> "torch.Tensor":  # noqa: F821
    import torch

    with torch.no_grad():
        return torch.cat([vae.encode(images[i:i + 256] * 2 - 1).latent_dist.mean for i in range(0, len(images), 256)])


def _ids(tokenizer, prompts: list[str]) -> "torch.Tensor":  # noqa: F821
    return tokenizer(prompts, padding="max_length", max_length=tokenizer.model_max_length, truncation=True,
                     return_tensors="pt").input_ids


def _train_unet(unet, text_encoder, scheduler, latents, ids, empty_ids, steps: int, name: str, started: float,
                extra=None, train_text: bool = True) -> None:
    """ε-prediction on `latents` (N, 4, h, w) with prompts `ids` (N, 77); `extra` (N, 5, h, w): the inpainting
    input's mask and masked-image latents."""
    import torch

    params = list(unet.parameters()) + (list(text_encoder.parameters()) if train_text else [])
    optimizer = torch.optim.AdamW(params, lr=LR, weight_decay=0.0)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=LR, total_steps=steps, pct_start=0.05)
    alpha_bar = scheduler.alphas_cumprod
    generator = torch.Generator().manual_seed(SEED + 1)
    unet.train()
    text_encoder.train(train_text)
    text_encoder.requires_grad_(train_text)
    running = None
    for step in range(steps):
        rows = torch.randint(0, len(latents), (BATCH,), generator=generator)
        z0 = latents[rows]
        t = torch.randint(T_MIN, len(alpha_bar), (BATCH,), generator=generator)
        noise = torch.randn(z0.shape, generator=generator)
        a = alpha_bar[t].view(-1, 1, 1, 1)
        zt = a.sqrt() * z0 + (1 - a).sqrt() * noise
        if extra is not None:
            zt = torch.cat([zt, extra[rows]], dim=1)
        batch_ids = ids[rows].clone()
        empty = torch.rand(BATCH, generator=generator) < EMPTY_PROMPT_P
        batch_ids[empty] = empty_ids
        text = text_encoder(batch_ids)[0]
        target = a.sqrt() * noise - (1 - a).sqrt() * z0   # v (velocity), the scheduler's prediction type
        loss = (unet(zt, t, encoder_hidden_states=text).sample - target).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()
        value = float(loss.detach())
        running = value if running is None else 0.98 * running + 0.02 * value
        if step % 200 == 0 or step == steps - 1:
            _log(started, f"{name} {step}: loss {running:.4f}")
    unet.eval()
    text_encoder.eval()


def _inpaint_unet(base_unet):
    """The base UNet with a 9-channel input: the five new channels' weights start at zero."""
    import torch
    from diffusers import UNet2DConditionModel

    config = dict(base_unet.config)
    config["in_channels"] = 9
    unet = UNet2DConditionModel.from_config(config)
    state = base_unet.state_dict()
    conv = state["conv_in.weight"]
    state["conv_in.weight"] = torch.cat([conv, torch.zeros(conv.shape[0], 5, *conv.shape[2:])], dim=1)
    unet.load_state_dict(state)
    return unet


def train(out: Path) -> None:
    import torch
    from diffusers import AutoencoderKL, DDPMScheduler, UNet2DConditionModel
    from transformers import CLIPTextModel

    from .prior_data import vocabulary
    from .tiny_models import build_tiny_sd, tiny_tokenizer

    started = time.perf_counter()
    torch.set_num_threads(THREADS)
    torch.manual_seed(SEED)
    work = out / ".building"
    shutil.rmtree(work, ignore_errors=True)
    # The real classes, built as the random tiny models are (the control has the same shape).
    tokenizer = tiny_tokenizer(vocabulary(), max_length=MAX_TOKENS)
    folder = build_tiny_sd(work / "base", 4, seed=SEED, tokenizer=tokenizer, **SHAPE)
    vae = AutoencoderKL.from_pretrained(folder / "vae")
    unet = UNet2DConditionModel.from_pretrained(folder / "unet")
    text_encoder = CLIPTextModel.from_pretrained(folder / "text_encoder")
    # v-prediction (as SD 2.1-768): at high noise the target is the clean latents themselves, so the colour
    # word is what lowers the loss; with ε-prediction a flat colour's word changed the loss by nothing the
    # 800 steps here could learn from (the critics convert v to ε, critics.to_epsilon).
    scheduler = DDPMScheduler.from_pretrained(folder / "scheduler", prediction_type="v_prediction")
    scheduler.save_pretrained(folder / "scheduler")
    local, glob = _data(started)
    local_images = _nchw([s.image for s in local])
    global_images = _nchw([s.image for s in glob])
    masked_images = _nchw([s.masked for s in glob])
    _train_vae(vae, torch.cat([local_images, global_images, masked_images]), started)
    raw = _latents(vae, local_images)
    scale = float(1.0 / raw.std())
    vae.register_to_config(scaling_factor=scale)
    local_latents = raw * scale
    global_latents = _latents(vae, global_images) * scale
    masked_latents = _latents(vae, masked_images) * scale
    masks = torch.from_numpy(np.stack([s.mask for s in glob]))[:, None]
    _log(started, f"latents: scaling factor {scale:.4f}")
    empty_ids = _ids(tokenizer, [""])[0]
    _train_unet(unet, text_encoder, scheduler, local_latents, _ids(tokenizer, [s.prompt for s in local]), empty_ids,
                BASE_STEPS, "base", started)
    inpaint = _inpaint_unet(unet)
    _train_unet(inpaint, text_encoder, scheduler, global_latents, _ids(tokenizer, [s.prompt for s in glob]),
                empty_ids, INPAINT_STEPS, "inpaint", started, extra=torch.cat([masks, masked_latents], dim=1),
                train_text=False)
    for module in (vae, unet, text_encoder, inpaint):
        module.requires_grad_(True)
    vae.save_pretrained(folder / "vae")
    unet.save_pretrained(folder / "unet")
    text_encoder.save_pretrained(folder / "text_encoder")
    inpaint_folder = work / "inpaint"
    shutil.copytree(folder, inpaint_folder)
    inpaint.save_pretrained(inpaint_folder / "unet")
    index = json.loads((folder / "model_index.json").read_text())
    index["_class_name"] = "StableDiffusionInpaintPipeline"
    (inpaint_folder / "model_index.json").write_text(json.dumps(index, indent=1))
    for role in ("base", "inpaint"):
        shutil.rmtree(out / role, ignore_errors=True)
        (work / role).rename(out / role)
    shutil.rmtree(work, ignore_errors=True)
    (out / STAMP).write_text(sources_hash() + "\n")
    _log(started, f"wrote {out / 'base'} and {out / 'inpaint'}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="where base/ and inpaint/ go")
    parser.add_argument("--force", action="store_true", help="train even when the weights are up to date")
    args = parser.parse_args(argv)
    if not args.force and up_to_date(args.out):
        print(f"{args.out}: the prior is up to date with its sources; nothing to do.")
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    train(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
