"""Outdoor completion by outpainting: the SD2 inpainting model paints the part of the map the photo
did not see (the issue's "outdoor" LDR map; the model is the one the global view already loads).

    outpaint_panorama(ldr, known, models, config) -> (H, W, 3) sRGB [0, 1]

The map (the photo warped into its place, the sky/ground prior elsewhere) is resized to the model's
working size (resolution x 2 resolution); the unseen part is painted by a DDIM loop written out as
diffusers' StableDiffusionInpaintPipeline runs it (9-channel UNet input [x_t, mask, masked-image
latents], classifier-free guidance); then, seam-aware, the map is rolled by half its width so the
wrap seam (u = 0 = 1) lies in the middle and a band across it is painted again with everything else
as context, and rolled back. Known texels are pasted back at the map's own resolution, so the photo's
region is kept exactly.
"""
from __future__ import annotations


import numpy as np
import torch
import torch.nn.functional as F

from ...base.errors import InputError
from ...guidance.models import GuidanceModels
from ...guidance.views import inpainting_input
from .config import OutpaintConfig



def _decode(models: GuidanceModels, latents: torch.Tensor) -> torch.Tensor:
    x = models.vae.decode((latents / models.latent_scale).to(models.vae.dtype)).sample.float()
    return ((x + 1.0) / 2.0).clamp(0.0, 1.0)


@torch.no_grad()
def inpaint(models: GuidanceModels, image: torch.Tensor, paint: torch.Tensor, config: OutpaintConfig,
            generator: torch.Generator) -> torch.Tensor:
    """(1, 3, h, w) sRGB [0, 1] with the `paint` (1, 1, h, w) = 1 region painted by the inpainting UNet."""
    from diffusers import DDIMScheduler  # lazy: diffusers takes seconds to load

    if models.inpaint_unet is None:
        raise InputError("Outpainting needs the inpainting model; load the models with need_inpaint=True.")
    scheduler = DDIMScheduler.from_config(models.scheduler.config)
    scheduler.set_timesteps(config.steps)
    h, w = image.shape[-2:]
    f = models.vae_scale_factor
    # Masked image (painted part blanked to grey) -> latents; the mask at latent resolution.
    masked = image * (1.0 - paint) + 0.5 * paint
    masked_latents = models.encode(masked)
    mask = (F.adaptive_max_pool2d(paint, (h // f, w // f)) > 0).float().to(models.device)
    text = torch.cat([models.embed(config.negative_prompt), models.embed(config.prompt)], dim=0)
    latents = torch.randn((1, 4, h // f, w // f), generator=generator).to(models.device) * scheduler.init_noise_sigma
    unet = models.inpaint_unet
    for t in scheduler.timesteps:
        # Both CFG rows in one batch: [∅, text].
        x = scheduler.scale_model_input(torch.cat([latents, latents], dim=0), t)
        sample = inpainting_input(x, mask.expand(2, -1, -1, -1), masked_latents.expand(2, -1, -1, -1))
        out = unet(sample.to(unet.dtype), t, encoder_hidden_states=text.to(unet.dtype)).sample.float()
        uncond, cond = out[:1], out[1:]
        noise_pred = uncond + config.guidance_scale * (cond - uncond)
        latents = scheduler.step(noise_pred, t, latents).prev_sample
    painted = _decode(models, latents).to(image.device)
    return image * (1.0 - paint) + painted * paint


def outpaint_panorama(ldr: np.ndarray, known: np.ndarray, models: GuidanceModels,
                      config: OutpaintConfig = OutpaintConfig()) -> np.ndarray:
    """Paint the unknown part of an (H, 2H, 3) sRGB map; known texels come back unchanged."""
    height, width = known.shape
    r = config.resolution
    generator = torch.Generator().manual_seed(config.seed)
    image = torch.from_numpy(np.ascontiguousarray(ldr, np.float32)).permute(2, 0, 1)[None]
    work = F.interpolate(image, size=(r, 2 * r), mode="bilinear", align_corners=False)
    known_t = torch.from_numpy(known.astype(np.float32))[None, None]
    # A texel is left alone only when all of its footprint is known.
    unknown = (F.interpolate(1.0 - known_t, size=(r, 2 * r), mode="area") > 0).float()
    # Pass 1: everything unseen.
    work = inpaint(models, work, unknown, config, generator)
    # Pass 2: roll the wrap seam into the middle and paint a band across it again.
    band = int(round(config.seam_band_fraction * 2 * r))
    if band > 0:
        rolled = torch.roll(work, r, dims=-1)
        seam = torch.zeros_like(unknown)
        seam[..., r - band // 2: r + band - band // 2] = 1.0
        seam = seam * torch.roll(unknown, r, dims=-1)
        if float(seam.sum()) > 0:
            work = torch.roll(inpaint(models, rolled, seam, config, generator), -r, dims=-1)
    out = F.interpolate(work, size=(height, width), mode="bilinear", align_corners=False)[0].permute(1, 2, 0)
    out = out.cpu().numpy().astype(np.float32)
    return np.where(known[..., None], np.asarray(ldr, np.float32), np.clip(out, 0.0, 1.0)).astype(np.float32)
