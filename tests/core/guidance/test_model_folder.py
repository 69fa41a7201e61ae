"""A model folder is data: its configs are read with limits, a named pipe in a config's place is refused
without being opened, and a config asking for a network larger than this machine's memory is one sentence
before anything is allocated. Fuzzed: random config values give a model or one sentence."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from conftest import shared_tiny_pair
from scenefit.core.base.errors import ModelMissingError
from scenefit.core.guidance.models import ModelConfig, load_guidance_models

FUZZ = settings(derandomize=True, max_examples=30, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _copy_base(tmp_path):
    base, _ = shared_tiny_pair()
    return shutil.copytree(base, tmp_path / "base")


def _config(base) -> ModelConfig:
    return ModelConfig(base_model=str(base), dtype_type="fp32", device_type="cpu")


def test_a_unet_config_asking_for_1000x_the_channels_is_one_sentence(tmp_path):
    """Used to try to allocate the network (a RuntimeError from torch's allocator)."""
    base = _copy_base(tmp_path)
    path = base / "unet" / "config.json"
    config = json.loads(path.read_text())
    config["block_out_channels"] = [c * 1000 for c in config["block_out_channels"]]
    path.write_text(json.dumps(config))
    with pytest.raises(ModelMissingError, match=r"needs about .* of memory") as refused:
        load_guidance_models(_config(base), need_inpaint=False, paths={"base": base})
    assert "\n" not in str(refused.value) and str(base / "unet") in str(refused.value)


def test_a_depth_config_that_is_a_named_pipe_is_refused_unopened(tmp_path):
    """`scenefit light` with such a depth model hung; the check runs in a process of its own so the old
    hang is a failure, not a stuck test."""
    from scenefit.devtools.tiny_models import build_tiny_depth

    depth = build_tiny_depth(tmp_path / "depth")
    (depth / "config.json").unlink()
    os.mkfifo(depth / "config.json")
    code = ("from scenefit.core.guidance.models import load_depth_estimator\n"
            "from scenefit.core.base.errors import ModelMissingError\n"
            f"try:\n    load_depth_estimator({str(depth)!r}, local_files_only=True)\n"
            "except ModelMissingError as error:\n    print(error)\n")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("loading a depth model whose config.json is a named pipe hung")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "not a regular file" in proc.stdout and "config.json" in proc.stdout


UNET_KEYS = ["block_out_channels", "in_channels", "out_channels", "cross_attention_dim", "layers_per_block",
             "norm_num_groups", "attention_head_dim", "sample_size"]
ODD = st.one_of(st.integers(-5, 2**40), st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=5),
                st.none(), st.lists(st.integers(-3, 2**31), max_size=4), st.booleans())


@FUZZ
@given(st.data())
def test_fuzz_model_folder_configs_give_a_model_or_one_sentence(tmp_path_factory, data):
    from scenefit.core.guidance.models import _check_guidance_folders

    import torch

    base = _copy_base(tmp_path_factory.mktemp("fuzz"))
    path = base / data.draw(st.sampled_from(["unet", "vae", "text_encoder"])) / "config.json"
    config = json.loads(path.read_text())
    for _ in range(data.draw(st.integers(1, 3))):
        config[data.draw(st.sampled_from(UNET_KEYS + ["hidden_size", "num_hidden_layers", "intermediate_size"]))] = \
            data.draw(ODD)
    text = json.dumps(config)
    if data.draw(st.booleans()):
        text = data.draw(st.sampled_from(["[" * 100_000, "[]", "1e999", "{", "\udcff"]))
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        _check_guidance_folders({"base": base}, torch.float32)
    except ModelMissingError as error:
        assert "\n" not in str(error)
