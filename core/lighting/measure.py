"""How close an estimated HDR map is to the true one, as light-estimation papers measure it.

- RMSE and scale-invariant RMSE (si-RMSE: the estimate multiplied by the least-squares scalar first)
  of a diffuse and of a glossy sphere rendered under the estimated versus the true map;
- the angular error (degrees) of the dominant light direction: the direction of the brightest texel of
  each map after a Gaussian blur of the solid-angle-weighted luminance;
- the paper's MSE of the object rendered under the estimated versus the true map.

Renders use the same camera, seed and sample count for both maps so that noise mostly cancels.
"""
from __future__ import annotations

import numpy as np
import torch

from ..camera import Camera
from ..primitives import uv_sphere
from ..render import AssetRenderer, equirect_directions

LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)
MATERIALS = {"diffuse": (0.8, 1.0, 0.0), "glossy": (0.9, 0.15, 1.0)}   # base colour, roughness, metallic


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def si_rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMSE after scaling the estimate by argmin_a ||a * estimate - truth||^2."""
    e, t = np.asarray(estimate, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    a = float(e @ t / max(e @ e, 1e-30))
    return rmse(a * e, t)


def dominant_direction(envmap: np.ndarray, blur_fraction: float = 1 / 32) -> np.ndarray:
    """Unit world direction of the map's brightest (blurred, solid-angle weighted) luminance."""
    import cv2

    h, w = envmap.shape[:2]
    lum = (np.asarray(envmap, np.float32)[..., :3] @ LUMINANCE)
    rows = (np.arange(h) + 0.5) / h
    lum = lum * np.sin(np.pi * rows)[:, None].astype(np.float32)
    sigma = max(0.5, w * blur_fraction)
    pad = int(3 * sigma) + 1
    wrapped = np.concatenate([lum[:, -pad:], lum, lum[:, :pad]], axis=1)
    blurred = cv2.GaussianBlur(wrapped, (0, 0), sigma)[:, pad:pad + w]
    r, c = np.unravel_index(int(np.argmax(blurred)), blurred.shape)
    return equirect_directions(h, w)[r, c]


def angular_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    a, b = dominant_direction(estimate), dominant_direction(truth)
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def _resize_like(envmap: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    import cv2

    if envmap.shape[:2] == tuple(shape):
        return np.ascontiguousarray(envmap, np.float32)
    return cv2.resize(np.ascontiguousarray(envmap, np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA)


class SphereProbe:
    """Diffuse and glossy spheres seen from the photo's direction, rendered under any map of one size."""

    def __init__(self, envmap_shape: tuple[int, int], azimuth_deg: float = 0.0, elevation_deg: float = 10.0,
                 size: int = 48, spp: int = 64) -> None:
        tex = (4, 4)
        self.renderer = AssetRenderer(uv_sphere(radius=0.5, segments=32, rings=16), tex,
                                      np.full((*envmap_shape, 3), 0.5, np.float32))
        self.camera = Camera(azimuth_deg=azimuth_deg, elevation_deg=elevation_deg, width=size, height=size)
        self.shape, self.spp, self.tex = envmap_shape, spp, tex

    def render(self, envmap: np.ndarray, material: str) -> np.ndarray:
        base, rough, metal = MATERIALS[material]
        h, w = self.tex
        env = torch.from_numpy(_resize_like(envmap, self.shape))
        with torch.no_grad():
            out = self.renderer.render(self.camera, torch.full((h, w, 3), base), torch.full((h, w, 1), rough),
                                       torch.full((h, w, 1), metal), env, spp=self.spp, seed=11)
        return out.rgb.numpy()


def compare_maps(estimate: np.ndarray, truth: np.ndarray, probe: SphereProbe) -> dict:
    """Sphere RMSE/si-RMSE (diffuse, glossy) and dominant-light angular error of estimate vs truth."""
    out = {}
    for material in ("diffuse", "glossy"):
        e, t = probe.render(estimate, material), probe.render(truth, material)
        out[f"{material}_rmse"] = rmse(e, t)
        out[f"{material}_si_rmse"] = si_rmse(e, t)
    out["dominant_angle_deg"] = angular_error_deg(estimate, truth)
    return out


def object_mse(renderer_render, estimate: np.ndarray, truth: np.ndarray) -> float:
    """The paper's measure: MSE between renders (same views, same seed) under the estimated and true maps.

    renderer_render(envmap_tensor) -> (V, h, w, 3) radiance, e.g. `lambda e: scene.render(e, spp, seed)[0]`.
    """
    with torch.no_grad():
        e = renderer_render(torch.from_numpy(np.ascontiguousarray(estimate, np.float32)))
        t = renderer_render(torch.from_numpy(np.ascontiguousarray(truth, np.float32)))
    return float(torch.mean((e - t) ** 2))
