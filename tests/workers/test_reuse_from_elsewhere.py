"""`scenefit batch --reuse-from EARLIER`: an earlier batch's folder is data. A job's finished stage whose
stage.json is not UTF-8, is a named pipe, or whose folder holds a named pipe, is not reused: the stage runs
again and the job is done (the job used to fail)."""
from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.workers.batch import run_batch
from scenefit.workers.jobs import load_jobs

from batch_inputs import CONVERT_JOB

JOBS = CONVERT_JOB


@pytest.fixture(scope="module")
def earlier(tmp_path_factory):
    root = tmp_path_factory.mktemp("reuse")
    save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((8, 8, 3), 0.5, np.float32)), root / "ball")
    (root / "jobs.toml").write_text(JOBS)
    [outcome] = run_batch(load_jobs(root / "jobs.toml"), root / "earlier")
    assert outcome.status == "done"
    return root


def _not_utf8(stage):
    (stage / "stage.json").write_bytes(b'{"key": "\xff\xfe", "report": {}}')


def _fifo_record(stage):
    (stage / "stage.json").unlink()
    os.mkfifo(stage / "stage.json")


def _fifo_beside(stage):
    os.mkfifo(stage / "notes.json")


@pytest.mark.parametrize("plant", [_not_utf8, _fifo_record, _fifo_beside])
def test_a_planted_earlier_stage_runs_again(earlier, tmp_path, plant):
    source = tmp_path / "earlier"
    shutil.copytree(earlier / "earlier", source, symlinks=True)
    (source / "a" / "report.json").unlink()   # (so the job is not skipped as done: its stages travel along)
    plant(source / "a" / "convert")
    [outcome] = run_batch(load_jobs(earlier / "jobs.toml"), tmp_path / "out", reuse_from=source)
    assert outcome.status == "done", outcome
    assert (tmp_path / "out" / "a" / "convert" / "stage.json").is_file()
