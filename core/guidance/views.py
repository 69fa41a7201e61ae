"""What the critics look at: the local view (object on a solid colour) and the global views (object
composited into the photo by compose's rule with its shadow, cropped at several scales; the asset
layer comes from core/stages/adapt/global_views.py), plus the inpainting input.

Images are torch (1, 3, H, W) display sRGB in [0, 1]; the object arrives as the renderer's linear,
premultiplied radiance (background 0, see SceneOptions.hide_emitters) and its alpha.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from ..base.errors import InputError
from ..scene.mattes import composite_linear

GREY = (0.5, 0.5, 0.5)


def linear_to_srgb_torch(x: torch.Tensor) -> torch.Tensor:
    """The sRGB curve, differentiable, on values clamped to [0, 1]."""
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * x.clamp_min(0.0031308) ** (1.0 / 2.4) - 0.055)


def srgb_to_linear_torch(x: torch.Tensor) -> torch.Tensor:
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def to_nchw(image_hwc: torch.Tensor) -> torch.Tensor:
    return image_hwc.permute(2, 0, 1)[None]


def background_color(rng: np.random.Generator, random_p: float = 0.5) -> tuple[float, float, float]:
    """Grey 0.5, or with probability `random_p` a random solid colour (sRGB), as in the appendix."""
    if rng.uniform() < random_p:
        r, g, b = (float(c) for c in rng.uniform(0.0, 1.0, 3))
        return r, g, b
    return GREY


def local_view(rgb: torch.Tensor, alpha: torch.Tensor, color: tuple[float, float, float], size: int | None = None) -> torch.Tensor:
    """(1, 3, S, S) sRGB: premultiplied linear radiance (h, w, 3) over a solid sRGB colour, resized to `size`."""
    bg = srgb_to_linear_torch(torch.tensor(color, dtype=rgb.dtype, device=rgb.device))
    image = linear_to_srgb_torch(rgb + (1.0 - alpha) * bg)
    image = to_nchw(image)
    if size is not None and image.shape[-1] != size:
        image = F.interpolate(image, size=(size, size), mode="bilinear", align_corners=False)
    return image


def sample_crops(photo_hw: tuple[int, int], box: tuple[float, float, float], count: int,
                 rng: np.random.Generator) -> list[tuple[float, float, float]]:
    """`count` square crops (x0, y0, side) at several scales, each holding the object's square `box`
    (x0, y0, side in photo pixels).

    The sides are stratified between the object's square and the largest square the photo holds
    around it: crop i's side is drawn in the i-th of `count` equal slices of that range, so every
    step sees a close crop and a wide one (one crop: anywhere in the range). Positions are random
    among those that keep the object inside (and the crop inside the photo where it can be).
    """
    h, w = photo_hw
    ox, oy, oside = box
    biggest = max(float(min(h, w)), oside)
    crops = []
    for i in range(count):
        side = oside + (biggest - oside) * (i + float(rng.uniform())) / count
        # x0 must satisfy x0 <= ox and x0 + side >= ox + oside, and stay in the photo where it can.
        lo_x, hi_x = ox + oside - side, ox
        lo_y, hi_y = oy + oside - side, oy
        lo_x, hi_x = max(lo_x, min(0.0, ox)), min(hi_x, max(w - side, lo_x))
        lo_y, hi_y = max(lo_y, min(0.0, oy)), min(hi_y, max(h - side, lo_y))
        x0 = float(rng.uniform(lo_x, hi_x)) if hi_x > lo_x else lo_x
        y0 = float(rng.uniform(lo_y, hi_y)) if hi_y > lo_y else lo_y
        crops.append((x0, y0, side))
    return crops


def photo_crop(photo: np.ndarray, crop: tuple[float, float, float], size: int) -> np.ndarray:
    """The photo inside `crop` resampled to size x size (edge pixels repeat outside the photo)."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    x0, y0, side = crop
    scale = side / size
    m = np.array([[scale, 0.0, x0], [0.0, scale, y0]], np.float32)
    # Sample at pixel centres: output pixel (i + 0.5) maps to x0 + (i + 0.5) * scale.
    m[:, 2] += 0.5 * scale - 0.5
    interp = cv2.INTER_AREA if scale > 1 else cv2.INTER_LINEAR
    if scale > 1.5:  # shrink first so the warp does not alias
        small = cv2.resize(photo, (max(1, int(photo.shape[1] / scale)), max(1, int(photo.shape[0] / scale))),
                           interpolation=interp)
        f = photo.shape[1] / small.shape[1], photo.shape[0] / small.shape[0]
        m = np.array([[scale / f[0], 0.0, (x0 + 0.5 * scale) / f[0] - 0.5],
                      [0.0, scale / f[1], (y0 + 0.5 * scale) / f[1] - 0.5]], np.float32)
        photo = small
    return cv2.warpAffine(photo, m, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def paste_layer(layer: torch.Tensor, rect: tuple[float, float, float, float], crop: tuple[float, float, float],
                size: int) -> torch.Tensor:
    """(1, C, S, S): a layer (h, w, C) that covers `rect` (x0, y0, width, height in photo pixels), seen
    through the square `crop` (x0, y0, side) at size x size, 0 outside it. Differentiable in `layer`."""
    x0, y0, side = crop
    scale = size / side
    rx, ry, rw, rh = rect
    pw, ph = max(1, int(round(rw * scale))), max(1, int(round(rh * scale)))
    out = layer.permute(2, 0, 1)[None]
    if out.shape[-2:] != (ph, pw):
        out = F.interpolate(out, size=(ph, pw), mode="bilinear", align_corners=False,
                            antialias=ph < out.shape[-2] or pw < out.shape[-1])
    left, top = int(round((rx - x0) * scale)), int(round((ry - y0) * scale))
    # Pad (or crop, with negative padding) the layer to the output canvas.
    return F.pad(out, (left, size - left - pw, top, size - top - ph))


def global_view(rgb: torch.Tensor, alpha: torch.Tensor, rect: tuple[float, float, float, float],
                photo: np.ndarray, matte: np.ndarray, crop: tuple[float, float, float],
                size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The asset's layer (premultiplied linear (h, w, 3), alpha (h, w, 1), covering `rect` = x0, y0,
    width, height of the photo) composited into the sRGB photo with its shadow `matte` (H, W, 3) by
    compose's rule, seen through `crop`, at size x size: ((1, 3, S, S) sRGB image, (1, 1, S, S) alpha).

    Differentiable with respect to rgb and alpha.
    """
    obj = paste_layer(torch.cat([rgb, alpha], dim=-1), rect, crop, size)
    obj_rgb, obj_alpha = obj[:, :3], obj[:, 3:4]
    bg = torch.from_numpy(photo_crop(np.asarray(photo, np.float32), crop, size)).to(rgb)
    bg_linear = srgb_to_linear_torch(bg.permute(2, 0, 1)[None])
    shadow = torch.from_numpy(photo_crop(np.asarray(matte, np.float32), crop, size)).to(rgb).permute(2, 0, 1)[None]
    image = linear_to_srgb_torch(composite_linear(obj_rgb, obj_alpha, bg_linear, shadow))
    return image, obj_alpha


def inpainting_input(noisy_latents: torch.Tensor, mask: torch.Tensor, masked_image_latents: torch.Tensor) -> torch.Tensor:
    """The 9-channel UNet input of SD inpainting: [x_t (4), mask (1), masked-image latents (4)]
    (the channel order of diffusers' StableDiffusionInpaintPipeline). mask is 1 where the model
    may paint, here where the object is."""
    if mask.shape[-2:] != noisy_latents.shape[-2:]:
        raise InputError(f"Mask {tuple(mask.shape)} and latents {tuple(noisy_latents.shape)} differ in size.")
    return torch.cat([noisy_latents, mask.to(noisy_latents.dtype), masked_image_latents.to(noisy_latents.dtype)], dim=1)


def latent_mask(alpha: torch.Tensor, latent_hw: tuple[int, int], threshold: float = 0.01) -> torch.Tensor:
    """(1, 1, h, w) binary mask at latent resolution: 1 wherever any of the object's pixels fall."""
    covered = (alpha.detach() > threshold).float()
    return (F.adaptive_max_pool2d(covered, latent_hw) > 0).float()


def masked_image(image: torch.Tensor, alpha: torch.Tensor, threshold: float = 0.01) -> torch.Tensor:
    """The photo with the object's region blanked (to 0.5 grey, i.e. 0 in [-1, 1]), no gradient."""
    keep = (alpha.detach() <= threshold).float()
    return image.detach() * keep + 0.5 * (1.0 - keep)
