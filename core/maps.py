"""PBR texture maps of an asset: base colour, roughness, metallic."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError

MapOrConstant = np.ndarray | float


@dataclass(frozen=True)
class PBRMaps:
    """The asset's material as the principled BSDF sees it.

    base_color: (H, W, 3) float32, *linear* RGB in [0, 1] (sRGB files are decoded on load).
    roughness, metallic: (H, W) float32 linear maps in [0, 1], or a constant float.
    Rows run top to bottom as in image files; UV v = 0 is the bottom row.
    """

    base_color: np.ndarray
    roughness: MapOrConstant = 0.5
    metallic: MapOrConstant = 0.0

    def __post_init__(self) -> None:
        bc = self.base_color
        if bc.ndim != 3 or bc.shape[2] != 3 or min(bc.shape[:2]) < 1:
            raise InputError(f"Base colour must be an RGB image, got an array of shape {bc.shape}.")
        for name in ("roughness", "metallic"):
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                if value.ndim != 2:
                    raise InputError(f"The {name} map must be a single-channel image, got shape {value.shape}.")
                if not np.isfinite(value).all():
                    raise InputError(f"The {name} map holds NaN or infinite values.")
            elif not 0.0 <= float(value) <= 1.0:
                raise InputError(f"The {name} value {value} is outside [0, 1].")
        if not np.isfinite(bc).all():
            raise InputError("The base colour image holds NaN or infinite values.")

    @property
    def resolution(self) -> tuple[int, int]:
        return self.base_color.shape[0], self.base_color.shape[1]

    def channel(self, name: str) -> np.ndarray:
        """A map as an (H, W) array at the base colour's resolution (constants broadcast)."""
        value = getattr(self, name)
        h, w = self.resolution
        if isinstance(value, np.ndarray):
            return value.astype(np.float32)
        return np.full((h, w), float(value), dtype=np.float32)

    def stacked(self) -> np.ndarray:
        """(H, W, 5): base colour RGB, roughness, metallic; maps of other sizes are resampled."""
        import cv2

        h, w = self.resolution
        planes = [self.base_color.astype(np.float32)]
        for name in ("roughness", "metallic"):
            plane = self.channel(name)
            if plane.shape != (h, w):
                plane = cv2.resize(plane, (w, h), interpolation=cv2.INTER_LINEAR)
            planes.append(plane[..., None])
        return np.concatenate(planes, axis=2)
