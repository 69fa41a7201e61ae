"""The reference critic: pixel loss against renders of the same views under the true HDR map.

It checks the light-scale machinery without any diffusion model (and is what `bench_light` uses):
if the scales can be found from a perfect critic, a diffusion critic only has to be good enough.
The loss per view is the relative MSE of linear radiance, mean((x - y)^2) / mean(y^2): the paper's
object MSE (what the benchmark reports), made independent of each view's brightness so the view
weights {1/6, 1/6, 1/6, 1/2} keep their meaning. (A log-space loss was tried first: it matched dark
pixels and let a few bright ones overshoot, raising the object MSE it was meant to lower.)
"""
from __future__ import annotations

import numpy as np
import torch

from .hdr import ApparatusScene, CriticRequest


class ReferenceCritic:
    """critic(renders, request) -> (V,) losses against `targets` (V, h, w, 3)."""

    def __init__(self, targets: torch.Tensor) -> None:
        self.targets = targets.detach()

    @classmethod
    def from_true_map(cls, scene: ApparatusScene, true_envmap: np.ndarray, spp: int = 64, seed: int = 7_777) -> "ReferenceCritic":
        """Render the scene's views under the true map (more samples, other seeds than the optimisation)."""
        with torch.no_grad():
            targets, _ = scene.render(torch.from_numpy(np.ascontiguousarray(true_envmap, np.float32)), spp=spp, seed=seed)
        return cls(targets)

    def __call__(self, renders: torch.Tensor, request: CriticRequest | None = None) -> torch.Tensor:
        targets = self.targets
        if request is not None and request.view_indices:
            targets = targets[list(request.view_indices)]
        mse = ((renders - targets) ** 2).flatten(1).mean(dim=1)
        return mse / (targets ** 2).flatten(1).mean(dim=1).clamp_min(1e-12)
