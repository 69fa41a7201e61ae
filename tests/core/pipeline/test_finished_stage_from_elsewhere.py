"""A stage folder from elsewhere (an earlier run, --reuse-from, a worker, a planted folder) is data: a
stage.json that is not a stage record, or a light map of NaN, is not a finished stage; it runs again."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from scenefit.core.data.imageio import write_image
from scenefit.core.pipeline.run import STAGE_FILE, _finished_stage


def light_stage(tmp_path, pixels):
    folder = tmp_path / "light"
    folder.mkdir()
    write_image(folder / "light.exr", pixels)
    (folder / STAGE_FILE).write_text(json.dumps({"key": "k", "report": {"outputs": {"light_exr": "light.exr"}}}))
    return folder


def test_a_finished_stage_with_finite_maps_is_reused(tmp_path):
    folder = light_stage(tmp_path, np.full((8, 16, 3), 2.0, np.float32))
    report = _finished_stage(folder, "k")
    assert report is not None and report["outputs"]["light_exr"] == str(folder / "light.exr")
    assert _finished_stage(folder, "other key") is None


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_light_map_that_is_not_finite_is_not_reused(tmp_path, bad):
    pixels = np.full((8, 16, 3), 2.0, np.float32)
    pixels[3, 5, 1] = bad
    assert _finished_stage(light_stage(tmp_path, pixels), "k") is None


def texture_stage(tmp_path, value: float):
    folder = tmp_path / "convert"
    folder.mkdir(parents=True)
    weights = {"residual": torch.zeros(4, 8, 8), "base": torch.full((3, 8, 8), 0.5), "step": torch.tensor(3)}
    weights["residual"][1, 2, 3] = value
    torch.save(weights, folder / "texture.pt")
    (folder / STAGE_FILE).write_text(json.dumps({"key": "k", "report": {"outputs": {"weights": "texture.pt"}}}))
    return folder


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_texture_that_is_not_finite_is_not_reused(tmp_path, bad):
    assert _finished_stage(texture_stage(tmp_path / "good", 0.25), "k") is not None
    assert _finished_stage(texture_stage(tmp_path / "bad", bad), "k") is None


@pytest.mark.parametrize("raw", [b"[]", b"[" * 100_000, b"\xff\xfe", b'{"key": "k", "report": []}',
                                 b'{"key": "k", "report": {"outputs": ["light.exr"]}}', b'{"key": ["k"]}'])
def test_a_planted_stage_record_runs_the_stage_again(tmp_path, raw):
    folder = light_stage(tmp_path, np.ones((8, 16, 3), np.float32))
    (folder / STAGE_FILE).write_bytes(raw)
    assert _finished_stage(folder, "k") is None
