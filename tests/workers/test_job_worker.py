"""One worker's life: the models loaded once for all its jobs, an earlier run's stages reused, the
add-on's plain data taken, a killed worker's folder cleared."""
from __future__ import annotations

import json
import sys
from pathlib import Path


from scenefit.cli import main
from scenefit.workers.batch import run_batch
from scenefit.workers.jobs import load_jobs
from conftest import shared_tiny_pair
from batch_inputs import make_inputs, outputs


def test_model_cache_loads_once_and_survives_a_released_text_encoder(tmp_path):
    from scenefit.core.guidance import ModelConfig
    from scenefit.core.guidance.models import ModelCache
    try:   # the tiny models' builder is moving from core/guidance/testing.py to devtools/
        from scenefit.devtools.tiny_models import build_tiny_sd
    except ImportError:
        from scenefit.core.guidance.testing import build_tiny_sd

    config = ModelConfig(base_model=str(build_tiny_sd(tmp_path / "sd")), local_files_only=True)
    cache = ModelCache()
    first = cache.get(config, need_inpaint=False)
    first.embed("a ball")
    first.release_text_encoder()                 # as the adapt stage does at its start
    second = cache.get(config, need_inpaint=False)
    assert cache.loads == 1 and second.unet is first.unet
    assert second.embed("a muddy ball").shape[1] == 77


def test_work_remotely_takes_the_add_ons_plain_data(tmp_path):
    """The add-on's background job hands arrays and a worker address; the folder comes back."""
    from scenefit.core.data.asset_io import load_asset_folder
    from scenefit.workers.remote import work_remotely

    make_inputs(tmp_path / "in")
    mesh, maps = load_asset_folder(tmp_path / "in" / "ball")
    events = []
    result = work_remotely({"mesh": mesh, "maps": maps, "photo": str(tmp_path / "in" / "room.png"), "at": (0.5, 0.7),
                            "stages": ["light"], "preset": "draft", "name": "blend-job", "worker": sys.executable,
                            "out": str(tmp_path / "back")}, progress=events.append)
    assert result["folder"] == str(tmp_path / "back" / "blend-job") and result["report"]["status"] == "done"
    assert (tmp_path / "back" / "blend-job" / "light" / "light.exr").is_file()
    assert result["report"]["job"]["stages"] == ["light"] and [e.stage for e in events][-1] == "light"


def test_a_worker_run_reuses_the_stages_of_the_earlier_run_it_is_given(tmp_path, capsys):
    """Run All on a worker reused nothing (a local Run All reuses the last run's stages): the earlier run's
    finished stages now travel with the job, here to another install's process through `scenefit batch
    --reuse-from`, and those whose inputs and settings are the same come back reused."""
    from scenefit.core.data.asset_io import load_asset_folder
    from scenefit.workers.remote import work_remotely

    make_inputs(tmp_path / "in")
    mesh, maps = load_asset_folder(tmp_path / "in" / "ball")
    data = {"mesh": mesh, "maps": maps, "photo": str(tmp_path / "in" / "room.png"), "at": (0.5, 0.7),
            "stages": ["convert", "light", "compose"], "preset": "draft", "worker": sys.executable,
            "overrides": {"compose": {"shadow_type": "ratio"}}}

    def statuses(result) -> dict:
        stages = result["report"]["stages"]["run"]["stages"]
        return {name: stages[name]["status"] for name in ("convert", "light", "compose")}

    first = work_remotely(dict(data, name="run-1", out=str(tmp_path / "back")))
    assert statuses(first) == {"convert": "ran", "light": "ran", "compose": "ran"}
    second = work_remotely(dict(data, name="run-2", out=str(tmp_path / "back"), earlier=first["folder"],
                                overrides={"compose": {"shadow_type": "none"}}))
    assert statuses(second) == {"convert": "reused", "light": "reused", "compose": "ran"}
    assert (Path(second["folder"]) / "convert" / "maps" / "texture.pt").is_file()   # copied in, whole
    assert (tmp_path / "back" / "run-1" / "convert" / "stage.json").is_file()   # the earlier run as it was

    assert main(["batch", str(tmp_path / "in" / "jobs.toml"), "--out", str(tmp_path / "x"), "--reuse-from",
                 str(tmp_path / "nowhere")]) == 2
    said = capsys.readouterr().err.strip()
    assert said.endswith("is not a folder; give an earlier batch's --out folder.") and len(said.splitlines()) == 1
    assert not (tmp_path / "x").exists()


TINY_JOBS = """
[batch]
retries = 0
[models]
base_model = "./tiny/sd2-base"
inpaint_model = "./tiny/sd2-inpaint"
local_files_only = true
[defaults]
preset = "draft"
photo = "room.png"
at = [0.5, 0.7]
asset = "ball"
stages = ["convert", "light", "adapt", "compose"]
prompt = "a mossy ball"
overrides = { convert = { iterations = 8 }, light = { map_height = 16, optimise = { iterations = 2 }, apparatus = { render_size = 16, spp = 2 }, diffusion = { model_resolution = 32 }, outpaint = { resolution = 32, steps = 1 } }, adapt = { iterations = 2, model_resolution = 32, views_per_step = 1, preview_every = 1, checkpoint_every = 100, stages = [[1.0, 16, 2, [500, 990]]] } }
[[job]]
name = "first"
[[job]]
name = "second"
[[job]]
name = "edit"
mode = "edit"
prompt = ""
object_prompt = "a rubber ball"
instruction = "add moss"
negative_prompt = "blurry"
seed = 5
overrides = { convert = { iterations = 4 }, light = { critic_type = "none", map_height = 16, apparatus = { render_size = 16, spp = 1 }, outpaint = { completion_type = "prior" } }, compose = { pilot_spp = 1, min_spp = 1, max_spp = 1 }, adapt = { light_type = "envmap", iterations = 1, model_resolution = 32, views_per_step = 1, preview_every = 1, checkpoint_every = 100, stages = [[1.0, 16, 1, [500, 990]]] } }
"""


