"""Orbit cameras around the normalised asset, as in the paper's appendix.

World space is Blender's: Z up, the asset's front faces -Y. Azimuth 0 looks at the front,
positive azimuth turns the camera counter-clockwise seen from above, elevation lifts it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..data.mesh import NORMALIZED_RADIUS
from ..scene.frame import look_frame

CAMERA_DISTANCE = 2.0  # d_cam in the paper


def fov_from_multiplier(fov_multiplier: float, radius: float = NORMALIZED_RADIUS,
                        distance: float = CAMERA_DISTANCE) -> float:
    """Full field of view in degrees for the paper's FOV = tanh(r * lambda_FOV / d), r = 0.5, d = 2.

    tanh(...) is the half-angle in radians. Read as the full angle (14 degrees at lambda = 1) the
    object would be cut at every multiplier the paper uses, even 1.65, which is there "to include
    the full shadow"; as the half-angle, lambda = 1 is the tight framing that separates the paper's
    close-ups (lambda < 1, "detailed close-up renderings of object parts") from whole-object views:
    the view spans +-r * lambda at the target's depth (tanh x = atan x to 0.02% here, so
    d * tan(half-angle) = r * lambda). A whole radius-r sphere bulges slightly past that plane in
    perspective and is inside the view from `whole_object_multiplier()` = 1.033 on.
    """
    if not fov_multiplier > 0:
        raise InputError(f"The FOV multiplier must be positive, got {fov_multiplier}.")
    return math.degrees(2.0 * math.tanh(radius * fov_multiplier / distance))


def whole_object_multiplier(radius: float = NORMALIZED_RADIUS, distance: float = CAMERA_DISTANCE) -> float:
    """The smallest lambda_FOV at which a whole sphere of `radius` (the normalised object's bound) is in
    view: its silhouette's half-angle asin(r / d) equals the view's tanh(r lambda / d)."""
    return math.atanh(math.asin(radius / distance)) * distance / radius


@dataclass(frozen=True)
class Camera:
    azimuth_deg: float = 0.0
    elevation_deg: float = 0.0
    fov_multiplier: float = 1.0
    distance: float = CAMERA_DISTANCE
    width: int = 256
    height: int = 256
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not -90.0 < self.elevation_deg < 90.0:
            raise InputError(f"Camera elevation must be strictly between -90 and 90 degrees, got {self.elevation_deg}.")
        if self.width < 1 or self.height < 1:
            raise InputError(f"Render size must be positive, got {self.width}x{self.height}.")
        if not self.distance > 0:
            raise InputError(f"Camera distance must be positive, got {self.distance}.")
        fov_from_multiplier(self.fov_multiplier)  # validates

    @property
    def fov_deg(self) -> float:
        return fov_from_multiplier(self.fov_multiplier, distance=self.distance)

    @property
    def origin(self) -> np.ndarray:
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        offset = np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
        return np.asarray(self.target, dtype=np.float64) + self.distance * offset

    @property
    def forward(self) -> np.ndarray:
        f = np.asarray(self.target, dtype=np.float64) - self.origin
        return f / np.linalg.norm(f)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (x right, y down; pixel centres at +0.5) of world points in front of the camera."""
        forward, right, up = look_frame(self.forward)
        rel = np.asarray(points, dtype=np.float64) - self.origin
        depth = rel @ forward
        # The FOV applies to the smaller image side (see AssetRenderer._sensor).
        half = np.tan(np.radians(self.fov_deg) / 2) * depth
        scale = min(self.width, self.height) / 2
        x = self.width / 2 + (rel @ right) / half * scale
        y = self.height / 2 - (rel @ up) / half * scale
        return np.stack([x, y], axis=-1)


def orbit_cameras(count: int, elevation_deg: float, fov_multiplier: float = 1.0, size: int = 256,
                  start_deg: float = 0.0) -> list[Camera]:
    """`count` cameras at evenly spaced azimuths (the paper samples 24 around 360 degrees)."""
    if count < 1:
        raise InputError(f"Need at least one view, got {count}.")
    return [Camera(start_deg + 360.0 * i / count, elevation_deg, fov_multiplier, width=size, height=size)
            for i in range(count)]
