"""The adapt stage's maths, checked against the known-answer prior (devtools/prior, devtools/known_prior.py).

Each test runs the real stage (the real critics, renderer and models' loading) on a small sphere with the
committed prior and asserts the texture moves toward the colour the prior was taught: a colour word's
(text rule) or the photo's hue (scene rule, the inpainting critic's). Random weights would pass a test
that only checks shapes; these fail when a sign, the guidance, the mask or the weighting is wrong
(docs/engineers/testing.md lists what was broken on purpose and seen to fail).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.guidance import CriticConfig, ModelConfig, load_guidance_models
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.placement import Placement
from scenefit.core.stages.adapt import AdaptConfig, AdaptInputs, StageSpec, adapt_texture
from scenefit.core.texture import NeuralTexture
from scenefit.devtools.known_prior import COLOURS, answer, distance, hue_deg, toward_hue

PRIOR = Path(__file__).resolve().parents[4] / "devtools" / "prior"
STAGES = (StageSpec(1.0, 32, 2, (300, 980)),)


@pytest.fixture(scope="module")
def prior():
    """The committed prior, loaded once: (models, ModelConfig)."""
    config = ModelConfig(base_model=str(PRIOR / "base"), inpaint_model=str(PRIOR / "inpaint"), dtype_type="fp32")
    return load_guidance_models(config, need_inpaint=True), config


@pytest.fixture(scope="module")
def sphere():
    mesh = uv_sphere(segments=16, rings=8)
    return mesh, rasterize_uv(mesh, 32)


def _texture(seed: int = 0) -> NeuralTexture:
    return NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=seed)


def texel_colour(texture: NeuralTexture, raster) -> np.ndarray:
    """The mean sRGB base colour over the texels the mesh covers."""
    with torch.no_grad():
        maps = texture.texture(raster.position, raster.border, raster.fill_index)[..., :3].numpy()
    return linear_to_srgb(np.clip(maps[np.asarray(raster.mask)], 0.0, 1.0)).mean(axis=0)


def _run(prior, sphere, mode: str, prompt: str = "", iterations: int = 40, photo=None, texture=None, **settings):
    models, model_config = prior
    mesh, raster = sphere
    critic = settings.pop("critic", CriticConfig(critic_type="sds", reference_type="none"))
    values = dict(mode_type=mode, prompt=prompt, iterations=iterations, stages=STAGES, views=8, views_per_step=1,
                  lr_texture=2e-2, checkpoint_every=0, preview_every=0, critic=critic, models=model_config,
                  views_type="local+global" if photo is not None else "local")
    values.update(settings)
    config = AdaptConfig(**values)
    inputs = AdaptInputs(mesh=mesh, raster=raster, texture=texture if mode != "generate" else None, photo=photo,
                         placement=Placement((0.5, 0.65), 0.45) if photo is not None else None)
    # A handle of its own (as ModelCache gives each job): the stage releases its handle's text encoder.
    return adapt_texture(inputs, config, models=replace(models, _embeddings=dict(models._embeddings)))


def _start(sphere, mode: str, texture=None):
    mesh, raster = sphere
    if mode == "generate":
        return texel_colour(_texture(), raster)   # the fresh texture generate starts from (seed 0)
    return texel_colour(texture, raster)


def _ratio(sphere, result, start, target) -> float:
    """The run's distance to `target` as a fraction of the start's."""
    return distance(texel_colour(result.texture, sphere[1]), target) / distance(start, target)


def test_sds_moves_a_fresh_texture_to_the_colour_the_prompt_names(prior, sphere):
    start = _start(sphere, "generate")
    result = _run(prior, sphere, "generate", "a blue fox")   # "fox": a noun the prior never saw
    assert _ratio(sphere, result, start, COLOURS["blue"]) < 0.5


def test_vsd_moves_the_texture_and_its_lora_critic_learns(prior, sphere):
    start = _start(sphere, "generate")
    result = _run(prior, sphere, "generate", "a blue truck", iterations=60,
                  critic=CriticConfig(critic_type="vsd", reference_type="none", lambda_end=1.0))
    assert _ratio(sphere, result, start, COLOURS["blue"]) < 0.6
    losses = [h["lora_loss"] for h in result.history]
    assert np.mean(losses[-15:]) < np.mean(losses[:15]), "ε_ψ's LoRA loss did not fall"


def test_classifier_free_guidance_is_what_carries_the_colour_word(prior, sphere):
    """At guidance 7.5 the texture reaches the named colour; with guidance 0 (the unconditional model only)
    it does not get as close: the colour comes from the conditional minus the unconditional branch."""
    start = _start(sphere, "generate")
    guided = _run(prior, sphere, "generate", "a yellow cabinet")
    unguided = _run(prior, sphere, "generate", "a yellow cabinet",
                    critic=CriticConfig(critic_type="sds", reference_type="none", guidance_scale=0.0))
    target = COLOURS["yellow"]
    assert _ratio(sphere, guided, start, target) < 0.5
    assert _ratio(sphere, guided, start, target) < 0.7 * _ratio(sphere, unguided, start, target)


def test_edit_mode_makes_the_texture_the_colour_the_instruction_names(prior, sphere):
    texture = _texture(seed=3)
    start = _start(sphere, "edit", texture)
    result = _run(prior, sphere, "edit", object_prompt="a knight", instruction="make it yellow", texture=texture,
                  critic=CriticConfig(critic_type="sds", reference_type="none"))
    assert answer(result.decisions["prompt"].choice) == COLOURS["yellow"]
    assert _ratio(sphere, result, start, COLOURS["yellow"]) < 0.5


def test_reference_injection_keeps_the_edit_on_its_answer(prior, sphere):
    """Edit mode with the reference's keys and values injected (the paper's identity preservation) still
    reaches the named colour, and the injection is live (every self-attention layer)."""
    texture = _texture(seed=3)
    start = _start(sphere, "edit", texture)
    result = _run(prior, sphere, "edit", "a shoe, blue", texture=texture,
                  critic=CriticConfig(critic_type="sds", reference_type="inject"))
    assert result.decisions["reference_injection"].choice > 0
    assert _ratio(sphere, result, start, COLOURS["blue"]) < 0.6


def test_batched_views_move_the_texture_as_one_view_at_a_time_does(prior, sphere):
    start = _start(sphere, "generate")
    batched = _run(prior, sphere, "generate", "a white helicopter", iterations=25, views_per_step=2, renderer="loop")
    assert batched.decisions["batched_views"].choice["steps"] == 25
    assert _ratio(sphere, batched, start, COLOURS["white"]) < 0.5


def test_the_loop_renderer_carries_the_critics_gradient_into_the_texture(prior, sphere):
    start = _start(sphere, "generate")
    result = _run(prior, sphere, "generate", "a yellow diorama", renderer="loop")
    assert result.decisions["renderer"].choice["local"] == "loop"
    assert _ratio(sphere, result, start, COLOURS["yellow"]) < 0.5


def _tinted_photo(hue: float) -> np.ndarray:
    from scenefit.devtools.known_prior import hsv_to_rgb

    rng = np.random.default_rng(7)
    photo = np.empty((48, 64, 3), np.float32)
    photo[:24] = hsv_to_rgb(hue, 0.45, 0.85)
    photo[24:] = hsv_to_rgb(hue + 10, 0.55, 0.55)
    return np.clip(photo + rng.normal(0, 0.02, photo.shape), 0, 1).astype(np.float32)


def test_the_inpainting_critic_paints_the_object_in_the_photos_hue(prior, sphere):
    """Scene mode, no colour word: the object's base colour turns toward the hue of the photo around it
    (the inpainting critic's mask marks the object, the region it paints)."""
    photo = _tinted_photo(200.0)   # a blue-cyan scene
    texture = _texture(seed=5)
    start = _start(sphere, "scene", texture)
    result = _run(prior, sphere, "scene", "a fox", photo=photo, texture=texture, iterations=40,
                  critic=CriticConfig(critic_type="sds", reference_type="none"), global_crops=2)
    hue = hue_deg(photo.reshape(-1, 3).mean(0))
    gap, moved = toward_hue(start, texel_colour(result.texture, sphere[1]), hue)
    # (from grey: the hue it takes is the photo's side of the colour wheel, its chroma grown toward it)
    assert moved > 0.05 and gap < 45.0, (gap, moved)
