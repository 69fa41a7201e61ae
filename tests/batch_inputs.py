"""A batch's inputs for the tests of `scenefit batch` (tests/workers/): a ball, a photo and a jobs file of
three draft jobs, workers that fail on purpose, and a job folder's files as bytes."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.workers.job_worker import JobWorker

# One small convert job of the ball (a 16-texel texture): a batch that runs in seconds.
CONVERT_JOB = """
[[job]]
name = "a"
asset = "ball"
stages = ["convert"]
preset = "draft"
[job.overrides.convert]
resolution = 16
"""

JOBS = """
[batch]
retries = {retries}
[defaults]
preset = "draft"
photo = "room.png"
at = [0.5, 0.7]
stages = ["light", "convert"]
[[job]]
name = "a"
asset = "ball"
[[job]]
name = "b"
asset = "ball"
seed = 1
[[job]]
name = "c"
asset = "ball"
stages = ["light"]
"""


def make_inputs(folder: Path, retries: int = 1) -> Path:
    """A 16x8-segment ball with 16² maps, a 64x48 photo and a jobs file of three draft jobs."""
    rng = np.random.default_rng(0)
    maps = PBRMaps(base_color=rng.uniform(0.1, 0.9, (16, 16, 3)).astype(np.float32), roughness=0.5, metallic=0.0)
    save_asset_folder(uv_sphere(segments=16, rings=8), maps, folder / "ball")
    y = np.linspace(0.0, 1.0, 48)[:, None, None]
    photo = np.concatenate([0.8 - 0.5 * y, 0.7 - 0.4 * y, 0.5 + 0.0 * y], axis=2)
    write_image(folder / "room.png", np.broadcast_to(photo, (48, 64, 3)).astype(np.float32))
    (folder / "jobs.toml").write_text(JOBS.format(retries=retries))
    return folder / "jobs.toml"


class FailingOnceWorker(JobWorker):
    """Job 'b' fails on its first attempt, wherever it runs."""

    def run(self, payload, progress_sink=None):
        if payload.job.name == "b" and payload.attempt == 1:
            raise RuntimeError("injected failure of job b's first attempt")
        return super().run(payload, progress_sink)


class AlwaysFailingWorker(JobWorker):
    def run(self, payload, progress_sink=None):
        if payload.job.name == "b":
            raise RuntimeError("injected failure of job b")
        return super().run(payload, progress_sink)


def outputs(folder: Path) -> dict[str, bytes]:
    """Every file a job wrote, except its reports and each stage's record of its report (timings, worker)
    -> bytes; EXR files by their pixels (OpenImageIO stamps the write time into the header)."""
    return {str(p.relative_to(folder)): read_image(p).tobytes() if p.suffix == ".exr" else p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name not in ("report.json", "stage.json")}
