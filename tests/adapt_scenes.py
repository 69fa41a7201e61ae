"""A small adaptation to run with the tiny models: a UV sphere, a fresh 32² neural texture and a noisy photo."""
from __future__ import annotations

import numpy as np

from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.placement import Placement
from scenefit.core.stages.adapt import AdaptInputs
from scenefit.core.texture import NeuralTexture


def sphere_in_a_photo() -> AdaptInputs:
    mesh = uv_sphere(segments=16, rings=8)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=0)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    return AdaptInputs(mesh=mesh, raster=rasterize_uv(mesh, 32), texture=texture, photo=photo,
                       placement=Placement((0.5, 0.6), 0.5))
