"""Hand one job to a SceneFit worker environment with GPUs and follow it from here (the Blender side).

The extension bundles CPU torch, so the adapt stage at the paper's settings would take a day on an
artist's laptop. `RemoteJob` starts the job on a Ray cluster (its address from the add-on's
preferences; "local" for a cluster on this machine) as a JobWorker actor with the job's CPUs and
GPUs, and streams its progress events (stage, step, metrics, the occasional preview image) back
through a Ray queue. The job's inputs travel as bytes and its output folder comes back as bytes, so
the cluster needs no access to the artist's disk. Nothing here blocks: a modal operator calls
`events()` and `finished()` from its timer, then `result(folder)` to unpack the outputs, which it
applies on Blender's main thread. `LocalProcessJob` is the same for a SceneFit install with CUDA
torch on this machine, without Ray: it runs `scenefit batch --events` with that install's Python.

Only plain data crosses to the worker (the job as a dict, its inputs as bytes, progress dicts, a
result dict): inside Blender this package is `bl_ext.<repo>.scenefit`, on the workers it is the
installed `scenefit`, so neither side could unpickle the other's classes.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.base import errors
from .packing import unpack
from .payload import finished_stage_folders, make_payload
from ..core.base.output_folder import install_folder
from .batch_ray import connect, import_ray, job_resources
from ..core.base.errors import Cancelled, SceneFitError
from .job_inputs import read_job_report
from .jobs import BatchSettings, Job
from ..core.pipeline.run_config import RunConfig

# What the worker environment imports SceneFit as (a pip install of it).
WORKER_PACKAGE = "scenefit"


def worker_actor_class(package: str = WORKER_PACKAGE):
    """The Ray actor class that runs jobs in the worker environment. Made in a function so that Ray
    ships it by value: the cluster needs `package`, never the caller's own module name."""

    class SceneFitWorker:
        def __init__(self, threads: int) -> None:
            import importlib

            self.job_worker = importlib.import_module(package + ".workers.job_worker")
            self.worker = self.job_worker.JobWorker(threads=threads)

        def run(self, job: dict, inputs: bytes, progress_sink=None) -> dict:
            return self.job_worker.run_plain(self.worker, job, inputs, progress_sink)

        def cancel(self) -> None:
            self.worker.cancel()

    return SceneFitWorker


def raise_worker_error(result: dict) -> None:
    """A worker's {"error", "kind"} as this side's exception (InputError, Cancelled, ...)."""
    kind = getattr(errors, result.get("kind", ""), SceneFitError)
    if not (isinstance(kind, type) and issubclass(kind, SceneFitError)):
        kind = SceneFitError
    raise kind(result["error"])


class RemoteJob:
    """One job running on a Ray cluster; poll it, cancel it, fetch its outputs."""

    def __init__(self, job: Job, address: str = "auto", settings: BatchSettings = BatchSettings(),
                 queue_size: int = 256, earlier: Path | None = None) -> None:
        ray = import_ray()
        from ray.util.queue import Queue

        self.ray, self.job = ray, job
        self.started_ray = connect(address)
        try:
            options = job_resources(settings, ray.cluster_resources())
            # Two calls at once: `run`, and `cancel` while it runs.
            self.actor = ray.remote(worker_actor_class()).options(max_concurrency=2, **options).remote(
                threads=max(1, int(settings.num_cpus)))
            self.queue = Queue(maxsize=queue_size)
            payload = make_payload(job, stages=finished_stage_folders(earlier))   # (they travel with the inputs)
            self.ref = self.actor.run.remote(job.to_dict(), payload.inputs, self.queue)
        except BaseException:
            self.close()
            raise
        self._result: dict | None = None

    def events(self, limit: int | None = None) -> list[dict]:
        """Progress events that arrived since the last call, oldest first (never waits)."""
        out: list[dict] = []
        while (limit is None or len(out) < limit) and not self.queue.empty():
            try:
                out.append(self.queue.get_nowait())
            except Exception:   # emptied between the check and the get
                break
        return out

    def finished(self) -> bool:
        ready, _ = self.ray.wait([self.ref], timeout=0)
        return bool(ready)

    def cancel(self) -> None:
        self.actor.cancel.remote()

    def result(self, out_dir: str | Path, timeout: float | None = None) -> Path:
        """Wait for the job, unpack its folder into OUT_DIR/<job name>/ (whole), return that folder.

        Raises the job's own SceneFitError (bad input, Cancelled, ...) as it was raised on the worker.
        """
        if self._result is None:
            self._result = self.ray.get(self.ref, timeout=timeout)
        if "error" in self._result:
            raise_worker_error(self._result)
        outputs = self._result["outputs"]
        return install_folder(Path(out_dir), self.job.name, lambda folder: unpack(outputs, folder))

    @property
    def report(self) -> dict | None:
        return None if self._result is None else self._result.get("report")

    def close(self) -> None:
        """Free the worker and the queue (and Ray itself when this job started it)."""
        for name in ("actor",):
            handle = getattr(self, name, None)
            if handle is not None:
                self.ray.kill(handle)
        queue = getattr(self, "queue", None)
        if queue is not None:
            queue.shutdown()
        if self.started_ray:
            self.ray.shutdown()

    def __enter__(self) -> RemoteJob:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_worker(job: Job, address: str, settings: BatchSettings = BatchSettings(), earlier: Path | None = None):
    """The worker environment the add-on's preference names: a Python interpreter of another SceneFit
    install (a path to a file) runs the job as a local process; anything else is a Ray address.
    `earlier`: an earlier run of the job, whose stages with the same inputs and settings the worker reuses."""
    if Path(address).expanduser().is_file():
        return LocalProcessJob(job, str(Path(address).expanduser()), settings, earlier=earlier)
    return RemoteJob(job, address, settings, earlier=earlier)


