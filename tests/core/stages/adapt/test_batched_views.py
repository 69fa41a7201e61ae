"""The views of a step through each model in one pass: the same step as one view (and one crop) at a time.

Two systems built alike, one batching (`train_views`: one VAE pass per kind of view, one UNet pass per
critic and one ε_ψ update over all the step's images) and one not; the same seed, so the same views,
timesteps, noise and ε_ψ draws. Tolerance: the two differ only in float32 rounding (a batched
convolution or matrix product may sum in another order than one image's, the texture's graph is built
once instead of per view; nothing else differs). Measured here: 8e-6 of the gradient's largest entry.
1e-3 leaves room for other BLAS builds and thread counts, and is far below what a missing or doubled
view would change (one view alone differs from the step's gradient by 0.9 of that entry).
"""
from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from scenefit.core.guidance import ModelConfig
from scenefit.core.stages.adapt import AdaptConfig, StageSpec
from scenefit.core.stages.adapt.system import AdaptSystem
from adapt_scenes import sphere_in_a_photo
from conftest import shared_tiny_pair

RELATIVE = 1e-3


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    base, inpaint = shared_tiny_pair()
    inputs = sphere_in_a_photo()
    config = AdaptConfig(prompt="a mossy sphere", iterations=1, stages=(StageSpec(1.0, 32, 2, (30, 990)),),
                         model_resolution=32, views=4, views_per_step=2, global_crops=2, checkpoint_every=0,
                         preview_every=0, renderer="loop",
                         models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type="fp32"))
    return inputs, config


def _one_step(inputs, config, batch: bool) -> tuple[torch.Tensor, dict, dict]:
    system = AdaptSystem.build(inputs, replace(config, batch_views=batch))
    passes = {"vae": 0, "unet": 0, "inpaint": 0}
    encode = system.models.encode

    def counted(images):
        passes["vae"] += 1
        return encode(images)

    system.models.encode = counted
    for name, model in (("unet", system.models.unet), ("inpaint", system.models.inpaint_unet)):
        model.register_forward_hook(lambda *_, name=name: passes.__setitem__(name, passes[name] + 1))
    metrics = system.step(0)
    grad = torch.cat([p.grad.flatten() for p in system.texture.parameters() if p.grad is not None])
    passes["batched steps"] = system.decisions()["batched_views"].choice["steps"]
    return grad, metrics, passes


def test_a_batched_step_gives_the_one_at_a_time_gradient(setup):
    inputs, config = setup
    batched, m_batched, p_batched = _one_step(inputs, config, batch=True)
    alone, m_alone, p_alone = _one_step(inputs, config, batch=False)
    # Both: 6 encodes of constant work (a reference per view, a masked photo per crop; once per bank view).
    # One at a time: 2 local and 4 global encodes; ε_φ and ε_ψ per view, ε_ψ's update per view; a pass per crop.
    assert p_alone == {"vae": 6 + 6, "unet": 6, "inpaint": 4, "batched steps": 0}
    assert p_batched == {"vae": 6 + 2, "unet": 3, "inpaint": 1, "batched steps": 1}
    scale = alone.abs().max()
    assert scale > 0 and (batched - alone).abs().max() <= RELATIVE * scale, float((batched - alone).abs().max() / scale)
    assert m_batched["t"] == m_alone["t"] and len(set(m_alone["t"])) == 2   # two views with their own t
    for key in ("local_grad_norm", "global_grad_norm", "lora_loss"):
        assert m_batched[key] == pytest.approx(m_alone[key], rel=RELATIVE), key


def test_a_run_resumes_with_either_and_the_setting_is_a_boolean(setup):
    """A run that ran out of memory batched goes on from its checkpoint one image at a time: batch_views
    is not part of what a checkpoint must match (the gradients are the same to rounding)."""
    from scenefit.core.base.errors import InputError
    from scenefit.core.stages.adapt.checkpoint import settings_key

    _, config = setup
    assert settings_key(replace(config, batch_views=False)) == settings_key(config)
    assert settings_key(replace(config, iterations=2)) != settings_key(config)
    with pytest.raises(InputError, match="batch_views"):
        replace(config, batch_views="no")
