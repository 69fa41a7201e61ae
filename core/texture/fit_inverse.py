"""Fitting a neural texture to an asset's maps by inverse rendering (the paper's conversion).

Both the asset with its own maps and the asset with the neural texture are rendered by Mitsuba from
the same random camera with the same sample seed (so their Monte Carlo noise is correlated and
mostly cancels in the loss); the image-space L2 loss is backpropagated through `dr.wrap` into the
network. Lit by a fixed studio-like environment: a uniform light would make roughness and
metallic almost invisible and so unrecoverable.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np
import torch

from ..render.orbit_camera import Camera
from ..data.mesh import Mesh
from ..base.progress import ProgressCallback, check_cancel, emit
from ..render.renderer import AssetRenderer, SceneOptions
from ..scene.frame import equirect_directions
from .neural_texture import split_channels


def studio_environment(height: int = 64) -> np.ndarray:
    """A fixed, asymmetric studio light: soft ambient, a key light, a fill light and a floor bounce."""
    directions = equirect_directions(height, 2 * height)
    env = np.full((height, 2 * height, 3), 0.25, np.float32)
    lights = (((-0.5, -0.6, 0.6), 12.0, 25.0), ((0.8, -0.2, 0.3), 4.0, 35.0), ((0.2, 0.9, 0.4), 2.0, 40.0))
    for direction, strength, size_deg in lights:
        d = np.asarray(direction) / np.linalg.norm(direction)
        cos = directions @ d
        env += (strength * np.exp((cos - 1.0) / (1.0 - math.cos(math.radians(size_deg)))))[..., None].astype(np.float32)
    env[directions[..., 2] < 0] *= 0.5
    return env


def annealed_lr(iteration: int, total: int, lr_start: float, lr_end: float) -> float:
    """Exponential (log-linear) annealing from lr_start to lr_end over `total` iterations."""
    if total <= 1:
        return lr_start
    t = min(max(iteration / (total - 1), 0.0), 1.0)
    return lr_start * (lr_end / lr_start) ** t


@dataclass
class InverseFitResult:
    seconds: float
    iterations: int
    loss_history: list[float] = field(default_factory=list)
    seconds_per_iteration: float = 0.0


def fit_inverse_rendering(texture_fn: Callable[[], torch.Tensor], parameters: Iterable[torch.nn.Parameter],
                          mesh: Mesh, target: torch.Tensor, iterations: int, lr_start: float = 0.02,
                          lr_end: float = 0.001, render_size: int = 256, spp: int = 16,
                          elevation_range: tuple[float, float] = (-10.0, 45.0), seed: int = 0,
                          progress: ProgressCallback | None = None, cancel: threading.Event | None = None,
                          on_iteration: Callable[[int], None] | None = None) -> InverseFitResult:
    """Optimise `parameters` so that renders of `texture_fn()` match renders of `target` (H, W, 5)."""
    start = time.perf_counter()
    env = studio_environment()
    renderer = AssetRenderer(mesh, tuple(target.shape[:2]), env, SceneOptions(max_depth=3))
    env_t = torch.from_numpy(env)
    optimizer = torch.optim.Adam(list(parameters), lr=lr_start)
    rng = np.random.default_rng(seed)
    history: list[float] = []
    target = target.detach()
    for it in range(iterations):
        check_cancel(cancel)
        for group in optimizer.param_groups:
            group["lr"] = annealed_lr(it, iterations, lr_start, lr_end)
        # A random view around the asset, seen by both renders with the same sample seed.
        camera = Camera(azimuth_deg=float(rng.uniform(0, 360)), elevation_deg=float(rng.uniform(*elevation_range)),
                        fov_multiplier=1.1, width=render_size, height=render_size)
        with torch.no_grad():
            reference = renderer.render(camera, *split_channels(target), env_t, spp=spp, seed=it).rgb
        rendered = renderer.render(camera, *split_channels(texture_fn()), env_t, spp=spp, seed=it).rgb
        loss = torch.nn.functional.mse_loss(rendered, reference)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        history.append(float(loss.detach()))
        if on_iteration is not None:
            on_iteration(it)
        emit(progress, "convert", it + 1, iterations, "inverse rendering", {"loss": history[-1]})
    seconds = time.perf_counter() - start
    return InverseFitResult(seconds=seconds, iterations=iterations, loss_history=history,
                            seconds_per_iteration=seconds / max(iterations, 1))
