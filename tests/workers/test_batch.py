"""`scenefit batch`: the jobs file, the in-process runner and the same jobs on a local Ray cluster."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.workers.batch import InProcessDispatcher, run_batch
from scenefit.workers.job_worker import JOB_FOLDER_PREFIX, JobWorker
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import read_image, write_image
from scenefit.workers.jobs import load_jobs
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from conftest import shared_tiny_pair

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


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The three jobs run once in this process (the reference the Ray run is compared with)."""
    root = tmp_path_factory.mktemp("batch_in_process")
    jobs_path = make_inputs(root / "in")
    outcomes = run_batch(load_jobs(jobs_path), root / "out")
    return jobs_path, root / "out", outcomes


@pytest.fixture(scope="module")
def local_ray():
    """One small local Ray cluster for this module's Ray tests; the module's functions and classes
    travel to its workers by value (the workers cannot import the test module)."""
    ray = pytest.importorskip("ray")
    from ray import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ray.init(num_cpus=2, object_store_memory=80 * 2**20, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()
    cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def test_jobs_file_paths_defaults_and_order(tmp_path):
    jobs = load_jobs(make_inputs(tmp_path))
    assert [j.name for j in jobs.jobs] == ["a", "b", "c"]
    a, b, c = jobs.jobs
    assert a.asset == (tmp_path / "ball").resolve() and a.photo == (tmp_path / "room.png").resolve()
    assert a.stages == ("convert", "light")          # pipeline order, whatever the file's order
    assert c.stages == ("light",) and b.run.seed == 1 and a.run.preset == "draft" and a.at == (0.5, 0.7)
    assert jobs.settings.retries == 1 and jobs.settings.num_gpus == "auto"


def test_a_job_may_name_the_folder_a_gltf_came_in(tmp_path):
    path = make_inputs(tmp_path)
    (tmp_path / "Fox").mkdir()
    (tmp_path / "Fox" / "Fox.glb").write_bytes(b"glTF")
    (tmp_path / "Fox" / "LICENSE.md").write_text("CC-BY")
    path.write_text(path.read_text().replace('asset = "ball"\nseed', 'asset = "Fox"\nseed'))
    assert load_jobs(path).jobs[1].asset == (tmp_path / "Fox" / "Fox.glb").resolve()
    (tmp_path / "Fox" / "Fox.gltf").write_text("{}")
    with pytest.raises(InputError, match="holds 2 asset files"):
        load_jobs(path)


@pytest.mark.parametrize("change, message", [
    (lambda t: t.replace('asset = "ball"\nseed', 'asset = "nothing"\nseed'), "the asset"),
    (lambda t: t.replace('name = "b"', 'name = "a"'), "two jobs are named 'a'"),
    (lambda t: t.replace('name = "c"', 'name = "../c"'), "needs a name"),
    (lambda t: t.replace('stages = ["light"]', 'stages = ["light", "paint"]'), "unknown stage 'paint'"),
    (lambda t: t.replace("at = [0.5, 0.7]", "at = [0.5, 1.7]"), r"at must be \[x, y\]"),
    (lambda t: t.replace('preset = "draft"', 'preset = "fast"'), "preset must be one of"),
    (lambda t: t.replace("seed = 1", "sed = 1"), "unknown key 'sed'"),
    (lambda t: t.replace("retries = 1", "retries = -1"), "retries must be"),
    (lambda t: t.replace('photo = "room.png"\n', ''), "needs a photo"),
    (lambda t: t.replace("[[job]]", "[[jobs]]"), "unknown table 'jobs'"),
    (lambda t: t + "[[job\n", "not valid TOML"),
    (lambda t: t + "[models]\nbase = 'x'\n", r"\[models\]: unknown key 'base'"),
    (lambda t: t + "[models]\ndevice_type = 'tpu'\n", "device_type must be one of"),
    (lambda t: t.replace("seed = 1", "overrides = { paint = { iterations = 2 } }"), "unknown stage 'paint'"),
])
def test_jobs_file_errors_are_one_sentence(tmp_path, change, message):
    path = make_inputs(tmp_path)
    path.write_text(change(path.read_text()))
    with pytest.raises(InputError, match=message) as error:
        load_jobs(path)
    assert "\n" not in str(error.value).strip()


def test_in_process_batch_writes_folders_summary_and_resumes(in_process, capsys):
    jobs_path, out, outcomes = in_process
    assert [(o.name, o.status, o.attempts) for o in outcomes] == [("a", "done", 1), ("b", "done", 1), ("c", "done", 1)]
    for name in "abc":
        report = json.loads((out / name / "report.json").read_text())
        assert report["status"] == "done" and report["job"]["name"] == name
        assert (out / name / "light" / "light.exr").is_file()
        # Paths in the report are inside the job's folder, relative to it.
        assert (out / name / report["stages"]["run"]["stages"]["light"]["report"]["outputs"]["hdr_exr"]).is_file()
    assert (out / "a" / "convert" / "maps" / "base_color.png").is_file() and not (out / "c" / "convert").exists()
    assert outcomes[0].quality["convert_psnr_db"] > 30.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"done": 3, "skipped": 0, "failed": 0}
    assert "| a | done | 1 |" in (out / "summary.md").read_text()
    sheet = read_image(out / "contact_sheet.png")
    assert sheet.shape[0] > 0 and sheet.shape[1] == 3 * 192      # three cells in one row
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".scenefit-run"]  # no staging folders left
    # No record or report names the worker's temporary copies of the inputs, gone once the job ended.
    assert not [p for p in out.rglob("*.json") if JOB_FOLDER_PREFIX in p.read_text()]

    # A second run does nothing: every job is skipped and no job folder is touched.
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.parent != out}
    assert main(["batch", str(jobs_path), "--out", str(out)]) == 0
    assert "0 done, 3 skipped" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.parent != out} == before


