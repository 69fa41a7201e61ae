"""The adapt step's constant work, done once per view of the bank (core/stages/adapt/sampling.py).

For a bank entry at a stage (render size, samples), these do not depend on the texture being
optimised: the reference render's latents (the frozen reference texture, the entry's camera,
background and seed), the ⟨camera, normal⟩ weights, and for each of the entry's global crops the
inpainting mask and the masked photo's latents (the asset's coverage and its shadow in the photo
from one fixed render, the reference texture's). With `cache` they are computed on the entry's
first use and kept; without, they are computed again every time, by the same code (the test that
both give the same step compares these two).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from ...guidance.views import global_view, latent_mask, local_view, masked_image
from ...guidance.weighting import normal_weight_map
from ...texture.neural_texture import split_channels
from .sampling import ViewSample


@dataclass
class ViewConstants:
    reference_latents: torch.Tensor | None
    weight_map: torch.Tensor | None
    crops: list[tuple[torch.Tensor, torch.Tensor]]     # per crop: (latent mask, masked-photo latents)


class ConstantWork:
    """Computes (and with `cache`, keeps) a view's ViewConstants; `hits` and `misses` count the uses."""

    def __init__(self, system, cache: bool = True) -> None:
        self.system, self.cache = system, cache
        self._kept: dict[tuple, ViewConstants] = {}
        self.hits = self.misses = 0

    def get(self, view: ViewSample, env: torch.Tensor) -> ViewConstants:
        # A view's own light (a random spherical Gaussian) changes the reference: not constant.
        key = None if view.entry is None or view.envmap is not None else (view.entry, view.stage)
        if self.cache and key is not None and key in self._kept:
            self.hits += 1
            return self._kept[key]
        self.misses += 1
        constants = self.compute(view, env)
        if self.cache and key is not None:
            self._kept[key] = constants
        return constants

    @torch.no_grad()
    def compute(self, view: ViewSample, env: torch.Tensor) -> ViewConstants:
        """Rendered before the step's differentiable renders (Mitsuba's backward replays the last one)."""
        s = self.system
        models, config, size = s.models, s.config, s.model_resolution
        reference_latents = weight_map = None
        maps = None if s.reference_stack is None else split_channels(s.reference_stack)
        if maps is not None:
            ref = s.renderer.render(view.camera, *maps, env, spp=view.stage.spp, seed=view.reference_seed)
            reference_latents = models.encode(local_view(ref.rgb, ref.alpha, view.background, size))
        if config.normal_weight_type != "none":
            aov = s.renderer.render_aovs(view.camera)
            weights = normal_weight_map(aov["normal"], aov["coverage"], view.camera.forward,
                                        (s.latent_res, s.latent_res), weight_type=config.normal_weight_type)
            weight_map = None if weights is None else weights.to(s.device)
        crops = []
        if view.crops:
            fixed = maps if maps is not None else split_channels(s.start_stack)
            placed = s.global_scene.render(*fixed, env, view.camera.azimuth_deg, view.stage.render_size,
                                           view.stage.spp, view.reference_seed + 1)
            for crop in view.crops:
                g_image, g_alpha = global_view(placed.rgb, placed.alpha, placed.rect, s.photo, placed.matte, crop,
                                               size)
                crops.append((latent_mask(g_alpha, (s.latent_res,) * 2),
                              models.encode(masked_image(g_image, g_alpha))))
        return ViewConstants(reference_latents, weight_map, crops)


def bank_box(system) -> tuple[tuple[int, int] | None, tuple[float, float, float] | None]:
    """The photo's size and the object's square, what the bank's crops are drawn in."""
    hw = None if system.photo is None else (int(system.photo.shape[0]), int(system.photo.shape[1]))
    box = None if system.global_scene is None else system.global_scene.box
    return hw, box
