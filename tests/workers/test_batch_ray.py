"""The same jobs on a local Ray cluster: retries and resume match the in-process run, a remote job streams
its progress and cancels, Ray ranks join a torch.distributed group."""
from __future__ import annotations

import json
import sys

import pytest

from scenefit.cli import main
from scenefit.workers.batch import run_batch
from scenefit.workers.jobs import load_jobs
import batch_inputs
from batch_inputs import FailingOnceWorker, make_inputs, outputs


@pytest.fixture(scope="module")
def local_ray():
    """One small local Ray cluster for this module's Ray tests; the module's functions and classes
    travel to its workers by value (the workers cannot import the test module)."""
    ray = pytest.importorskip("ray")
    from ray import cloudpickle

    for module in (sys.modules[__name__], batch_inputs):
        cloudpickle.register_pickle_by_value(module)
    ray.init(num_cpus=2, object_store_memory=80 * 2**20, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()
    for module in (sys.modules[__name__], batch_inputs):
        cloudpickle.unregister_pickle_by_value(module)


def test_a_ray_address_ray_cannot_read_is_one_sentence(tmp_path, capsys):
    """`--ray none` (meaning: not on Ray) was Ray's ValueError traceback."""
    pytest.importorskip("ray")
    jobs = make_inputs(tmp_path)
    assert main(["batch", str(jobs), "--out", str(tmp_path / "out"), "--ray", "none"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("scenefit: error: 'none' is not a Ray cluster address") and "Traceback" not in str(err)
    assert "leave --ray out" in err[-1] and not (tmp_path / "out").exists()


@pytest.mark.slow   # a local Ray cluster
def test_ray_batch_retries_resumes_and_matches_in_process(in_process, local_ray, tmp_path):
    from scenefit.workers.batch_ray import RayDispatcher

    jobs_path, reference, _ = in_process
    jobs = load_jobs(jobs_path)
    dispatcher = RayDispatcher(jobs.settings, len(jobs.jobs), worker_class=FailingOnceWorker)
    assert dispatcher.workers == 2 and dispatcher.options == {"num_cpus": 1.0, "num_gpus": 0.0}
    outcomes = run_batch(jobs, tmp_path / "out", dispatcher)
    assert [(o.name, o.status, o.attempts) for o in outcomes] == [("a", "done", 1), ("b", "done", 2),
                                                                  ("c", "done", 1)]
    report = json.loads((tmp_path / "out" / "b" / "report.json").read_text())
    assert report["attempts"] == 2 and report["worker"]["pid"] != __import__("os").getpid()

    # A second run does nothing.
    again = run_batch(jobs, tmp_path / "out", RayDispatcher(jobs.settings, len(jobs.jobs)))
    assert [o.status for o in again] == ["skipped"] * 3
    # Same outputs as in-process: the same threads per job give the same bytes.
    for name in "abc":
        assert outputs(tmp_path / "out" / name) == outputs(reference / name), name


@pytest.mark.slow   # a local Ray cluster
def test_remote_job_streams_progress_cancels_and_returns_its_folder(in_process, local_ray, tmp_path):
    """What the add-on does with a worker environment: hand a job to Ray, follow it, cancel it, fetch it."""
    import threading
    from dataclasses import replace

    from scenefit.core.base.errors import Cancelled
    from scenefit.workers.remote import run_remote

    jobs_path, reference, _ = in_process
    job = load_jobs(jobs_path).jobs[0]
    events = []
    folder, report = run_remote(job, tmp_path / "back", progress=events.append)
    assert folder == tmp_path / "back" / "a" and report["status"] == "done"
    stages = [e.stage for e in events]
    assert "convert" in stages and "light" in stages and stages.index("convert") < stages.index("light")
    assert all(0 <= e.step <= e.total for e in events) and events[-1].fraction == 1.0
    assert outputs(folder) == outputs(reference / "a")

    # Cancelled at its first progress event: the worker stops with Cancelled and nothing comes back. (A
    # fit of many iterations: the exact start converts in a blink, so a plain convert could finish
    # before the cancel reached the worker, as it did under load.)
    cancel = threading.Event()
    long_job = replace(job, name="long", stages=("convert",), run=replace(
        job.run, preset="final", stage_overrides={"convert": {"iterations": 100000}}))
    with pytest.raises(Cancelled):
        run_remote(long_job, tmp_path / "back", progress=lambda event: cancel.set(), cancel=cancel)
    assert not (tmp_path / "back" / "long").exists()


def _sum_over_ranks(value_per_rank: float) -> tuple[int, int, float, int]:
    """One rank's part, through the adapt stage's own functions: join the group from the environment
    run_on_ranks sets (torchrun's), and sum a gradient over the ranks as a step does."""
    import torch

    from scenefit.core.stages.adapt.distributed import join_process_group, sum_gradients

    rank, world, why = join_process_group()
    weight = torch.nn.Parameter(torch.zeros(1))
    weight.grad = torch.tensor([value_per_rank * (rank + 1)])
    sum_gradients([weight])
    return rank, world, float(weight.grad), why.choice


@pytest.mark.slow   # a local Ray cluster
def test_ray_launches_a_torch_distributed_group_on_one_node(local_ray):
    """The adapt stage's views spread over Ray ranks (test_distributed checks the same join and sum,
    step by step against one process, under torchrun)."""
    from scenefit.workers.batch_ray import run_on_ranks

    assert run_on_ranks(_sum_over_ranks, (0.5,), world=2) == [(0, 2, 1.5, 2), (1, 2, 1.5, 2)]
