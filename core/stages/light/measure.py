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

from ...render.orbit_camera import Camera
from ...data.primitives import uv_sphere
from ...render.renderer import AssetRenderer
from ...scene.frame import blender_direction_to_equirect_uv, equirect_directions, look_frame
from .cues import solid_angles

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
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

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


def mean_radiance(envmap: np.ndarray) -> float:
    """The map's mean radiance over the sphere (texels weighted by their solid angle, channels averaged):
    a plain texel mean over-counts the poles, where an equirectangular map's rows are shortest."""
    weight = solid_angles(*envmap.shape[:2]) * np.ones((1, envmap.shape[1]))
    level = np.asarray(envmap, np.float64).mean(axis=-1)
    return float((level * weight).sum() / weight.sum())


def angular_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    a, b = dominant_direction(estimate), dominant_direction(truth)
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def _resize_like(envmap: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

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


# -- the field's sphere protocol (DiffusionLight / StyleLight evaluation) ------------------------------
# Three spheres seen orthographically from the photo's side, rendered by integrating the map directly
# (no path tracer): noise-free, so estimate and truth differ only by their maps.
PROBE_MATERIALS = ("mirror", "matte", "diffuse")
MATTE_ROUGHNESS = 0.33          # matte silver: GGX alpha = roughness^2, silver's F0 about 0.95
SILVER_F0 = 0.95
DIFFUSE_ALBEDO = 0.8


def sample_envmap(envmap: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Bilinear radiance of a lat-long map along world directions (..., 3), wrapping in u."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    h, w = envmap.shape[:2]
    flat = dirs.reshape(-1, 1, 3)
    uv = blender_direction_to_equirect_uv(flat)
    map_x = (uv[..., 0] * w - 0.5 + 1.0).astype(np.float32)
    map_y = np.clip(uv[..., 1] * h - 0.5, 0, h - 1).astype(np.float32)
    padded = np.concatenate([envmap[:, -1:], envmap, envmap[:, :1]], axis=1).astype(np.float32)
    out = cv2.remap(padded, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(*dirs.shape[:-1], envmap.shape[2])


def probe_geometry(forward: np.ndarray, size: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask (s, s), normals (n, 3), reflected view directions (n, 3)) of a unit sphere seen along `forward`."""
    f, right, up = look_frame(forward)
    xs = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(xs, -xs)
    mask = x ** 2 + y ** 2 < 1.0
    z = np.sqrt(np.maximum(1.0 - x ** 2 - y ** 2, 0.0))[mask]
    normals = x[mask, None] * right + y[mask, None] * up - z[:, None] * f
    reflected = f - 2.0 * (normals @ f)[:, None] * normals
    return mask, normals, reflected


def _lobe_integral(envmap: np.ndarray, axes: np.ndarray, weight) -> np.ndarray:
    """sum over texels of L * weight(axis . texel) * solid angle, normalised per axis, chunked."""
    h, w = envmap.shape[:2]
    dirs = equirect_directions(h, w).reshape(-1, 3).astype(np.float32)
    omega = solid_angles(h, w)[:, 0].astype(np.float32)
    radiance = (envmap.reshape(h, w, -1) * omega[:, None, None]).reshape(-1, envmap.shape[2]).astype(np.float32)
    omega_flat = np.repeat(omega, w)
    out = np.empty((len(axes), envmap.shape[2]), np.float64)
    for start in range(0, len(axes), 512):
        k = weight(np.asarray(axes[start:start + 512], np.float32) @ dirs.T)
        out[start:start + 512] = (k @ radiance) / np.maximum(k @ omega_flat, 1e-30)[:, None]
    return out


def _ggx_weight(cos_r: np.ndarray) -> np.ndarray:
    """GGX D at the half vector between the reflection axis and a texel, times (axis . texel)+ (split sum)."""
    a2 = MATTE_ROUGHNESS ** 4
    c = np.clip(cos_r, -1.0, 1.0)
    cos_h2 = (1.0 + c) / 2.0                      # cos^2 of the half angle
    d = a2 / (np.pi * (cos_h2 * (a2 - 1.0) + 1.0) ** 2)
    return (d * np.maximum(c, 0.0)).astype(np.float32)


def render_probe(envmap: np.ndarray, material: str, forward: np.ndarray, size: int = 64) -> np.ndarray:
    """(size, size, 3) linear radiance of a mirror / matte-silver / diffuse sphere under `envmap`, black outside."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    env = np.ascontiguousarray(np.asarray(envmap, np.float32)[..., :3])
    mask, normals, reflected = probe_geometry(np.asarray(forward, np.float64), size)
    if material == "mirror":
        values = sample_envmap(env, reflected)
    elif material == "matte":
        small = cv2.resize(env, (128, 64), interpolation=cv2.INTER_AREA) if env.shape[0] > 64 else env
        values = SILVER_F0 * _lobe_integral(small, reflected, _ggx_weight)
    elif material == "diffuse":
        small = cv2.resize(env, (64, 32), interpolation=cv2.INTER_AREA) if env.shape[0] > 32 else env
        # The normalised cosine lobe is the irradiance / pi: albedo x that is the outgoing radiance.
        values = DIFFUSE_ALBEDO * _lobe_integral(small, normals, lambda c: np.maximum(c, 0.0))
    else:
        raise ValueError(f"unknown probe material {material!r}")
    image = np.zeros((size, size, 3), np.float32)
    image[mask] = values
    return image


def stylelight_tonemap(image: np.ndarray, mask: np.ndarray, gamma: float = 2.4, percentile: float = 99.0,
                       max_mapping: float = 0.99) -> np.ndarray:
    """StyleLight's TonemapHDR: x^(1/gamma), scaled so the 99th percentile of the sphere maps to 0.99, clipped."""
    powered = np.maximum(image, 0.0) ** (1.0 / gamma)
    inside = powered[mask]
    positive = inside[inside > 0]
    ratio = max_mapping / max(float(np.percentile(positive, percentile)), 1e-12) if positive.size else 1.0
    return np.clip(powered * ratio, 0.0, 1.0)


def rgb_angular_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Mean per-pixel angle between the RGB vectors (the protocol's 'angular error'), in degrees."""
    e, t = np.asarray(estimate, np.float64).reshape(-1, 3), np.asarray(truth, np.float64).reshape(-1, 3)
    cos = (e * t).sum(1) / np.maximum(np.linalg.norm(e, axis=1) * np.linalg.norm(t, axis=1), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())


def probe_scores(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict:
    """RMSE, si-RMSE and angular error over the sphere's pixels, linear and StyleLight-tone-mapped."""
    out = {}
    for form, (e, t) in (("linear", (estimate, truth)),
                         ("tonemapped", (stylelight_tonemap(estimate, mask), stylelight_tonemap(truth, mask)))):
        out[form] = {"rmse": rmse(e[mask], t[mask]), "si_rmse": si_rmse(e[mask], t[mask]),
                     "angular_deg": rgb_angular_error_deg(e[mask], t[mask])}
    return out
