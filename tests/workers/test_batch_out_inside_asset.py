"""A batch whose --out lies inside the asset's folder: its own output (the batch folder, a job's staging
folder, the lock beside it) is not part of the asset, so the job's digest stays and the next batch skips
the job instead of running it again; a file the user adds to the folder still changes it."""
from __future__ import annotations

import numpy as np

from scenefit.core.base.output_folder import LOCK_TEXT, write_marker
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.workers.job_inputs import job_digest, job_files
from scenefit.workers.jobs import Job


def test_the_batchs_own_output_inside_the_asset_folder_leaves_the_digest(tmp_path):
    folder = save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((4, 4, 3), 0.5, np.float32)),
                               tmp_path / "ball")
    job = Job(name="j", asset=folder, stages=("convert",))
    before = job_digest(job, job_files(job))
    out = folder / "results"                  # scenefit batch jobs.toml --out ball/results
    (out / "j" / "convert").mkdir(parents=True)
    write_marker(out)
    write_marker(out / "j")
    (out / "j" / "report.json").write_text('{"status": "done"}')
    (out / "j" / "convert" / "texture.pt").write_bytes(b"weights")
    staging = folder / "results" / ".k.partial-x1"
    staging.mkdir()
    write_marker(staging)
    (staging / "half.png").write_bytes(b"half")
    (folder / ".results.lock").write_bytes(LOCK_TEXT)
    files = job_files(job)
    assert job_digest(job, files) == before
    assert not any("results" in name or name.endswith(".lock") for name in files), sorted(files)
    (folder / "notes.txt").write_text("the user's own file is the asset's")
    assert job_digest(job, job_files(job)) != before
    (folder / "notes.txt").unlink()
    (folder / ".mine.lock").write_text("a user's file of that name is theirs")
    assert job_digest(job, job_files(job)) != before


def test_a_folder_that_is_itself_a_run_folder_is_read_whole(tmp_path):
    from scenefit.core.data.asset_files import asset_files

    folder = save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((4, 4, 3), 0.5, np.float32)),
                               tmp_path / "texture")
    write_marker(folder)   # a convert's output folder, given as `scenefit bake --texture`: its files are inputs
    listed = {p.name for p in asset_files(folder)}
    assert {p.name for p in folder.iterdir() if p.is_file()} <= listed and len(listed) >= 2
