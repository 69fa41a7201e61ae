"""Only what the scene needs: sizes and representations chosen from the asset and the shot, each
with the reason the report gives.

    constant_channels(maps)          roughness/metallic that hold one value stay constants, not maps
    texture_size_for_screen(px, ...) texels an object needs when it covers `px` pixels of the composite
    envmap_height_for(maps)          environment-map rows from how glossy the asset is
"""
from __future__ import annotations

import math

import numpy as np

from ..base.decision import Decision
from .maps import PBRMaps

# 16-bit maps: values closer than one level are the same value.
CONSTANT_TOLERANCE = 1.0 / 65535.0
ENVMAP_HEIGHTS = (32, 256)      # smallest and largest map chosen (rows; 256 is the final preset's, the paper's)
GLOSSIEST_PERCENTILE = 5.0      # the glossiest 5% of the surface decides the map's sharpness


def report(decision: Decision) -> dict:
    """A decision here as the reports give it: {"value": ..., "why": ...}."""
    return {"value": decision.choice, "why": decision.reason}


def constant_channels(maps: PBRMaps) -> dict[str, Decision]:
    """For roughness and metallic: Decision(choice=float constant, or "map")."""
    out = {}
    for name in ("roughness", "metallic"):
        value = getattr(maps, name)
        if not isinstance(value, np.ndarray):
            out[name] = Decision(float(value), f"the asset's {name} is the constant {float(value):g}")
            continue
        low, high = float(value.min()), float(value.max())
        if high - low <= CONSTANT_TOLERANCE:
            constant = round(0.5 * (low + high), 6)
            out[name] = Decision(constant, f"the asset's {name} map holds one value ({constant:g}) everywhere, "
                                           "so it stays a constant instead of a baked map")
        else:
            out[name] = Decision("map", f"the asset's {name} varies ({low:.3g} to {high:.3g})")
    return out


def material_constant_channels(maps: list[PBRMaps], names: list[str]) -> dict[str, Decision]:
    """constant_channels for several materials, each judged on its own texels (an atlas's empty
    background once made every material's roughness 1 read as 'varies 0 to 1'): one value only when
    every material holds that same value."""
    if len(maps) == 1:
        return constant_channels(maps[0])
    per = [constant_channels(m) for m in maps]
    out = {}
    for name in ("roughness", "metallic"):
        values = [d[name].choice for d in per]
        if all(v != "map" for v in values) and max(values) - min(values) <= CONSTANT_TOLERANCE:
            out[name] = Decision(values[0], f"every material's {name} is the constant {values[0]:g}")
        else:
            kinds = ", ".join(f"'{n}' {'a map' if v == 'map' else f'{v:g}'}" for n, v in zip(names, values))
            out[name] = Decision("map", f"the materials' {name} differ ({kinds}): baked as a map")
    return out


def texture_size_for_screen(screen_px: int) -> int:
    """Texels across the texture for an object `screen_px` pixels tall in the composite.

    About half of the surface faces the camera and the UV layout packs the whole surface into the
    texture, so one screen pixel per texel needs about twice the object's on-screen size; rounded
    up to a power of two.
    """
    return 2 ** math.ceil(math.log2(max(8, 2 * int(screen_px))))


def envmap_height_for(maps: PBRMaps, covered: np.ndarray | None = None) -> Decision:
    """Rows of the environment map the asset's glossiest parts can resolve.

    A GGX lobe of roughness r (alpha = r^2) is about alpha radians wide; a map whose texel (pi / H)
    is half that shows every reflection sharp enough: H = 2 pi / alpha, as a power of two within
    ENVMAP_HEIGHTS. A rough asset needs a small map; a mirror the largest. covered: (H, W) bool of
    the texels the mesh uses (the rest of a map is padding and says nothing about the surface).
    """
    rough = maps.roughness
    if isinstance(rough, np.ndarray):
        used = rough
        if covered is not None:
            import cv2  # lazy: Blender may lack OpenCV (missing_modules)

            mask = cv2.resize(covered.astype(np.uint8), rough.shape[::-1], interpolation=cv2.INTER_NEAREST) > 0
            used = rough[mask] if mask.any() else rough
        r = float(np.percentile(used, GLOSSIEST_PERCENTILE))
    else:
        r = float(rough)
    alpha = max(r * r, 1e-4)
    low, high = ENVMAP_HEIGHTS
    height = int(min(high, max(low, 2 ** math.ceil(math.log2(2 * math.pi / alpha)))))
    where = "constant" if not isinstance(rough, np.ndarray) else f"{GLOSSIEST_PERCENTILE:g}th percentile"
    return Decision(height, f"the asset's glossiest roughness ({where}) is {r:.3g}: its reflections resolve "
                            f"{math.degrees(alpha):.2g} deg, so a {height}x{2 * height} map is enough")