def run_remote(job: Job, out_dir: str | Path, address: str = "auto", settings: BatchSettings = BatchSettings(),
               progress=None, cancel=None, poll_seconds: float = 0.2, earlier: Path | None = None) -> tuple[Path, dict]:
    """Run `job` in the worker environment at `address` (open_worker) and wait: the shape of a
    background-job work function.

    Streams the worker's events to `progress` as ProgressEvents (previews included), passes a set
    `cancel` event on to the worker, and returns (OUT_DIR/<job name>, the job's report).
    """
    import time

    from ..core.base.progress import ProgressEvent

    with open_worker(job, address, settings, earlier) as remote:
        asked_to_cancel = False
        while True:
            finished = remote.finished()
            for e in remote.events():
                if progress is not None:
                    progress(ProgressEvent(e["stage"], e["step"], e["total"], e["message"], e["metrics"],
                                           e["preview"]))
            if finished:
                break
            if cancel is not None and cancel.is_set() and not asked_to_cancel:
                remote.cancel()
                asked_to_cancel = True
            time.sleep(poll_seconds)
        folder = remote.result(out_dir)
        return folder, remote.report


class LocalProcessJob:
    """One job run by another SceneFit install on this machine (e.g. one with CUDA torch), followed
    through `scenefit batch --events`: the same interface as RemoteJob, without Ray.

    `python` is that install's interpreter. The job goes in a one-job jobs file beside its inputs
    (paths made absolute); progress comes back as JSON lines; cancel sends SIGINT, which the
    command line turns into a clean stop.
    """

    def __init__(self, job: Job, python: str, settings: BatchSettings = BatchSettings(), env: dict | None = None,
                 earlier: Path | None = None) -> None:
        import os
        import queue
        import shutil
        import subprocess
        import tempfile
        import threading

        self.job = job
        self.report: dict | None = None
        self.tmp = tempfile.TemporaryDirectory(prefix="scenefit-remote-")
        root = Path(self.tmp.name)
        entry = {k: v for k, v in job.to_dict().items() if v not in (None, "", {})}
        models = entry.pop("models", {})
        entry["stages"] = list(job.stages)
        lines = ["[batch]", "retries = 0", f"num_cpus = {settings.num_cpus:g}", "", "[models]"]
        lines += [f"{k} = {_toml(v)}" for k, v in models.items() if v is not None]
        lines += ["", "[[job]]"] + [f"{k} = {_toml(v)}" for k, v in entry.items()]
        (root / "jobs.toml").write_text("\n".join(lines) + "\n")
        self.out = root / "out"
        reuse = []
        if earlier is not None and install_takes_reuse_from(python, env):   # (an older install runs all again)
            from .payload import finished_stage_folders

            for stage in finished_stage_folders(earlier):   # copied as an earlier batch's job folder
                shutil.copytree(stage, root / "earlier" / job.name / stage.name)
            reuse = ["--reuse-from", str(root / "earlier")]
        self.process = subprocess.Popen([python, "-m", "scenefit.cli", "batch", str(root / "jobs.toml"), "--out",
                                         str(self.out), "--events", "--quiet", *reuse], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})})
        self._events: queue.Queue = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        import json

        for line in self.process.stdout:  # type: ignore[union-attr]
            try:
                event = json.loads(line)
            except ValueError:
                continue   # the command's own summary line
            if isinstance(event, dict) and event.get("event") == "progress":
                event.pop("event")
                path = event.pop("preview_png", None)
                event["preview"] = _read_preview(path) if path else None
                self._events.put(event)

    def events(self, limit: int | None = None) -> list[dict]:
        out: list[dict] = []
        while limit is None or len(out) < limit:
            try:
                out.append(self._events.get_nowait())
            except Exception:
                break
        return out

    def finished(self) -> bool:
        return self.process.poll() is not None

    def cancel(self) -> None:
        import signal

        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)

    def result(self, out_dir: str | Path, timeout: float | None = None) -> Path:
        import shutil

        code = self.process.wait(timeout=timeout)
        self._reader.join(timeout=10)
        error = self.process.stderr.read().strip()  # type: ignore[union-attr]
        if code == 130:
            raise Cancelled("Cancelled by the user; the worker stopped and nothing came back.")
        report = read_job_report(self.out / self.job.name / "report.json")   # (None: absent or unreadable)
        self.report = report
        if code != 0 or report is None or report.get("status") != "done":
            why = (report or {}).get("error") or (error.splitlines()[-1] if error else f"exit code {code}")
            raise SceneFitError(f"The SceneFit worker failed job '{self.job.name}': {why}")
        source = self.out / self.job.name
        return install_folder(Path(out_dir), self.job.name, lambda folder: shutil.copytree(source, folder,
                                                                                         dirs_exist_ok=True))

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.tmp.cleanup()

    def __enter__(self) -> LocalProcessJob:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