def test_failed_job_is_reported_and_retried_by_the_next_run(tmp_path, capsys):
    jobs = load_jobs(make_inputs(tmp_path / "in", retries=2))
    outcomes = run_batch(jobs, tmp_path / "out", InProcessDispatcher(jobs.settings, AlwaysFailingWorker))
    by_name = {o.name: o for o in outcomes}
    assert by_name["b"].status == "failed" and by_name["b"].attempts == 3
    assert "injected failure" in by_name["b"].error
    assert by_name["a"].status == by_name["c"].status == "done"
    report = json.loads((tmp_path / "out" / "b" / "report.json").read_text())
    assert report["status"] == "failed" and report["attempts"] == 3 and "injected failure" in report["error"]
    assert "| b | failed | 3 |" in (tmp_path / "out" / "summary.md").read_text()
    # The command line says so and exits 1; the next run retries only the failed job.
    assert main(["batch", str(jobs.path), "--out", str(tmp_path / "out")]) == 0
    assert "1 done, 2 skipped" in capsys.readouterr().out
    assert json.loads((tmp_path / "out" / "b" / "report.json").read_text())["status"] == "done"


def test_cli_bad_jobs_file_exits_2(tmp_path, capsys):
    (tmp_path / "jobs.toml").write_text("[[job]]\nname = 'x'\n")
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out")]) == 2
    assert "asset is missing" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


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


