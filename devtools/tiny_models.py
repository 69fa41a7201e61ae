"""Tiny random-weight stand-ins for Stable Diffusion 2, laid out like the hub repositories.

Tests and `make bench` build them with the same diffusers/transformers classes as the real models
and load them through `models.load_guidance_models`, so the loading code under test is the real one.
Nothing here is used by a real run.
"""
from __future__ import annotations

import json
from pathlib import Path

# The byte-level alphabet of CLIP's BPE (the GPT-2 table): every byte gets a printable character.
def _bytes_to_unicode() -> dict[int, str]:
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    cs = bs[:]
    n = 0
    for b in range(256):
        if b not in bs:
            bs.append(b)
            cs.append(256 + n)
            n += 1
    return dict(zip(bs, (chr(c) for c in cs)))


def tiny_tokenizer(words: tuple[str, ...] = (), max_length: int = 77):
    """A CLIPTokenizer with a 514-token vocabulary: every byte alone and word-final, plus the specials;
    each of `words` (lower case) also becomes one token of its own, by BPE merges that join its letters.
    max_length: the sequence prompts are padded to (CLIP's 77)."""
    from transformers import CLIPTokenizer

    chars = list(_bytes_to_unicode().values())
    vocab: dict[str, int] = {}
    for token in chars + [c + "</w>" for c in chars] + ["<|startoftext|>", "<|endoftext|>"]:
        vocab[token] = len(vocab)
    merges: list[tuple[str, str]] = []
    tokenizer = CLIPTokenizer(vocab=vocab, merges=merges, model_max_length=max_length)
    for word in words:
        # Join the pieces the merges so far leave, left to right; the new merges rank after every earlier
        # one, so no word made before is split differently.
        pieces = tokenizer.tokenize(word)
        if len(pieces) > 1:
            joined = pieces[0]
            for piece in pieces[1:]:
                merges.append((joined, piece))
                joined += piece
                vocab.setdefault(joined, len(vocab))
            tokenizer = CLIPTokenizer(vocab=vocab, merges=merges, model_max_length=max_length)
    for word in words:
        if len(tokenizer.tokenize(word)) != 1:
            raise ValueError(f"The word {word!r} did not become one token.")
    return tokenizer


# Stable Diffusion 2's UNet shape (865M parameters), for timing with random weights on a GPU.
SD2_UNET = {"sample_size": 64, "block_out_channels": (320, 640, 1280, 1280), "cross_attention_dim": 1024,
            "layers_per_block": 2, "attention_head_dim": (5, 10, 20, 20)}
# The whole of SD2 at its real size (stabilityai/stable-diffusion-2-base's configs): the UNet above, the
# SD VAE (8x downsampling, 84M) and a text encoder of OpenCLIP ViT-H's size (23 layers of 1024, 340M).
SD2_SIZED = {**SD2_UNET, "vae_block_out_channels": (128, 256, 512, 512), "vae_layers_per_block": 2,
             "text_layers": 23, "text_heads": 16, "text_intermediate": 4096}


