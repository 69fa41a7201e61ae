"""PBR texture maps of an asset: base colour, roughness, metallic, and the normal map renders use."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError

MapOrConstant = np.ndarray | float

# A tangent-space normal map texel that leaves the surface normal as it is.
FLAT_NORMAL = (0.5, 0.5, 1.0)


def resize_channels(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W) or (H, W, C) float32 resized to (height, width), each channel on its own.

    OpenCV resizes at most four channels at once with INTER_AREA, so a five-channel stack (or a
    2048² RGBA plus maps) is done plane by plane. Area averaging when shrinking, bilinear otherwise.
    """
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    image = np.asarray(image, dtype=np.float32)
    if image.shape[:2] == (height, width):
        return image.copy()
    shrinking = height * width < image.shape[0] * image.shape[1]
    interpolation = cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR
    if image.ndim == 2:
        return cv2.resize(image, (width, height), interpolation=interpolation)
    planes = [cv2.resize(np.ascontiguousarray(image[..., c]), (width, height), interpolation=interpolation)
              for c in range(image.shape[2])]
    return np.stack(planes, axis=2)


@dataclass(frozen=True)
class PBRMaps:
    """The asset's material as the principled BSDF sees it.

    base_color: (H, W, 3) float32, *linear* RGB in [0, 1] (sRGB files are decoded on load).
    roughness, metallic: (H, W) float32 linear maps in [0, 1], or a constant float.
    normal: optional (Hn, Wn, 3) tangent-space normal map as stored (OpenGL convention, [0, 1]
        encoding, Blender's Normal Map strength already applied). Not fitted: renders use it so
        the asset looks like itself, and game export keeps the asset's own normal map.
    Rows run top to bottom as in image files; UV v = 0 is the bottom row.
    """

    base_color: np.ndarray
    roughness: MapOrConstant = 0.5
    metallic: MapOrConstant = 0.0
    normal: np.ndarray | None = None

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
        n = self.normal
        if n is not None and (n.ndim != 3 or n.shape[2] != 3 or not np.isfinite(n).all()):
            raise InputError(f"The normal map must be a finite RGB image, got shape {n.shape}.")

    @property
    def resolution(self) -> tuple[int, int]:
        return self.base_color.shape[0], self.base_color.shape[1]

    @property
    def native_size(self) -> int:
        """The largest side among the fitted maps (base colour, roughness, metallic)."""
        sizes = [max(self.resolution)] + [max(m.shape) for m in (self.roughness, self.metallic)
                                          if isinstance(m, np.ndarray)]
        return max(sizes)

    def channel(self, name: str) -> np.ndarray:
        """A map as an (H, W) array at the base colour's resolution (constants broadcast)."""
        value = getattr(self, name)
        h, w = self.resolution
        if isinstance(value, np.ndarray):
            return value.astype(np.float32)
        return np.full((h, w), float(value), dtype=np.float32)

    def stacked(self) -> np.ndarray:
        """(H, W, 5): base colour RGB, roughness, metallic; maps of other sizes are resampled."""
        return self.stacked_at(*self.resolution)

    def stacked_at(self, height: int, width: int) -> np.ndarray:
        """(height, width, 5) float32, every map resized on its own (never one many-channel resize)."""
        planes = [resize_channels(self.base_color, height, width)]
        for name in ("roughness", "metallic"):
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                planes.append(resize_channels(value, height, width)[..., None])
            else:
                planes.append(np.full((height, width, 1), float(value), np.float32))
        return np.concatenate(planes, axis=2)

    def normal_at(self, height: int, width: int) -> np.ndarray:
        """(height, width, 3) normal map; flat where the material has none."""
        if self.normal is None:
            return np.broadcast_to(np.array(FLAT_NORMAL, np.float32), (height, width, 3)).copy()
        return resize_channels(self.normal, height, width)
