"""Renders of an asset's map stacks from orbit cameras, and the display helpers around them (tone map,
PSNR, a labelled contact sheet): what `scenefit render`, the demo and the benchmarks show."""
from __future__ import annotations

import threading

import numpy as np
import torch

from ..base.progress import ProgressCallback, check_cancel, emit
from ..data.imageio import linear_to_srgb
from ..data.mesh import Mesh
from .neural_texture import split_channels
from ..render.orbit_camera import Camera
from ..render.renderer import AssetRenderer, SceneOptions


def tonemap_srgb(rgb: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear radiance -> display sRGB in [0, 1] (exposure, clip, sRGB curve)."""
    return linear_to_srgb(np.clip(np.asarray(rgb) * exposure, 0.0, 1.0))


def render_views(normalized_mesh: Mesh, stacks: dict[str, torch.Tensor], envmap: np.ndarray,
                 cameras: list[Camera], spp: int, progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None,
                 normal_map: np.ndarray | None = None) -> dict[str, list[np.ndarray]]:
    """Render every (H, W, 5) map stack from every camera with one scene; linear RGB images.

    normal_map: the asset's tangent-space normal map (PBRMaps.normal), used by every render: it is
    not fitted, so the original and the neural texture are shown on the same bumps."""
    shapes = {tuple(s.shape[:2]) for s in stacks.values()}
    images: dict[str, list[np.ndarray]] = {name: [] for name in stacks}
    env_t = torch.from_numpy(envmap)
    renderers = {shape: AssetRenderer(normalized_mesh, shape, envmap, SceneOptions(integrator_type="path"),
                                      normal_map=normal_map)
                 for shape in shapes}
    total, done = len(stacks) * len(cameras), 0
    with torch.no_grad():
        for name, stack in stacks.items():
            renderer = renderers[tuple(stack.shape[:2])]
            for i, camera in enumerate(cameras):
                check_cancel(cancel)
                out = renderer.render(camera, *split_channels(stack), env_t, spp=spp, seed=i)
                images[name].append(out.rgb.numpy())
                done += 1
                emit(progress, "render", done, total, f"{name} view {i + 1}")
    return images


def image_psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB between two display images in [0, 1]."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def contact_sheet(rows: dict[str, list[np.ndarray]], label_height: int = 22) -> np.ndarray:
    """A grid image (one labelled row per entry) of sRGB [0, 1] images."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    strips = []
    for label, images in rows.items():
        strip = np.concatenate(images, axis=1)
        band = np.full((label_height, strip.shape[1], 3), 0.12, np.float32)
        cv2.putText(band, label, (6, label_height - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0.95, 0.95, 0.95), 1,
                    cv2.LINE_AA)
        strips.append(np.concatenate([band, strip], axis=0))
    return np.concatenate(strips, axis=0)
