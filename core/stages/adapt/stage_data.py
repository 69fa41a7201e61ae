"""What the adapt stage works on and what it gives back: AdaptInputs (validated against the config) and
AdaptResult (the adapted texture, its history, timings and decisions; what write_adapt reports)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from ...base.decision import Decision
from ...base.errors import InputError
from ...data.mesh import Mesh
from ...data.uv_raster import UVRaster
from ...scene.camera import PhotoCamera
from ...scene.placement import Placement
from ...texture.neural_texture import NeuralTexture
from ...texture.surface_layout import SurfaceLayout
from .config import AdaptConfig


@dataclass
class AdaptInputs:
    """What the stage works on. mesh: normalised (radius 0.5); raster: its UV raster at the texture's
    resolution; texture: the converted neural texture (None only for "generate"); photo: sRGB float
    (H, W, 3) in [0, 1] and placement ("scene"); envmap: (He, 2He, 3) linear ("envmap" light);
    photo_camera: the light stage's camera for the photo (None: the light stage's default for it);
    base_logit: the texture's base for `raster` when it is not the texture's own layout, and `layout`
    that layout (core.surface_layout: the asset's UVs share texels, so adaptation works in new ones)."""

    mesh: Mesh
    raster: UVRaster
    texture: NeuralTexture | None = None
    photo: np.ndarray | None = None
    placement: Placement | None = None
    envmap: np.ndarray | None = None
    photo_camera: PhotoCamera | None = None
    base_logit: torch.Tensor | None = None
    layout: SurfaceLayout | None = None

    def validate(self, config: AdaptConfig) -> None:
        if config.mode_type != "generate" and self.texture is None:
            raise InputError(f"Mode '{config.mode_type}' adapts an existing texture; convert the asset first.")
        if config.views_type == "local+global":
            if self.photo is None or self.placement is None:
                raise InputError("Scene-conditional adaptation needs the photo and where the object goes in it.")
            photo = np.asarray(self.photo)
            if photo.ndim != 3 or photo.shape[2] != 3 or min(photo.shape[:2]) < 8:
                raise InputError(f"The photo must be an RGB image of at least 8x8 pixels, got {photo.shape}.")
        if config.light_type == "envmap" and self.envmap is None:
            raise InputError("light_type 'envmap' needs an environment map (e.g. the estimated HDR map).")
        if self.texture is not None and self.texture.config.resolution != self.raster.resolution[0]:
            raise InputError(f"The texture is {self.texture.config.resolution}² but the UV raster is "
                             f"{self.raster.resolution[0]}²; rasterise at the texture's resolution.")


@dataclass
class AdaptResult:
    texture: NeuralTexture
    iterations: int
    seconds: float
    history: list[dict]
    timings: dict[str, float]           # seconds summed over the iterations run here, per phase
    resumed_from: int = 0
    decisions: dict[str, Decision] = field(default_factory=dict)
    peak_memory_mb: float | None = None
    # for write_adapt, set by adapt_and_bake: the config, the asset's own UV raster the maps are baked
    # in, and what the UV check decided
    config: AdaptConfig | None = None
    bake_raster: UVRaster | None = None
    uv_report: dict = field(default_factory=dict)

    def seconds_per_iteration(self) -> dict[str, float]:
        n = max(1, self.iterations - self.resumed_from)
        return {k: v / n for k, v in self.timings.items()}
