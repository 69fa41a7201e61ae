"""Baking a neural texture to image maps Blender and game engines read, and saving its weights.

base_color.png: 8-bit sRGB (linear -> sRGB). roughness.png, metallic.png: 16-bit single-channel,
linear (non-colour data). All maps are dilated past UV seams so bilinear/mip lookups at island
edges never read the black background. texture.pt holds the config and weights so a later stage
(adaptation) resumes from exactly this network.
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import torch

from ..base.atomic import write_bytes_atomic
from ..base.errors import InputError
from ..data.imageio import linear_to_srgb, write_image
from .neural_texture import NeuralTexture, NeuralTextureConfig
from .surface_layout import SurfaceLayout

WEIGHTS_FORMAT = "scenefit.neural_texture"
WEIGHTS_VERSION = 1

MAP_FILES = {"base_color": "base_color.png", "roughness": "roughness.png", "metallic": "metallic.png"}
WEIGHTS_FILE = "texture.pt"


def bake_texture(texture: NeuralTexture, position_map, mask, fill_index, base_logit=None) -> np.ndarray:
    """(H, W, 5) float32 linear maps evaluated on `mask` texels and dilated past seams (base_logit: a
    residual texture's base for this raster, when it is not the texture's own)."""
    with torch.no_grad():
        return texture.texture(position_map, mask, fill_index, base_logit).cpu().numpy().astype(np.float32)


def bake_maps(texture: NeuralTexture, position_map, mask, fill_index, out_dir: str | os.PathLike,
              constants: dict[str, float] | None = None) -> dict[str, Path | float]:
    """Write base_color.png, roughness.png, metallic.png and texture.pt into out_dir (atomically).

    Pass a UVRaster's `position`, `border` and `fill_index`. Returns {"base_color", "roughness",
    "metallic", "weights"} -> path. constants: roughness/metallic that stay one value; they are
    returned as that float and get no map (write_result_material sets the socket's value).
    """
    out_dir = Path(out_dir)
    constants = constants or {}
    maps = bake_texture(texture, position_map, mask, fill_index)
    out: dict[str, Path | float] = {
        "base_color": write_image(out_dir / MAP_FILES["base_color"], linear_to_srgb(maps[..., 0:3]), dtype="uint8")}
    for channel, name in ((3, "roughness"), (4, "metallic")):
        out[name] = float(constants[name]) if name in constants else \
            write_image(out_dir / MAP_FILES[name], maps[..., channel], dtype="uint16")
    out["weights"] = save_neural_texture(texture, out_dir / WEIGHTS_FILE)
    return out


def save_neural_texture(texture: NeuralTexture, path: str | os.PathLike) -> Path:
    """Config + state_dict in one torch file, written to a temp name and renamed."""
    state = {k: v.detach().cpu() for k, v in texture.state_dict().items()}
    payload = {"format": WEIGHTS_FORMAT, "version": WEIGHTS_VERSION,
               "config": texture.config.to_dict(), "state_dict": state}
    if texture.layout is not None:   # adaptation's new UV layout (core.surface_layout)
        payload["layout"] = texture.layout.to_payload()
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return write_bytes_atomic(path, buffer.getvalue())


def torch_load_reason(error: Exception) -> str:
    """Why torch.load failed, in a few words (its own message advises unsafe loading, which is not for users)."""
    text = str(error)
    if "weights_only" in text or "Weights only" in text:
        return "it holds more than tensors or is not a file SceneFit saved"
    first = next((line.strip() for line in text.splitlines() if line.strip()), "")
    return first[:200] or type(error).__name__


def load_neural_texture(path: str | os.PathLike, device: str | torch.device = "cpu") -> NeuralTexture:
    """The NeuralTexture saved by bake_maps / save_neural_texture, on `device`."""
    path = Path(path)
    if path.is_dir():
        path = path / WEIGHTS_FILE
    if not path.is_file():
        raise InputError(f"No neural texture weights at '{path}'; run the conversion first.")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several types for truncated or foreign files
        raise InputError(f"'{path}' is not a readable neural texture file ({torch_load_reason(error)}); "
                         "convert the asset again to make one.") from None
    if not isinstance(payload, dict) or payload.get("format") != WEIGHTS_FORMAT:
        raise InputError(f"'{path}' is not a SceneFit neural texture file.")
    if payload.get("version") != WEIGHTS_VERSION:
        raise InputError(f"'{path}' has neural texture format version {payload.get('version')}; "
                         f"this SceneFit reads version {WEIGHTS_VERSION}.")
    texture = NeuralTexture(NeuralTextureConfig.from_dict(payload["config"]), seed=None)
    try:
        texture.load_state_dict(payload["state_dict"])
    except RuntimeError as error:
        raise InputError(f"The weights in '{path}' do not match their config: {error}") from error
    if payload.get("layout") is not None:
        try:
            texture.layout = SurfaceLayout.from_payload(payload["layout"])
        except (KeyError, TypeError, ValueError, AttributeError):
            raise InputError(f"'{path}' has an unreadable UV layout; adapt the asset again.") from None
    return texture.to(device)