def build_tiny_sd(folder: str | Path, in_channels: int = 4, seed: int = 0, sample_size: int = 16,
                  block_out_channels: tuple[int, ...] = (32, 64), cross_attention_dim: int = 32,
                  layers_per_block: int = 1, attention_head_dim: tuple[int, ...] | None = None,
                  vae_block_out_channels: tuple[int, ...] = (8, 16), vae_layers_per_block: int = 1,
                  text_layers: int = 2, text_heads: int = 4, text_intermediate: int | None = None,
                  tokenizer=None, norm_groups: int | None = None, vae_norm_groups: int | None = None) -> Path:
    """Write unet/, vae/, text_encoder/, tokenizer/, scheduler/ and model_index.json into `folder`.

    in_channels 4 is the text-to-image model, 9 the inpainting one (latents, mask, masked image).
    The VAE halves the resolution once per block after the first (tiny: a 32-pixel render gives 16x16
    latents; SD2_SIZED: 8x, as SD's). build_tiny_sd(folder, **SD2_SIZED) is Stable Diffusion 2's size.
    tokenizer: a CLIPTokenizer (default: tiny_tokenizer()). norm_groups / vae_norm_groups: the GroupNorm
    groups (default: up to 32, one channel each at these widths, which removes each channel's mean).
    """
    import torch
    from diffusers import AutoencoderKL, DDPMScheduler, UNet2DConditionModel
    from transformers import CLIPTextConfig, CLIPTextModel

    folder = Path(folder)
    torch.manual_seed(seed)
    tokenizer = tiny_tokenizer() if tokenizer is None else tokenizer
    n = len(block_out_channels)
    unet = UNet2DConditionModel(
        sample_size=sample_size, in_channels=in_channels, out_channels=4, layers_per_block=layers_per_block,
        block_out_channels=block_out_channels, norm_num_groups=norm_groups or min(32, block_out_channels[0]),
        down_block_types=("CrossAttnDownBlock2D",) * (n - 1) + ("DownBlock2D",),
        up_block_types=("UpBlock2D",) + ("CrossAttnUpBlock2D",) * (n - 1),
        cross_attention_dim=cross_attention_dim,
        attention_head_dim=attention_head_dim or tuple(max(1, c // 16) for c in block_out_channels),
        use_linear_projection=True,  # as SD2
    )
    levels = len(vae_block_out_channels)
    vae = AutoencoderKL(in_channels=3, out_channels=3, latent_channels=4, block_out_channels=vae_block_out_channels,
                        down_block_types=("DownEncoderBlock2D",) * levels, up_block_types=("UpDecoderBlock2D",) * levels,
                        layers_per_block=vae_layers_per_block,
                        norm_num_groups=vae_norm_groups or min(32, vae_block_out_channels[0]),
                        sample_size=sample_size * 2 ** (levels - 1))
    text_encoder = CLIPTextModel(CLIPTextConfig(
        vocab_size=len(tokenizer), hidden_size=cross_attention_dim,
        intermediate_size=text_intermediate or 2 * cross_attention_dim,
        num_hidden_layers=text_layers, num_attention_heads=text_heads, max_position_embeddings=77,
        projection_dim=cross_attention_dim,
        bos_token_id=tokenizer.bos_token_id, eos_token_id=tokenizer.eos_token_id, pad_token_id=tokenizer.pad_token_id))
    scheduler = DDPMScheduler(num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012,
                              beta_schedule="scaled_linear", prediction_type="epsilon", clip_sample=False)
    unet.save_pretrained(folder / "unet")
    vae.save_pretrained(folder / "vae")
    text_encoder.save_pretrained(folder / "text_encoder")
    tokenizer.save_pretrained(folder / "tokenizer")
    scheduler.save_pretrained(folder / "scheduler")
    (folder / "model_index.json").write_text(json.dumps({
        "_class_name": "StableDiffusionInpaintPipeline" if in_channels == 9 else "StableDiffusionPipeline",
        "unet": ["diffusers", "UNet2DConditionModel"], "vae": ["diffusers", "AutoencoderKL"],
        "text_encoder": ["transformers", "CLIPTextModel"], "tokenizer": ["transformers", "CLIPTokenizer"],
        "scheduler": ["diffusers", "DDPMScheduler"]}, indent=1))
    return folder


def build_tiny_pair(folder: str | Path) -> tuple[Path, Path]:
    """A tiny text-to-image model and a tiny inpainting model: (base, inpaint) folders."""
    folder = Path(folder)
    return build_tiny_sd(folder / "sd2-base", 4, seed=0), build_tiny_sd(folder / "sd2-inpaint", 9, seed=1)


def build_tiny_depth(folder: str | Path) -> Path:
    """A random-weight Depth Anything (a few kB) saved as the depth model's folder, for tests of the real
    loading code."""
    import torch
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config, DPTImageProcessor

    backbone = Dinov2Config(hidden_size=16, num_hidden_layers=2, num_attention_heads=2, intermediate_size=32,
                            image_size=28, patch_size=14, out_features=["stage1", "stage2"], out_indices=[1, 2],
                            reshape_hidden_states=False)
    config = DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=16, neck_hidden_sizes=[8, 16],
                                 fusion_hidden_size=8, head_hidden_size=8, reassemble_factors=[2, 1])
    torch.manual_seed(0)
    DepthAnythingForDepthEstimation(config).save_pretrained(folder)
    DPTImageProcessor(size={"height": 28, "width": 28}, keep_aspect_ratio=False, ensure_multiple_of=14).save_pretrained(folder)
    return Path(folder)
