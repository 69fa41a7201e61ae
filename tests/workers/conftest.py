"""Fixtures shared by the batch tests: the three jobs of batch_inputs run once in this process."""
from __future__ import annotations

import pytest

from scenefit.workers.batch import run_batch
from scenefit.workers.jobs import load_jobs
from batch_inputs import make_inputs

@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The three jobs run once in this process (the reference the Ray run is compared with)."""
    root = tmp_path_factory.mktemp("batch_in_process")
    jobs_path = make_inputs(root / "in")
    outcomes = run_batch(load_jobs(jobs_path), root / "out")
    return jobs_path, root / "out", outcomes
