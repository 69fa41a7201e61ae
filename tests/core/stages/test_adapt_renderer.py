"""The adapt stage's renderer choice: by default ("auto") the loop renderer where it was measured to agree
with path tracing (local and global views, benchmarks/results/loop_render.md), path tracing elsewhere; "loop" (each bank view's G-buffer traced
once, then shaded every step) or "path" everywhere when asked; the report says which ran and why."""
from __future__ import annotations

import pytest
import torch

from scenefit.core.base.errors import InputError
from scenefit.core.guidance import ModelConfig
from scenefit.core.render.loop_renderer import LoopRenderer
from scenefit.core.stages.adapt import AdaptConfig, StageSpec
from scenefit.core.stages.adapt.system import AdaptSystem
from adapt_scenes import sphere_in_a_photo
from conftest import shared_tiny_pair


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    base, inpaint = shared_tiny_pair()
    inputs = sphere_in_a_photo()
    models = ModelConfig(base_model=str(base), inpaint_model=str(inpaint))
    return inputs, models


def config(models, **overrides) -> AdaptConfig:
    values = dict(prompt="a mossy sphere", iterations=3, stages=(StageSpec(1.0, 32, 2, (500, 990)),),
                  model_resolution=32, views=2, view_variants=1, views_per_step=1, checkpoint_every=0,
                  preview_every=0, lr_texture=1e-2, models=models)
    values.update(overrides)
    return AdaptConfig(**values)


def test_auto_uses_the_loop_renderer_where_it_agrees(setup):
    inputs, models = setup
    cfg = config(models, iterations=1)
    assert cfg.renderer == "auto" and (cfg.renderer_of("local"), cfg.renderer_of("global")) == ("loop", "loop")
    system = AdaptSystem.build(inputs, cfg)
    system.step(0)
    assert isinstance(system.renderer, LoopRenderer) and isinstance(system.global_scene.renderer, LoopRenderer)
    decision = system.decisions()["renderer"]
    assert decision.choice["local"] == "loop" and decision.choice["global"] == "loop"
    assert "35 dB" in decision.reason and "loop_render.md" in decision.reason


def test_the_loop_renderer_traces_each_view_once(setup):
    inputs, models = setup
    cfg = config(models, renderer="loop")
    system = AdaptSystem.build(inputs, cfg)
    start = [p.detach().clone() for p in system.texture.parameters()]
    for i in range(cfg.iterations):
        system.step(i)
    assert isinstance(system.renderer, LoopRenderer) and isinstance(system.global_scene.renderer, LoopRenderer)
    decision = system.decisions()["renderer"]
    # Three steps over a bank of two views: at most two local and two global G-buffers, the rest reused.
    assert decision.choice["local"] == decision.choice["global"] == "loop" and decision.choice["traced"] <= 4
    assert decision.choice["reused"] >= 2 and "traced once" in decision.reason
    # The tracing is its own phase (once per view), not the render's nor the constant work's.
    traced = system.renderer.trace_seconds + system.global_scene.renderer.trace_seconds
    assert traced > 0 and system.timer.totals["trace"] == pytest.approx(traced)
    before = dict(system.timer.totals)
    system.step(cfg.iterations)   # every view of the bank met: nothing more to trace
    assert system.timer.totals["trace"] == before["trace"] and system.timer.totals["render"] > before["render"]
    assert any((a - b).abs().max() > 0 for a, b in zip(start, system.texture.parameters()))
    assert all(torch.isfinite(p).all() for p in system.texture.parameters())


def test_path_tracing_when_asked_and_a_bad_name_refused(setup):
    inputs, models = setup
    system = AdaptSystem.build(inputs, config(models, renderer="path", iterations=1))
    system.step(0)
    choice = system.decisions()["renderer"].choice
    assert choice["local"] == choice["global"] == "path" and "traced" not in choice
    assert not isinstance(system.renderer, LoopRenderer) and system.timer.totals.get("trace", 0.0) == 0.0
    with pytest.raises(InputError, match="renderer"):
        config(models, renderer="raster")


def test_loop_and_path_steps_point_the_same_way(setup):
    """The same view scored through either renderer: the texture gradients agree in direction (the
    renderers agree to ~35 dB, the critic's noise is the same: same seeds; path traced at 256 spp so its
    own noise does not hide the direction)."""
    inputs, models = setup
    grads = {}
    for renderer in ("loop", "path"):   # local views only: one renderer each
        system = AdaptSystem.build(inputs, config(models, renderer=renderer, views_type="local",
                                                  stages=(StageSpec(1.0, 32, 256, (500, 990)),)))
        system.optimizer.zero_grad(set_to_none=True)
        system.train_view(system.sample(0, 0))
        grads[renderer] = torch.cat([p.grad.flatten() for p in system.texture.parameters() if p.grad is not None])
    cos = torch.nn.functional.cosine_similarity(grads["loop"].double(), grads["path"].double(), dim=0).item()
    assert cos > 0.8, cos
