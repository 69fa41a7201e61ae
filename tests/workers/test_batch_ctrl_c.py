"""Ctrl-C stops a batch within seconds, its finished jobs whole: a Ctrl-C that lands inside a render
reaches the job as Dr.Jit's RuntimeError, which the batch used to take for a failed attempt, retry,
and go on with the next jobs (45 s after Ctrl-C). A real `scenefit batch` process gets a real SIGINT."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np

from conftest import ROOT, takes_ctrl_c
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere

JOBS = """
[[job]]
name = "a"
asset = "ball"
stages = ["convert"]
preset = "draft"
[[job]]
name = "b"
asset = "ball"
photo = "room.png"
at = [0.5, 0.7]
stages = ["convert", "light", "compose"]
preset = "final"
[[job]]
name = "c"
asset = "ball"
photo = "room.png"
at = [0.5, 0.7]
stages = ["convert", "light", "compose"]
preset = "final"
seed = 3
"""


def test_ctrl_c_stops_the_batch_within_seconds_with_finished_jobs_whole(tmp_path):
    save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((8, 8, 3), 0.5, np.float32)), tmp_path / "ball")
    y = np.linspace(0.0, 1.0, 96)[:, None, None]
    write_image(tmp_path / "room.png", np.broadcast_to(np.concatenate([0.8 - 0.5 * y, 0.7 - 0.4 * y, 0.5 + 0 * y], 2),
                                                       (96, 128, 3)).astype(np.float32))
    (tmp_path / "jobs.toml").write_text(JOBS)
    batch = subprocess.Popen([sys.executable, "-m", "scenefit.cli", "batch", tmp_path / "jobs.toml", "--out",
                              tmp_path / "out", "--events"], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                             cwd=ROOT, preexec_fn=takes_ctrl_c)
    for line in batch.stdout:   # Ctrl-C half a second into job b's first compose render (1.5 s long here)
        event = json.loads(line) if line.startswith("{") else {}
        if event.get("job") == "b" and event.get("stage") == "compose":
            break
    time.sleep(0.5)
    batch.send_signal(signal.SIGINT)
    sent = time.perf_counter()
    rest = batch.communicate(timeout=300)[1]
    seconds = time.perf_counter() - sent
    assert batch.returncode == 130 and seconds < 15, (batch.returncode, seconds, rest[-2000:])
    assert "attempt 2" not in rest and "[c]" not in rest.replace("[c] queued", ""), rest[-2000:]
    out = tmp_path / "out"
    assert json.loads((out / "a" / "report.json").read_text())["status"] == "done"   # finished: whole
    assert not (out / "b").exists() and not (out / "c").exists()
    summary = {job["name"]: job["status"] for job in json.loads((out / "summary.json").read_text())["jobs"]}
    assert summary == {"a": "done", "b": "interrupted", "c": "interrupted"}
