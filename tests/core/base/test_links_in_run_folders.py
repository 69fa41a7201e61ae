"""A link planted inside a run folder or its staging folder (to a folder of the user's) is never written
through: `scenefit run` starting from an earlier folder, and a resumed `.out.partial`, drop such links
(the link, never what it points at) before any stage writes."""
from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np

from scenefit.core.base.output_folder import output_folder, staging_path, write_marker
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.pipeline.run import run_pipeline
from scenefit.core.pipeline.run_config import RunConfig


def _mine(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    for name in ("base_color.png", "roughness.png", "notes.txt"):
        (mine / name).write_bytes(b"the user's own " + name.encode())
    return mine, {p.name: p.read_bytes() for p in mine.iterdir()}


def _convert(staging, iterations):
    mesh = replace(uv_sphere(0.5, 12, 6), name="ball")
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    return run_pipeline(mesh, maps, None, None, staging,
                        RunConfig(stage_overrides={"convert": {"iterations": iterations, "max_resolution": 16}}),
                        stages=("convert",))


def test_a_run_from_an_earlier_folder_never_writes_through_a_link_in_it(tmp_path):
    out = tmp_path / "run"
    with output_folder(out, reuse=True) as staging:
        _convert(staging, 2)
    maps = out / "convert" / "maps"
    assert maps.is_dir()
    mine, before = _mine(tmp_path)
    shutil.rmtree(maps)
    maps.symlink_to(mine, target_is_directory=True)
    with output_folder(out, reuse=True) as staging:   # other settings: convert runs again
        _convert(staging, 3)
    assert {p.name: p.read_bytes() for p in mine.iterdir()} == before
    assert (out / "convert" / "maps").is_dir() and not (out / "convert" / "maps").is_symlink()


def test_a_resumed_staging_folder_never_writes_through_a_link_in_it(tmp_path):
    out = tmp_path / "run"
    staging = staging_path(out)
    (staging / "convert").mkdir(parents=True)
    write_marker(staging)
    mine, before = _mine(tmp_path)
    (staging / "convert" / "maps").symlink_to(mine, target_is_directory=True)
    with output_folder(out, resume=True) as resumed:
        _convert(resumed, 2)
    assert {p.name: p.read_bytes() for p in mine.iterdir()} == before
