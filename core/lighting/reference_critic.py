"""The reference critic: pixel loss against renders of the same views under the true HDR map.

It checks the light-scale machinery without any diffusion model (and is what `bench_light` uses):
if the scales can be found from a perfect critic, a diffusion critic only has to be good enough.
The loss is the mean squared difference of log(1 + radiance), so very dark and very bright views
both give gradients (linear MSE would be ruled by the brightest pixels, x/(1+x) flattens at 1e4).
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
        diff = torch.log1p(renders.clamp_min(0.0)) - torch.log1p(self.targets)
        return (diff ** 2).flatten(1).mean(dim=1)
