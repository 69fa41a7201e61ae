"""Background jobs: one long stage in a worker thread, driven by polling from the caller's thread.

    job = Job("convert", work, data)      # work(data, progress, cancel) -> plain result
    start_job(job)                        # refuses while another job runs (one at a time)
    state = job.poll()                    # caller's thread (Blender: the modal operator's timer)
    job.cancel()                          # sets the event the stages check between iterations

The worker gets `data` (plain values: numbers, strings, paths, numpy arrays, frozen dataclasses of
those) and a queue; never an operator or anything of bpy, which only the main thread may touch.
`check_plain` enforces that when the job is made. Everything the caller needs (stage, fraction,
ETA, the latest preview, the result or the error sentence) is in `JobState`, filled by `poll()`.

Why a thread and not a child process: Mitsuba and torch release the GIL inside their kernels, so
Blender's main thread keeps drawing while a stage runs; a child process would first spend seconds
importing torch and Mitsuba and recompiling Mitsuba's kernels, and Blender's Python cannot always
start one (its `sys.executable` and the `bl_ext` package path differ between Blender and the bpy
module). benchmarks/FINDINGS.md has the measurement.
"""
from __future__ import annotations

import dataclasses
import enum
import queue
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any, Callable

import numpy as np

from ..core.base.errors import Cancelled, InputError, SceneFitError
from ..core.base.progress import ProgressEvent, check_cancel

# work(data, progress, cancel) -> result; progress(ProgressEvent) also raises Cancelled once cancel is set.
Work = Callable[[Any, Callable[[ProgressEvent], None], threading.Event], Any]

RUNNING, DONE, CANCELLED, FAILED = "running", "done", "cancelled", "failed"
# An ETA is only shown once this much of a stage is done (earlier guesses jump around).
ETA_MIN_FRACTION = 0.05

_PLAIN_LEAVES = (type(None), bool, int, float, complex, str, bytes, PurePath, np.ndarray, np.generic, enum.Enum)


def check_plain(value: Any, where: str = "data") -> None:
    """Raise TypeError unless `value` is plain data a worker may hold (no bpy objects, no operators).

    Allowed: None, numbers, strings, bytes, paths, numpy arrays, enums, and dicts, lists, tuples,
    sets and frozen dataclasses of those; torch tensors too (the stages' own arrays).
    """
    if isinstance(value, _PLAIN_LEAVES) or _is_tensor(value):
        return
    if isinstance(value, dict):
        for key, item in value.items():
            check_plain(key, f"{where} key")
            check_plain(item, f"{where}[{key!r}]")
        return
    if isinstance(value, (list, tuple, set, frozenset)):
        for i, item in enumerate(value):
            check_plain(item, f"{where}[{i}]")
        return
    if dataclasses.is_dataclass(value) and not isinstance(value, type) and value.__dataclass_params__.frozen:  # type: ignore[attr-defined]
        for f in dataclasses.fields(value):
            check_plain(getattr(value, f.name), f"{where}.{f.name}")
        return
    raise TypeError(f"{where} is a {type(value).__module__}.{type(value).__qualname__}; a job's worker gets "
                    "plain data only (numbers, strings, paths, arrays, frozen dataclasses), never bpy objects.")


def _is_tensor(value: Any) -> bool:
    module = type(value).__module__
    return module.startswith("torch") and type(value).__name__ in ("Tensor", "Parameter")


@dataclass
class JobState:
    """What the caller shows: filled by Job.poll() on the caller's thread."""

    name: str
    status: str = RUNNING
    stage: str = ""
    step: int = 0
    total: int = 0
    message: str = ""
    fraction: float = 0.0             # of the current stage
    eta_seconds: float | None = None  # of the current stage
    preview: np.ndarray | None = None  # the latest preview, (h, w, 3) sRGB uint8
    preview_serial: int = 0           # increases with each new preview
    result: Any = None
    error: str = ""
    details: str = ""                 # the traceback of an unexpected failure, for the console
    started: float = field(default_factory=time.perf_counter)
    seconds: float = 0.0

    @property
    def finished(self) -> bool:
        return self.status != RUNNING

    def status_line(self) -> str:
        """One line for the panel and the status bar."""
        if self.status == DONE:
            return f"{self.name}: done in {self.seconds:.1f} s"
        if self.status == CANCELLED:
            return f"{self.name}: cancelled"
        if self.status == FAILED:
            return self.error
        step = f" {self.step}/{self.total}" if self.total else ""
        eta = f", about {format_seconds(self.eta_seconds)} left" if self.eta_seconds is not None else ""
        return f"{self.name}: {self.stage or 'starting'}{step}{eta}"


def format_seconds(seconds: float) -> str:
    seconds = max(0.0, float(seconds))
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


