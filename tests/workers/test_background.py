"""The job object without Blender: start, progress, preview, ETA, cancel, finish, error, one at a time."""
import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest

from scenefit.workers import background as jobs
from scenefit.core.base.errors import InputError
from scenefit.core.base.progress import emit


def _poll_until(job, done, timeout=10.0):
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        state = job.poll()
        if done(state):
            return state
        time.sleep(0.005)
    raise AssertionError(f"job state never reached the condition: {job.poll()}")


@pytest.fixture(autouse=True)
def free_slot():
    yield
    jobs.end_active_job(timeout=5.0)


def test_progress_preview_eta_and_result_reach_the_caller():
    gate = threading.Event()

    def work(data, progress, cancel):
        for i in range(1, 5):
            emit(progress, "fit", i, 8, preview=np.full((2, 2, 3), i, np.uint8) if i == 2 else None)
        gate.wait(5)
        return {"sum": float(np.sum(data["values"]))}

    job = jobs.start_job(jobs.Job("convert", work, {"values": np.arange(4.0)}))
    state = _poll_until(job, lambda s: s.step == 4)
    assert state.status == jobs.RUNNING and state.stage == "fit" and state.fraction == 0.5
    assert state.preview_serial == 1 and state.preview[0, 0, 0] == 2
    assert state.eta_seconds is not None and state.eta_seconds >= 0.0
    assert "fit 4/8" in state.status_line()
    gate.set()
    state = job.wait(5)
    assert state.status == jobs.DONE and state.result == {"sum": 6.0} and state.eta_seconds is None


def test_cancel_stops_the_worker_at_its_next_progress():
    steps = []

    def work(data, progress, cancel):
        for i in range(10_000):
            steps.append(i)
            emit(progress, "adapt", i, 10_000)
            time.sleep(0.001)
        return "finished"

    job = jobs.start_job(jobs.Job("adapt", work, None))
    _poll_until(job, lambda s: s.step >= 3)
    job.cancel()
    state = job.wait(5)
    assert not job.alive and state.status == jobs.CANCELLED and state.result is None
    assert len(steps) < 10_000


def test_errors_become_one_sentence_and_unexpected_ones_keep_the_traceback():
    def bad_input(data, progress, cancel):
        raise InputError("The photo 'x.png' does not exist.")

    def crash(data, progress, cancel):
        return 1 / 0

    state = jobs.start_job(jobs.Job("light", bad_input, None)).wait(5)
    assert state.status == jobs.FAILED and state.error == "The photo 'x.png' does not exist." and not state.details
    state = jobs.start_job(jobs.Job("light", crash, None)).wait(5)
    assert state.status == jobs.FAILED and "ZeroDivisionError" in state.error
    assert "1 / 0" in state.details


def test_a_full_disk_in_a_blender_job_is_one_sentence_naming_the_file(tmp_path):
    import errno

    target = tmp_path / "out" / "maps" / "base_color.png"

    def disk_full(data, progress, cancel):
        raise OSError(errno.ENOSPC, "No space left on device", str(target))

    state = jobs.start_job(jobs.Job("convert", disk_full, {"out": str(tmp_path / "out")})).wait(5)
    assert state.status == jobs.FAILED and "disk is full" in state.error and str(target) in state.error
    assert "\n" not in state.error and "OSError" not in state.error


def test_one_job_at_a_time_and_the_slot_frees_when_it_ends():
    gate = threading.Event()
    first = jobs.start_job(jobs.Job("convert", lambda d, p, c: gate.wait(5), None))
    with pytest.raises(InputError, match="already running"):
        jobs.start_job(jobs.Job("light", lambda d, p, c: None, None))
    gate.set()
    first.wait(5)
    second = jobs.start_job(jobs.Job("light", lambda d, p, c: "ok", None))  # finished jobs free the slot
    assert second.wait(5).result == "ok" and jobs.active_job() is second
    jobs.release_job(second)
    assert jobs.active_job() is None


def test_end_active_job_cancels_and_waits():
    def work(data, progress, cancel):
        while True:
            emit(progress, "compose", 0, 1)
            time.sleep(0.001)

    job = jobs.start_job(jobs.Job("compose", work, None))
    state = jobs.end_active_job(timeout=5)
    assert state.status == jobs.CANCELLED and not job.alive and jobs.active_job() is None


@dataclass(frozen=True)
class _Frozen:
    path: str
    size: tuple


@dataclass
class _Mutable:
    value: int


class _Operator:  # stands for a bpy operator or ID: anything that is not plain data
    pass


def test_worker_data_must_be_plain():
    jobs.check_plain({"mesh": _Frozen("a.png", (1, 2)), "maps": [np.zeros(2), 1.5, None], "ok": True})
    with pytest.raises(TypeError, match=r"data\['op'\] is a .*_Operator"):
        jobs.Job("convert", lambda d, p, c: None, {"op": _Operator()})
    with pytest.raises(TypeError, match="_Mutable"):
        jobs.check_plain([_Mutable(1)])
    with pytest.raises(TypeError):
        jobs.run_inline(lambda d, p, c: None, (lambda: None,))


def test_run_inline_is_the_same_code_path_on_the_calling_thread():
    seen = []

    def work(data, progress, cancel):
        emit(progress, "fit", 1, 2)
        return threading.current_thread() is threading.main_thread(), data * 2

    assert jobs.run_inline(work, 21, seen.append) == (True, 42)
    assert seen[0].stage == "fit"
