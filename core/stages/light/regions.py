"""Bright regions of the LDR map: the texels whose radiance the HDR scales multiply (paper §3.4).

Indoors:  far  = {D >= tau_d and I >= tau_f},   near = {D < tau_d and I >= tau_n}
Outdoors: far  = {row / H < 0.5 (upper half) or I >= tau_o},   near = {} (no near light)

I is the texel's intensity in the LDR map as stored (sRGB-encoded, [0, 1]): the mean of R, G, B.
D is the distance from the object to the surface the texel shows (inf where unknown).

Thresholds. The appendix prints "tau_f = 0.8, tau_f = 0.95, tau_o = 0.9, tau_d = +inf", one
subscript being a typo. We read it as tau_n = 0.8 (near) and tau_f = 0.95 (far) because with
tau_d = +inf every texel of finite depth is "near", so the near threshold is the one that acts
indoors, and §3.4 gives exactly 0.8 as its example ("where intensity I >= 0.8"); a far threshold
of 0.95 only matters for texels of unknown (infinite) depth, for which a stricter test is safer.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...base.errors import InputError

@dataclass(frozen=True)
class RegionThresholds:
    far: float = 0.95          # tau_f
    near: float = 0.8          # tau_n
    outdoor: float = 0.9       # tau_o
    distance: float = float("inf")  # tau_d

    def __post_init__(self) -> None:
        for name in ("far", "near", "outdoor"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise InputError(f"The {name} intensity threshold must be in [0, 1], got {getattr(self, name)}.")
        if not self.distance > 0:
            raise InputError(f"The distance threshold must be positive, got {self.distance}.")


def intensity(ldr: np.ndarray) -> np.ndarray:
    return np.asarray(ldr, np.float32)[..., :3].mean(axis=-1)


def bright_regions(ldr: np.ndarray, distance: np.ndarray | None, scene_type: str,
                   thresholds: RegionThresholds = RegionThresholds()) -> dict[str, np.ndarray]:
    """Boolean (H, W) masks of the light regions that exist (an empty region gets no entry, hence no scale)."""
    level = intensity(ldr)
    h = level.shape[0]
    if scene_type == "indoor":
        d = np.full(level.shape, np.inf, np.float32) if distance is None else np.asarray(distance)
        far = (d >= thresholds.distance) & (level >= thresholds.far)
        near = (d < thresholds.distance) & (level >= thresholds.near)
        regions = {"far": far, "near": near}
    elif scene_type == "outdoor":
        rows = np.arange(h)[:, None] / h   # the paper's i / H_e < 0.5, i counted from the top row
        regions = {"far": (rows < 0.5) | (level >= thresholds.outdoor)}
    else:
        raise InputError(f"scene_type must be 'indoor' or 'outdoor', got {scene_type!r}.")
    return {name: mask for name, mask in regions.items() if mask.any()}
