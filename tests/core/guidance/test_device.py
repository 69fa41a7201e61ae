"""The device "auto" finds (CUDA, then Apple's MPS, then the CPU), the precision each holds the weights in,
the memory switches each offers, and the depth model following the diffusion models' device."""
from __future__ import annotations

import pytest
import torch

from scenefit.core.base.errors import InputError
from scenefit.core.guidance.models import ModelConfig, found_device, memory_options_for
from scenefit.core.stages.light.depth import depth_config_for


@pytest.mark.parametrize("cuda, mps, expected", [(True, True, "cuda"), (False, True, "mps"), (False, False, "cpu")])
def test_auto_takes_cuda_then_mps_then_cpu(monkeypatch, cuda, mps, expected):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: cuda)
    monkeypatch.setattr(torch.backends.mps, "is_available", lambda: mps)
    assert found_device() == expected
    config = ModelConfig(device_type="auto")
    assert config.device().type == expected
    if expected != "cpu":   # a GPU holds the frozen weights in half precision
        assert config.dtype() == torch.float16


def test_a_missing_gpu_is_one_sentence(monkeypatch):
    monkeypatch.setattr(torch.backends.mps, "is_available", lambda: False)
    with pytest.raises(InputError, match="MPS"):
        ModelConfig(device_type="mps").device()
    with pytest.raises(InputError, match="device_type must be one of"):
        ModelConfig(device_type="metal")


def test_memory_switches_and_the_depth_device():
    assert "cpu_offload" in memory_options_for("cuda")
    assert "cpu_offload" not in memory_options_for("mps") and "cpu_offload" not in memory_options_for("cpu")
    assert {"attention_slicing", "vae_tiling"} <= set(memory_options_for("mps"))
    assert depth_config_for(ModelConfig(device_type="mps")).device == "mps"
    assert depth_config_for(ModelConfig(device_type="cuda")).device == "cuda"
    assert depth_config_for(ModelConfig(device_type="auto")).device == "cpu"