def test_a_worker_loads_the_models_once_and_reuses_them_with_the_same_outputs(tmp_path, monkeypatch):
    """Two jobs with diffusion guidance in one worker: the tiny models load once (counted in the real
    loader), the second job (reused models) writes the same bytes as the first (fresh models). A third job's
    mode, object prompt, instruction, negative prompt and seed reach adapt: it adapts in mode edit with the
    prompt made of its words, as `scenefit adapt --mode edit` does, its local views lit by the run's own
    light map as its overrides ask."""
    from scenefit.core.stages.adapt.config import edit_prompt
    from scenefit.core.guidance import models as model_module
    make_inputs(tmp_path)
    (tmp_path / "tiny").symlink_to(shared_tiny_pair()[0].parent)   # the jobs file's ./tiny
    (tmp_path / "jobs.toml").write_text(TINY_JOBS)
    jobs = load_jobs(tmp_path / "jobs.toml")
    assert jobs.jobs[0].models.base_model == str((tmp_path / "tiny" / "sd2-base").resolve())   # beside the file
    real_load, loads = model_module.load_guidance_models, []

    def counted_load(config, need_inpaint, paths=None):
        loads.append(need_inpaint)
        return real_load(config, need_inpaint, paths)

    monkeypatch.setattr(model_module, "load_guidance_models", counted_load)
    outcomes = run_batch(jobs, tmp_path / "out")
    assert [(o.name, o.status) for o in outcomes] == [("first", "done"), ("second", "done"), ("edit", "done")], \
        outcomes
    assert loads == [True]                     # one model set (with the inpainting UNet) for every job
    reports = [json.loads((tmp_path / "out" / name / "report.json").read_text()) for name in ("first", "second")]
    run = reports[1]["stages"]["run"]["stages"]
    assert {name: run[name]["status"] for name in ("convert", "light", "adapt", "compose")} == dict.fromkeys(
        ("convert", "light", "adapt", "compose"), "ran")
    assert run["light"]["report"]["decisions"]["critic"]["type"] == "diffusion"   # light used the models too
    assert [r["worker"]["model_loads_by_this_worker"] for r in reports] == [1, 1]
    edit = json.loads((tmp_path / "out" / "edit" / "report.json").read_text())["stages"]["run"]
    adapt = edit["stages"]["adapt"]["report"]
    assert (adapt["config"]["mode_type"], adapt["config"]["object_prompt"], adapt["config"]["instruction"],
            adapt["config"]["negative_prompt"], adapt["config"]["seed"], adapt["config"]["views_type"],
            adapt["config"]["light_type"]) == ("edit", "a rubber ball", "add moss", "blurry", 5, "local", "envmap")
    assert edit_prompt("a rubber ball", "add moss") == "a rubber ball, with moss"
    assert "a rubber ball, with moss" in json.dumps(adapt["decisions"]["prompt"])
    assert edit["config"]["mode"] == "edit" and edit["stages"]["convert"]["report"]["config"]["seed"] == 5
    # Every image and texture the same bytes (the JSON records differ in timings and temporary paths).
    first, second = (outputs(tmp_path / "out" / name) for name in ("first", "second"))
    assert {k for k in first if not k.endswith(".json")} >= {"adapt/maps/texture.pt", "compose/composite.png"}
    assert {k: v for k, v in first.items() if not k.endswith(".json")} == {
        k: v for k, v in second.items() if not k.endswith(".json")}


def test_a_killed_workers_job_folder_is_removed_by_the_next_worker_and_nothing_else(tmp_path):
    """A worker killed mid-job (a stopped Ray actor) leaves its scenefit-job-<pid>-... folder; the next
    worker removes those whose process is gone, never a running process's or another name."""
    import os
    import subprocess

    from scenefit.workers.job_worker import JOB_FOLDER_PREFIX, remove_orphaned_job_folders

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    orphan = tmp_path / f"{JOB_FOLDER_PREFIX}{gone.pid}-abc"
    running = tmp_path / f"{JOB_FOLDER_PREFIX}{os.getpid()}-def"
    others = [tmp_path / f"{JOB_FOLDER_PREFIX}x", tmp_path / "scenefit-jobs-12-a", tmp_path / f"{JOB_FOLDER_PREFIX}12"]
    for folder in [orphan, running, *others]:
        (folder / "out").mkdir(parents=True)
        (folder / "out" / "composite.png").write_bytes(b"x")
    assert remove_orphaned_job_folders(tmp_path) == [orphan]
    assert not orphan.exists() and running.is_dir() and all(f.is_dir() for f in others)
