"""The steps a material's maps are computed with from their pixels, by name (core/data/map_plan.py):
Blender's implicit socket conversions, Separate Color's channels, Multiply's product and clamp, a Mix's
factor, a normal map's strength, and the maps made whole. Pure numpy, so a job's worker runs them."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .maps import PBRMaps, resize_channels

# Blender's colour -> float conversion for the default (Rec.709) OCIO configuration.
REC709_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
# Size of the base-colour image made when Base Color is a constant but another channel is not.
CONSTANT_SIZE = 256

Value = float | np.ndarray  # float, (3,) colour, (H, W) map or (H, W, 3) colour map


def is_color(value: Value) -> bool:
    return isinstance(value, np.ndarray) and (value.shape == (3,) or (value.ndim == 3 and value.shape[2] == 3))


def convert(value: Value, kind: str) -> Value:
    """Blender's implicit conversions between colour and float sockets."""
    colour = is_color(value)
    if kind == "color" and not colour:
        return np.repeat(np.asarray(value, np.float32)[..., None], 3, axis=-1) if isinstance(value, np.ndarray) \
            else np.full(3, float(value), np.float32)
    if kind == "float" and colour and isinstance(value, np.ndarray):
        gray = (value @ REC709_LUMA).astype(np.float32)
        if value.ndim == 3 and np.array_equal(value[..., 0], value[..., 1]) \
                and np.array_equal(value[..., 0], value[..., 2]):
            gray = value[..., 0].copy()  # a grey image is its own value, bit for bit
        return gray if value.ndim == 3 else float(gray)
    return value


def product(a: Value, b: Value) -> Value:
    """a * b, broadcasting maps of different sizes to the larger one."""
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.ndim >= 2 and b.ndim >= 2 \
            and a.shape[:2] != b.shape[:2]:
        h, w = max(a.shape[:2], b.shape[:2], key=lambda s: s[0] * s[1])
        a, b = resize_channels(a, h, w), resize_channels(b, h, w)
    if isinstance(a, np.ndarray) and a.ndim == 2 and is_color(b):
        a = a[..., None]  # a grey map times a colour
    if isinstance(b, np.ndarray) and b.ndim == 2 and is_color(a):
        b = b[..., None]
    result = np.asarray(a, np.float32) * np.asarray(b, np.float32)
    return result if result.ndim else float(result)


def clamp(on: bool, value: Value) -> Value:
    if not on:
        return value
    return np.clip(value, 0.0, 1.0) if isinstance(value, np.ndarray) else min(max(value, 0.0), 1.0)


def mixed(a: Value, b: Value, factor: float) -> Value:
    """A Mix node's Multiply at `factor`."""
    multiplied = product(a, b)
    return product(a, 1.0 - factor) + product(multiplied, factor) if factor != 1.0 else multiplied


def colour(pixels: np.ndarray) -> np.ndarray:
    return pixels[..., :3].copy()


def alpha(pixels: np.ndarray) -> np.ndarray:
    return pixels[..., 3].copy()


def channel(color: Value, index: int) -> Value:
    return color[..., index].copy() if isinstance(color, np.ndarray) and color.ndim == 3 \
        else float(np.asarray(color)[index])


def clipped(value: Value) -> Value:
    return np.clip(value, 0.0, 1.0) if isinstance(value, np.ndarray) else float(np.clip(value, 0.0, 1.0))


def baked(pixels: np.ndarray, kind: str) -> np.ndarray:
    """A Cycles bake's (H, W, 3) as the socket's kind, in [0, 1]."""
    return np.clip(pixels if kind == "color" else pixels[..., 0].copy(), 0.0, 1.0)


def normal_at_strength(stored: np.ndarray, strength: float) -> np.ndarray:
    """A tangent-space normal map's encoded RGB with a Normal Map node's strength applied."""
    encoded = stored[..., :3]
    if strength != 1.0:  # Blender blends the perturbed normal with the surface normal by strength
        n = (encoded * 2.0 - 1.0) * strength + np.array([0.0, 0.0, 1.0 - strength], np.float32)
        n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-8)
        encoded = (n * 0.5 + 0.5).astype(np.float32)
    return np.ascontiguousarray(encoded, dtype=np.float32)


def pbr_maps(base_color: Value, roughness: Value, metallic: Value, normal: np.ndarray | None) -> PBRMaps:
    """The maps made whole: a constant base colour becomes an image the size of the other maps (or
    CONSTANT_SIZE square)."""
    if not (isinstance(base_color, np.ndarray) and base_color.ndim == 3):
        sizes = [m.shape for m in (roughness, metallic) if isinstance(m, np.ndarray)]
        h, w = sizes[0] if sizes else (CONSTANT_SIZE, CONSTANT_SIZE)
        base_color = np.broadcast_to(np.asarray(base_color, np.float32), (h, w, 3)).copy()
    return PBRMaps(base_color=np.ascontiguousarray(base_color, dtype=np.float32), roughness=roughness,
                   metallic=metallic, normal=normal)


STEPS: dict[str, Callable[..., Any]] = {
    "convert": convert, "product": product, "clamp": clamp, "mixed": mixed, "colour": colour, "alpha": alpha,
    "channel": channel, "clipped": clipped, "baked": baked, "normal_at_strength": normal_at_strength,
    "pbr_maps": pbr_maps}