def test_a_changed_job_runs_again_reusing_its_unchanged_stages(tmp_path, capsys):
    """A job edited since an earlier batch (or whose input files changed) used to be skipped as done, its
    folder then holding another job's results. It runs again, and its earlier stages whose inputs and
    settings are the same travel with it and are reused; an input file touched but not changed is the same."""
    make_inputs(tmp_path)
    jobs_path = tmp_path / "jobs.toml"
    text = ('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
            'stages = ["convert", "light", "compose"]\n[[job]]\nname = "a"\nasset = "ball"\n'
            'overrides = { compose = { shadow_type = "ratio" } }\n')
    jobs_path.write_text(text)
    out = tmp_path / "out"
    args = ["batch", str(jobs_path), "--out", str(out)]

    def statuses() -> dict:
        stages = json.loads((out / "a" / "report.json").read_text())["stages"]["run"]["stages"]
        return {name: stage["status"] for name, stage in stages.items() if name in ("convert", "light", "compose")}

    assert main(args) == 0 and statuses() == {"convert": "ran", "light": "ran", "compose": "ran"}
    capsys.readouterr()
    first = (out / "a" / "compose" / "composite.png").read_bytes()
    photo = tmp_path / "room.png"
    photo.write_bytes(photo.read_bytes())   # touched, not changed: still done
    assert main(args) == 0 and "0 done, 1 skipped" in capsys.readouterr().out

    jobs_path.write_text(text.replace('"ratio"', '"none"'))   # compose's setting only
    assert main(args) == 0
    said = capsys.readouterr()
    assert "1 done, 0 skipped" in said.out and "[a] changed since the earlier run" in said.err
    assert statuses() == {"convert": "reused", "light": "reused", "compose": "ran"}
    assert "; convert, light reused" in said.err   # said, and in the summary
    assert "| a | done | 1 |" in (out / "summary.md").read_text() and "| convert, light |" in (out / "summary.md").read_text()
    assert json.loads((out / "summary.json").read_text())["jobs"][0]["reused"] == ["convert", "light"]
    assert (out / "a" / "compose" / "composite.png").read_bytes() != first   # no shadow now, not the old one
    assert main(args) == 0 and "0 done, 1 skipped" in capsys.readouterr().out

    write_image(photo, np.full((48, 64, 3), 0.4, np.float32))   # another photo under the same name
    assert main(args) == 0 and "1 done, 0 skipped" in capsys.readouterr().out
    assert statuses() == {"convert": "reused", "light": "ran", "compose": "ran"}
    assert main(args + ["--replace"]) == 0   # --replace runs the job again from scratch
    assert statuses() == {"convert": "ran", "light": "ran", "compose": "ran"}


def test_a_job_of_an_obj_takes_its_material_library_and_maps_along(tmp_path, capsys):
    """A job's .obj travelled alone (a .gltf took its whole folder): the worker read it without its .mtl
    and maps, and the batch fitted a flat white where `scenefit convert` fits the texture. Its files now
    travel as the file names them (a map in a subfolder, a link by its own name); one it names outside
    its folder is refused in one sentence before any job (a downloaded asset could name any file)."""
    from asset_builder import write_obj

    from scenefit.core.data.imageio import read_image

    make_inputs(tmp_path)
    rng = np.random.default_rng(3)
    obj = Path(write_obj(tmp_path / "model", uv_sphere(0.5, 16, 8), rng.uniform(0.1, 0.9, (32, 32, 3)).astype(np.float32)))
    (tmp_path / "model" / "lib").mkdir()
    (tmp_path / "model" / "albedo.png").rename(tmp_path / "model" / "lib" / "albedo.png")
    (tmp_path / "model" / "Textures").mkdir()
    (tmp_path / "model" / "Textures" / "albedo.png").symlink_to(Path("..") / "lib" / "albedo.png")
    mtl = tmp_path / "model" / "ball.mtl"
    mtl.write_text(mtl.read_text().replace("map_Kd albedo.png", "map_Kd Textures/albedo.png"))
    (tmp_path / "jobs.toml").write_text('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
                                        'stages = ["convert"]\n[[job]]\nname = "obj"\nasset = "model/ball.obj"\n')
    out = tmp_path / "model" / "runs"   # the batch's folder inside the asset's: not an input of the job
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out), "--quiet"]) == 0
    assert main(["convert", str(obj), "--out", str(tmp_path / "convert"), "--preset", "draft", "--quiet"]) == 0
    batch = read_image(out / "obj" / "convert" / "maps" / "base_color.png")
    alone = read_image(tmp_path / "convert" / "maps" / "base_color.png")
    assert batch.std() > 0.1 and batch.shape == alone.shape and np.abs(batch - alone).max() < 1e-6
    capsys.readouterr()
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]) == 0   # its own results are no input
    assert "0 done, 1 skipped" in capsys.readouterr().out

    secret = tmp_path / "secret.png"
    secret.write_bytes(b"not for the cluster")
    (tmp_path / "model" / "lib" / "leak.png").symlink_to(secret)
    # the asset the jobs file names may itself be a link (its files are what it names, beside the link)
    (tmp_path / "library").mkdir()
    (tmp_path / "library" / "chair.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "model" / "chair.obj").symlink_to(tmp_path / "library" / "chair.obj")
    from scenefit.workers.job_inputs import job_files
    from scenefit.workers.jobs import Job

    assert list(job_files(Job(name="l", asset=tmp_path / "model" / "chair.obj", stages=("convert",)))) == \
        ["asset/chair.obj"]
    for named, shown in (("../secret.png", f"'{secret}'"), (str(secret), f"'{secret}'"),
                         ("lib/leak.png", f"'{tmp_path / 'model' / 'lib' / 'leak.png'}', a link to '{secret}'")):
        mtl.write_text(f"newmtl Ball\nmap_Kd {named}\n")
        assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "elsewhere")]) == 2
        said = capsys.readouterr().err.strip()
        assert f"'ball.obj' reads {shown}, outside its folder" in said and len(said.splitlines()) == 1
        assert not (tmp_path / "elsewhere").exists()


