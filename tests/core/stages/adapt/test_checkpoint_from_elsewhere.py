"""A checkpoint found in a run folder is data: one made for another asset (same settings) is refused in
one sentence rather than resumed, and a planted one without its settings, with an iteration of text, or of
any other shape gives one sentence, never a KeyError or TypeError. Fuzzed."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.core.base.errors import InputError
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.guidance import ModelConfig
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.stages.adapt import AdaptConfig, AdaptInputs, StageSpec, adapt_texture
from scenefit.core.stages.adapt.checkpoint import CHECKPOINT_FILE, CHECKPOINT_FORMAT, load_checkpoint, settings_key
from scenefit.core.texture import NeuralTexture
from conftest import shared_tiny_pair

FUZZ = settings(derandomize=True, max_examples=60, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _inputs(segments: int):
    mesh = uv_sphere(segments=segments, rings=8)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=0)
    return AdaptInputs(mesh=mesh, raster=rasterize_uv(mesh, 32), texture=texture)


def _config() -> AdaptConfig:
    base, inpaint = shared_tiny_pair()
    return AdaptConfig(prompt="a mossy sphere", views_type="local", iterations=1,
                       stages=(StageSpec(1.0, 16, 2, (30, 990)),), model_resolution=32, views=2, views_per_step=1,
                       checkpoint_every=1, preview_every=0,
                       models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))


def test_another_assets_checkpoint_is_not_resumed(tmp_path):
    """The same settings, another asset: its finished checkpoint was resumed (no step of this asset's ran) and
    nothing said; the run starts fresh, and its own checkpoint resumes."""
    config = _config()
    adapt_texture(_inputs(16), config, checkpoint_dir=tmp_path)
    assert (tmp_path / CHECKPOINT_FILE).is_file()
    other = adapt_texture(_inputs(12), config, checkpoint_dir=tmp_path)
    assert other.resumed_from == 0 and len(other.history) == config.iterations
    assert adapt_texture(_inputs(12), config, checkpoint_dir=tmp_path).resumed_from == 1   # its own resumes


def _good_payload(config: AdaptConfig) -> dict:
    return {"format": CHECKPOINT_FORMAT, "iteration": 0, "settings": settings_key(config), "inputs": "",
            "texture_config": {}, "texture": {"w": torch.zeros(2)}, "optimizer": {"state": {}, "param_groups": []},
            "lora": None, "history": []}


@pytest.mark.parametrize("change", [{"settings": None}, {"iteration": "abc"}, {"iteration": 10**9},
                                    {"history": "x"}, {"texture": [1, 2]}])
def test_a_planted_checkpoint_of_another_shape_is_one_sentence(tmp_path, change):
    config = AdaptConfig(prompt="x")
    payload = _good_payload(config)
    payload.update(change)
    payload = {k: v for k, v in payload.items() if v is not None}
    torch.save(payload, tmp_path / CHECKPOINT_FILE)
    with pytest.raises(InputError, match="not what SceneFit writes") as refused:
        load_checkpoint(tmp_path / CHECKPOINT_FILE, config)
    assert "\n" not in str(refused.value)


ODD = st.one_of(st.none(), st.integers(-2**40, 2**40), st.floats(), st.text(max_size=6), st.booleans(),
                st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@FUZZ
@given(st.data())
def test_fuzz_checkpoints_give_a_payload_or_one_sentence(tmp_path_factory, data):
    config = AdaptConfig(prompt="x", iterations=10)
    payload = _good_payload(config)
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from(sorted(payload) + ["extra"]))
        if data.draw(st.booleans()):
            payload.pop(key, None)
        else:
            payload[key] = data.draw(ODD)
    path = tmp_path_factory.mktemp("ckpt") / CHECKPOINT_FILE
    torch.save(payload, path)
    if data.draw(st.booleans()):
        raw = bytearray(path.read_bytes())
        at = data.draw(st.integers(0, len(raw) - 1))
        raw[at:at + 4] = np.random.default_rng(at).bytes(4)
        path.write_bytes(bytes(raw))
    try:
        got = load_checkpoint(path, config)
    except InputError as error:
        assert "\n" not in str(error)
    else:
        assert got is not None and isinstance(got["iteration"], int) and 0 <= got["iteration"] <= 10
