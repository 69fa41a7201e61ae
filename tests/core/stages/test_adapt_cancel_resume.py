"""A cancel inside an adapt step stops between its views and keeps the steps made so far as a checkpoint,
which a run with the same settings resumes from (the step count goes on), bit for bit on one thread."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import torch

from scenefit.core.base.errors import Cancelled
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.guidance import ModelConfig
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.placement import Placement
from scenefit.core.stages.adapt import AdaptConfig, AdaptInputs, AdaptSystem, StageSpec, adapt_texture
from scenefit.core.stages.adapt.checkpoint import CHECKPOINT_FILE
from scenefit.core.texture import NeuralTexture
from conftest import shared_tiny_pair


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory):
    return shared_tiny_pair()


@pytest.fixture
def one_render_thread():
    import drjit as dr

    before = dr.thread_count()
    dr.set_thread_count(1)
    yield
    dr.set_thread_count(before)


def _setup(tiny_models):
    mesh = uv_sphere(segments=16, rings=8)
    raster = rasterize_uv(mesh, 32)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=0)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    base, inpaint = tiny_models
    # No periodic checkpoint: what a cancel keeps is the cancel's own.
    config = AdaptConfig(prompt="a mossy sphere", iterations=2, stages=(StageSpec(1.0, 16, 2, (30, 990)),),
                         model_resolution=32, views=4, views_per_step=2, checkpoint_every=0, preview_every=0,
                         models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))
    inputs = AdaptInputs(mesh=mesh, raster=raster, texture=texture, photo=photo, placement=Placement((0.5, 0.6), 0.5))
    return inputs, config, raster


def test_a_cancel_mid_step_stops_between_views_and_resume_continues_the_count(tiny_models, tmp_path, monkeypatch,
                                                                               one_render_thread):
    inputs, config, raster = _setup(tiny_models)
    whole = adapt_texture(inputs, config)
    with torch.no_grad():
        expected = whole.texture.texture(raster.position, raster.border, raster.fill_index)

    cancel, views, asked = threading.Event(), [], []
    render_view = AdaptSystem.render_view   # every view of a step, batched or one at a time, is rendered here

    def counted(self, view, *args):
        views.append(len(views))
        rendered = render_view(self, view, *args)
        if len(views) == 3:   # the first view of the second step: cancel before its second view
            cancel.set()
            asked.append(time.perf_counter())
        return rendered

    monkeypatch.setattr(AdaptSystem, "render_view", counted)
    with pytest.raises(Cancelled):
        adapt_texture(inputs, config, cancel=cancel, checkpoint_dir=tmp_path)
    stopped = time.perf_counter() - asked[0]
    assert len(views) == 3, "a view ran after the cancel"
    assert stopped < 5.0
    checkpoint = torch.load(tmp_path / CHECKPOINT_FILE, map_location="cpu", weights_only=True)
    assert checkpoint["iteration"] == 1 and len(checkpoint["history"]) == 1   # the finished step, not the half one

    monkeypatch.setattr(AdaptSystem, "render_view", render_view)
    resumed = adapt_texture(inputs, config, checkpoint_dir=tmp_path)
    assert resumed.resumed_from == 1 and len(resumed.history) == config.iterations
    with torch.no_grad():
        got = resumed.texture.texture(raster.position, raster.border, raster.fill_index)
    assert torch.equal(got, expected)   # the half-made step left no trace


def test_a_cancel_is_seen_inside_a_unet_pass(tiny_models):
    """A view's UNet pass takes tens of seconds on a CPU at the presets' sizes: each of its blocks (and the VAE's)
    checks the cancel, so a cancel set during a pass ends it at the next block, not at the view's end; the hooks
    go with the step, so a later pass runs whole."""
    from scenefit.core.guidance.models import load_guidance_models
    from scenefit.core.stages.adapt.system import cancel_hooks

    base, inpaint = tiny_models
    models = load_guidance_models(ModelConfig(base_model=str(base), inpaint_model=str(inpaint)), need_inpaint=True)
    cancel, entered = threading.Event(), []
    first_block = models.unet.down_blocks[0]
    spy = first_block.register_forward_pre_hook(lambda module, args: (entered.append(1), cancel.set()))
    hooks = cancel_hooks(models, cancel)
    latents = torch.zeros(1, 4, 4, 4, dtype=models.dtype)
    text = torch.zeros(1, 77, models.unet.config.cross_attention_dim, dtype=models.dtype)
    with torch.no_grad(), pytest.raises(Cancelled):
        models.unet(latents, 10, encoder_hidden_states=text)   # cancel set as the first block starts
    assert entered == [1] and len(hooks) >= len(models.unet.down_blocks) * 2
    for hook in hooks + [spy]:
        hook.remove()
    with torch.no_grad():
        assert models.unet(latents, 10, encoder_hidden_states=text).sample.shape == latents.shape