def test_a_blend_job_sends_the_images_it_reads_and_no_others(tmp_path):
    """A .blend's external images (not packed) travel, found by linking its images for a look (the open
    file keeps what it had); other images beside it (photos, renders) do not, so they neither travel nor
    change its digest. An .fbx sends the images beside it whose names it holds."""
    import bpy

    from scenefit.core.data.imageio import write_image
    from scenefit.workers.job_inputs import job_digest, job_files
    from scenefit.workers.jobs import Job

    for name in ("textures/wood.png", "textures/unused.png", "photos/room.png"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        write_image(tmp_path / name, np.full((4, 4, 3), 0.5, np.float32))
    script = (f"import bpy\nbpy.ops.wm.read_factory_settings(use_empty=True)\n"
              f"image = bpy.data.images.load({str(tmp_path / 'textures' / 'wood.png')!r})\nimage.use_fake_user = True\n"
              f"bpy.ops.wm.save_as_mainfile(filepath={str(tmp_path / 'props.blend')!r}, relative_remap=True)\n")
    import subprocess
    subprocess.run([sys.executable, "-c", script], check=True, capture_output=True)
    before = (len(bpy.data.images), len(bpy.data.libraries))
    job = Job(name="a", asset=tmp_path / "props.blend", stages=("convert",))
    files = job_files(job)
    assert sorted(files) == ["asset/props.blend", "asset/textures/wood.png"]
    assert (len(bpy.data.images), len(bpy.data.libraries)) == before   # nothing of the look stays
    digest = job_digest(job, files)
    write_image(tmp_path / "photos" / "room.png", np.full((4, 4, 3), 0.9, np.float32))   # another job's photo
    assert job_digest(job, job_files(job)) == digest
    write_image(tmp_path / "textures" / "wood.png", np.full((4, 4, 3), 0.1, np.float32))  # its own texture
    assert job_digest(job, job_files(job)) != digest

    # a headless batch run in Blender with that .blend open (Blender cannot link from the open file)
    opened = subprocess.run([sys.executable, "-c", f"import bpy\nbpy.ops.wm.open_mainfile(filepath={str(tmp_path / 'props.blend')!r})\n"
                             "from scenefit.workers.job_inputs import job_files\nfrom scenefit.workers.jobs import Job\n"
                             f"print('FILES', sorted(job_files(Job(name='a', asset=__import__('pathlib').Path({str(tmp_path / 'props.blend')!r}), "
                             "stages=('convert',)))))\n"], capture_output=True, text=True)
    assert "FILES ['asset/props.blend', 'asset/textures/wood.png']" in opened.stdout, opened.stderr[-2000:]

    # an .fbx: the images whose whole names it holds ("wood.png", not "unused.png" inside "not_unused.png"),
    # never its own batch's outputs beside it
    (tmp_path / "sofa.fbx").write_bytes(b"Kaydara FBX Binary\x00 Texture::Wood RelativeFilename textures\\wood.png"
                                        b"\x00S\x0e\x00\x00\x00not_unused.png")
    from scenefit.core.base.output_folder import MARKER

    (tmp_path / "runs" / "sofa" / "textures").mkdir(parents=True)
    (tmp_path / "runs" / MARKER).write_text("{}")
    write_image(tmp_path / "runs" / "sofa" / "textures" / "wood.png", np.zeros((4, 4, 3), np.float32))
    files = job_files(Job(name="b", asset=tmp_path / "sofa.fbx", stages=("convert",)))
    assert sorted(files) == ["asset/sofa.fbx", "asset/textures/wood.png"]


def test_blend_tiles_and_frames_and_an_unreadable_blend(tmp_path):
    """A UDIM image's tiles and a sequence's frames travel (the .blend names one file for all); a .blend
    Blender cannot read is one sentence."""
    from scenefit.blender_io.asset_file import _tiles_or_frames, blend_external_files

    for name in ("wall.1001.png", "wall.1002.png", "wall.png", "walls.1003.png", "fire_0001.png", "fire_0002.png"):
        (tmp_path / name).write_bytes(b"x")
    tiles = _tiles_or_frames(tmp_path / "wall.<UDIM>.png", "TILED")
    assert sorted(p.name for p in tiles) == ["wall.1001.png", "wall.1002.png"]
    for name in ("rock_1001_4k.png", "rock_1002_4k.png", "rock_1001_2k.png"):   # digits after the tile's own
        (tmp_path / name).write_bytes(b"x")
    assert sorted(p.name for p in _tiles_or_frames(tmp_path / "rock_<UDIM>_4k.png", "TILED")) == \
        ["rock_1001_4k.png", "rock_1002_4k.png"]
    assert sorted(p.name for p in _tiles_or_frames(tmp_path / "fire_0001.png", "SEQUENCE")) == \
        ["fire_0001.png", "fire_0002.png"]
    (tmp_path / "broken.blend").write_bytes(b"BLENDER-v400 not really")
    with pytest.raises(InputError, match=r"^Blender cannot read '.*broken\.blend' \(.*\); open it in Blender and save "
                                         r"it again\.$"):
        blend_external_files(tmp_path / "broken.blend")


def test_an_earlier_stage_holding_a_link_is_not_sent(tmp_path):
    """Earlier stages travel as files: one holding a link (to anything) would send what it points at, so
    it runs again instead."""
    from scenefit.workers.payload import finished_stage_folders

    for stage in ("convert", "light"):
        (tmp_path / "run" / stage).mkdir(parents=True)
        (tmp_path / "run" / stage / "stage.json").write_text("{}")
    (tmp_path / "secret.txt").write_text("x")
    assert [p.name for p in finished_stage_folders(tmp_path / "run")] == ["convert", "light"]
    (tmp_path / "run" / "light" / "light.exr").symlink_to(tmp_path / "secret.txt")
    assert [p.name for p in finished_stage_folders(tmp_path / "run")] == ["convert"]



def test_a_changed_job_that_fails_keeps_its_earlier_stages_for_the_next_try(tmp_path):
    """A job changed since a done run, failing this time, was written down as failed with nothing else: the
    earlier run's finished stages were lost and the next try ran all of them again."""
    make_inputs(tmp_path)
    text = ('[batch]\nretries = 0\n[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
            'stages = ["convert", "light", "compose"]\n[[job]]\nname = "b"\nasset = "ball"\n'
            'overrides = { compose = { shadow_type = "ratio" } }\n')
    (tmp_path / "jobs.toml").write_text(text)
    out = tmp_path / "out"
    assert [o.status for o in run_batch(load_jobs(tmp_path / "jobs.toml"), out)] == ["done"]
    (tmp_path / "jobs.toml").write_text(text.replace('"ratio"', '"none"'))
    jobs = load_jobs(tmp_path / "jobs.toml")
    assert [o.status for o in run_batch(jobs, out, InProcessDispatcher(jobs.settings, AlwaysFailingWorker))] == ["failed"]
    report = json.loads((out / "b" / "report.json").read_text())
    assert report["status"] == "failed" and report["kept"]["stages"] == ["convert", "camera", "light", "compose"]
    assert [o.status for o in run_batch(jobs, out)] == ["done"]
    stages = json.loads((out / "b" / "report.json").read_text())["stages"]["run"]["stages"]
    assert {name: stages[name]["status"] for name in ("convert", "light", "compose")} == \
        {"convert": "reused", "light": "reused", "compose": "ran"}


def test_an_install_without_reuse_from_is_not_given_it(tmp_path):
    """A worker install from before `scenefit batch --reuse-from` would refuse the whole job over the flag:
    it is asked first, and only one that has it is given it."""
    from scenefit.workers.remote import install_takes_reuse_from

    older = tmp_path / "python"
    older.write_text("#!/bin/sh\necho 'usage: scenefit batch [-h] [--out OUT] [--replace] jobs'\n")
    older.chmod(0o755)
    assert install_takes_reuse_from(sys.executable) and not install_takes_reuse_from(str(older))
    assert not install_takes_reuse_from(str(tmp_path / "missing-python"))


def test_a_convert_job_of_several_materials_fits_them_as_scenefit_convert_does(tmp_path):
    """A batch convert job read the asset as one atlas texture and capped it whole (half the detail per
    material of `scenefit convert`'s: the corpus's ToyCar at a 512² atlas against 1024²); it now fits each
    material in its own cell, and its maps are the command line's."""
    from scenefit.core.data.imageio import read_image, write_image

    make_inputs(tmp_path)
    mesh, rng = uv_sphere(0.5, 16, 8), np.random.default_rng(5)
    folder = tmp_path / "two"
    folder.mkdir()
    for name in ("red", "blue"):
        write_image(folder / f"{name}.png", rng.uniform(0.1, 0.9, (512, 512, 3)).astype(np.float32))   # draft's cap
    (folder / "two.mtl").write_text("newmtl Red\nmap_Kd red.png\nnewmtl Blue\nmap_Kd blue.png\n")
    lines = ["mtllib two.mtl"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    half = len(mesh.faces) // 2
    for material, faces in (("Red", mesh.faces[:half]), ("Blue", mesh.faces[half:])):
        lines += [f"usemtl {material}"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    (folder / "two.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "jobs.toml").write_text('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
                                        'stages = ["convert"]\n[[job]]\nname = "two"\nasset = "two/two.obj"\n')
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert main(["convert", str(folder / "two.obj"), "--out", str(tmp_path / "convert"), "--preset", "draft",
                 "--quiet"]) == 0
    batch = read_image(tmp_path / "out" / "two" / "convert" / "maps" / "base_color.png")
    alone = read_image(tmp_path / "convert" / "maps" / "base_color.png")
    assert batch.shape == alone.shape == (1024, 1024, 3) and np.abs(batch - alone).max() < 1e-6


def test_a_batch_stopped_half_way_says_which_jobs_it_finished_and_its_summary_matches(tmp_path, monkeypatch, capsys):
    """Ctrl-C half-way through a batch said "'DIR' is unchanged (nothing of this run was written to it)" though
    the jobs finished before it were in DIR, and its summary.md still described the earlier batch."""
    make_inputs(tmp_path)
    out = tmp_path / "out"
    args = ["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]
    assert main(args) == 0
    before = (out / "c" / "report.json").read_text()
    run = JobWorker.run

    def stopped_at_b(self, payload, progress_sink=None):
        if payload.job.name == "b":
            raise KeyboardInterrupt
        return run(self, payload, progress_sink)

    monkeypatch.setattr(JobWorker, "run", stopped_at_b)
    capsys.readouterr()
    assert main(args + ["--replace"]) == 130
    said = capsys.readouterr().err.strip().splitlines()[-1]
    assert said == (f"scenefit: interrupted; the jobs finished before it (a) are in '{out}', each folder whole, the "
                    "others as they were (summary.md says which): run the same command again to run them.")
    summary = json.loads((out / "summary.json").read_text())
    assert [job["status"] for job in summary["jobs"]] == ["done", "interrupted", "interrupted"]
    assert "1 done, 0 skipped (done before), 0 failed, 2 not run (the batch was interrupted)" in \
        (out / "summary.md").read_text()
    assert (out / "c" / "report.json").read_text() == before   # a job not reached is as it was
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]   # nothing half-written beside it