_TAKES_REUSE_FROM: dict[str, bool] = {}


def install_takes_reuse_from(python: str, env: dict | None = None) -> bool:
    """Whether the SceneFit install of `python` has `scenefit batch --reuse-from` (asked once per install
    and session: an install from before it would refuse the whole job over the flag; one that does not
    answer in 30 s is taken for such an install)."""
    import os
    import subprocess

    key = python + repr(sorted((env or {}).items()))
    if key not in _TAKES_REUSE_FROM:
        try:
            shown = subprocess.run([python, "-m", "scenefit.cli", "batch", "--help"], capture_output=True, text=True,
                                   timeout=30, env={**os.environ, **(env or {})}).stdout
        except (OSError, subprocess.SubprocessError):
            shown = ""
        _TAKES_REUSE_FROM[key] = "--reuse-from" in shown
    return _TAKES_REUSE_FROM[key]


def _toml(value) -> str:
    """A TOML value: JSON's strings, numbers, booleans and lists are TOML too; tables are inline."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return json.dumps(value)


def _read_preview(path: str):
    import numpy as np

    from ..core.data.imageio import read_image

    try:
        return (np.clip(read_image(path)[..., :3], 0.0, 1.0) * 255).round().astype(np.uint8)
    except Exception:
        return None


def work_remotely(data: dict, progress=None, cancel=None) -> dict:
    """A background-job work function for scripts: plain data in (the asset as arrays, the photo, the
    placement), the job run in the worker environment `data["worker"]`, its folder back in `data["out"]`.
    Keys: asset (planned, decoded here; or mesh and maps), photo, at, worker, out; optional name, stages,
    models (a ModelConfig), num_cpus, num_gpus, earlier (an earlier run's folder: its stages with the same
    inputs and settings are reused), and the run's settings as a jobs file's job gives them
    (core/pipeline/run_table.py: preset, mode, prompt, overrides, object_size, camera, sun, scene, ...).
    Blender's Run All sends its RunConfig as it is (send_run)."""
    from ..core.pipeline.registry import STAGES
    from ..core.guidance.models import ModelConfig
    from ..core.pipeline.run_table import KEYS, run_config

    name = data.get("name", "scenefit")
    stages = tuple(data.get("stages", STAGES))
    run = run_config({k: data[k] for k in KEYS if data.get(k) is not None}, f"The remote job '{name}'", stages,
                     models=data.get("models") or ModelConfig())
    return send_run(RemoteRun(name=name, worker=data["worker"], out=data["out"], stages=stages, run=run,
                              photo=data.get("photo"), at=tuple(data["at"]) if data.get("at") is not None else None,
                              asset=data.get("asset"), mesh=data.get("mesh"), maps=data.get("maps"),
                              earlier=data.get("earlier"), num_cpus=float(data.get("num_cpus", 1.0)),
                              num_gpus=data.get("num_gpus", "auto")), progress, cancel)


@dataclass(frozen=True)
class RemoteRun:
    """One run sent to a worker environment: the RunConfig as it is (Blender's Run All builds it once, at the
    click), the asset (planned in Blender and decoded in the job, or a script's mesh and maps), the photo and
    placement, where the job's folder comes back (out/name), and an earlier run whose stages may be reused."""

    name: str
    worker: str
    out: str
    stages: tuple[str, ...]
    run: RunConfig
    photo: str | None = None
    at: tuple[float, float] | None = None
    asset: Any = None
    mesh: Any = None
    maps: Any = None
    earlier: str | None = None
    num_cpus: float = 1.0
    num_gpus: Any = "auto"


def send_run(sent: RemoteRun, progress=None, cancel=None) -> dict:
    """Run `sent` as one Job in its worker environment; {"folder", "report"} of the folder that came back."""
    import tempfile

    from ..core.data.asset_io import save_asset_folder
    from ..core.data.map_plan import fitting_inputs

    with tempfile.TemporaryDirectory(prefix="scenefit-asset-") as tmp:
        asset = save_asset_folder(*fitting_inputs({"asset": sent.asset, "mesh": sent.mesh, "maps": sent.maps}),
                                  Path(tmp) / "asset")
        job = Job(name=sent.name, asset=asset, stages=sent.stages, photo=Path(sent.photo) if sent.photo else None,
                  at=sent.at, run=sent.run)
        settings = BatchSettings(retries=0, num_cpus=sent.num_cpus, num_gpus=sent.num_gpus)
        folder, report = run_remote(job, sent.out, sent.worker, settings, progress=progress, cancel=cancel,
                                    earlier=Path(sent.earlier) if sent.earlier else None)
    return {"folder": str(folder), "report": report}