class Job:
    """One stage (or several) run by `work(data, progress, cancel)` in a daemon thread."""

    def __init__(self, name: str, work: Work, data: Any) -> None:
        check_plain(data)
        self.name = name
        self._work = work
        self._data = data
        self._events: queue.Queue = queue.Queue()
        self._cancel = threading.Event()
        self._thread: threading.Thread | None = None
        self._stage_started = time.perf_counter()
        self.state = JobState(name)

    # -- caller's thread ---------------------------------------------------------------------------
    def start(self) -> "Job":
        if self._thread is not None:
            raise RuntimeError(f"Job '{self.name}' was already started.")
        self.state.started = self._stage_started = time.perf_counter()
        self._thread = threading.Thread(target=self._run, name=f"scenefit-{self.name}", daemon=True)
        self._thread.start()
        return self

    def cancel(self) -> None:
        """Ask the worker to stop at its next check; poll() reports CANCELLED when it has."""
        self._cancel.set()

    @property
    def cancel_requested(self) -> bool:
        return self._cancel.is_set()

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def wait(self, timeout: float | None = None) -> JobState:
        """Block until the worker ends (or `timeout`), then poll."""
        if self._thread is not None:
            self._thread.join(timeout)
        return self.poll()

    def poll(self) -> JobState:
        """Drain the worker's queue into self.state; never blocks."""
        state = self.state
        while True:
            try:
                kind, payload = self._events.get_nowait()
            except queue.Empty:
                break
            if kind == "progress":
                self._take_progress(payload)
                continue
            state.seconds = time.perf_counter() - state.started
            state.eta_seconds = None
            if kind == "done":
                state.status, state.result, state.fraction = DONE, payload, 1.0
            elif kind == "cancelled":
                state.status, state.error = CANCELLED, payload
            else:
                state.status, (state.error, state.details) = FAILED, payload
        return state

    def _take_progress(self, event: ProgressEvent) -> None:
        state, now = self.state, time.perf_counter()
        if event.stage != state.stage:
            self._stage_started = now
        state.stage, state.step, state.total, state.message = event.stage, event.step, event.total, event.message
        state.fraction = min(max(event.fraction, 0.0), 1.0)
        elapsed = now - self._stage_started
        state.eta_seconds = (elapsed * (1.0 - state.fraction) / state.fraction
                             if state.fraction >= ETA_MIN_FRACTION and state.fraction < 1.0 else None)
        if event.preview is not None:
            state.preview, state.preview_serial = event.preview, state.preview_serial + 1

    # -- worker thread: no bpy, no operator, only self._data and the queue -------------------------
    def _progress(self, event: ProgressEvent) -> None:
        check_cancel(self._cancel)
        self._events.put(("progress", event))

    def _run(self) -> None:
        try:
            result = self._work(self._data, self._progress, self._cancel)
            check_cancel(self._cancel)
            self._events.put(("done", result))
        except Cancelled as error:
            self._events.put(("cancelled", str(error)))
        except SceneFitError as error:
            self._events.put(("error", (str(error), "")))
        except OSError as error:   # disk full, read-only, a path in the way: a sentence, as on the command line
            from ..core.base.os_errors import os_error_sentence

            request = getattr(self._data, "request", None)
            out = request.out if request is not None else self._data.get("out") if isinstance(self._data, dict) else None
            self._events.put(("error", (os_error_sentence(error, out), traceback.format_exc())))
        except Exception as error:  # an unexpected failure still ends the job, with its traceback kept
            self._events.put(("error", (f"{self.name} failed: {error!r}", traceback.format_exc())))


# -- one job at a time -------------------------------------------------------------------------------
_active: Job | None = None
_lock = threading.Lock()


def active_job() -> Job | None:
    """The job started last, while its worker still runs or its end has not been polled."""
    return _active


def start_job(job: Job) -> Job:
    """Start `job` unless another one is running (InputError: one sentence for the artist)."""
    global _active
    with _lock:
        if _active is not None and (_active.alive or not _active.state.finished):
            _active.poll()
            if _active.alive or not _active.state.finished:
                raise InputError(f"A SceneFit job ('{_active.name}') is already running; wait for it or "
                                 "cancel it first.")
        _active = job
    return job.start()


def release_job(job: Job) -> None:
    """Forget `job` once its end has been handled (the slot frees for the next one)."""
    global _active
    with _lock:
        if _active is job:
            _active = None


def end_active_job(timeout: float = 10.0) -> JobState | None:
    """Cancel the running job and wait up to `timeout` for its worker to stop (Blender is loading another file,
    quitting, or disabling SceneFit). The slot frees only once the worker has stopped: one still running
    (stuck in a call that checks no cancel) keeps it, so no new job starts beside it."""
    job = _active
    if job is None:
        return None
    job.cancel()
    state = job.wait(timeout)
    if not job.alive:
        release_job(job)
    return state


def run_inline(work: Work, data: Any, progress: Callable[[ProgressEvent], None] | None = None) -> Any:
    """Run `work` on the calling thread (scripts, `blender -b`): same code path, no worker."""
    check_plain(data)
    return work(data, progress or (lambda event: None), threading.Event())
