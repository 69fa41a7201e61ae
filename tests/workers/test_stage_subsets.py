"""Which of a job's stage subsets run: each one that runs is read from a jobs file and run by run_pipeline (its
steps, nothing more); every other is one sentence (exit 2) when the file is read, never a job that fails and
is retried."""
from __future__ import annotations

import itertools
import threading

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.base.errors import InputError
from scenefit.core.pipeline.registry import BUILT_IN

ALONE_STAGES, OPTIONAL_STAGES, PIPELINE_STAGES, STAGES = (BUILT_IN.ALONE_STAGES, BUILT_IN.OPTIONAL_STAGES,
                                                          BUILT_IN.PIPELINE_STAGES, BUILT_IN.STAGES)
from scenefit.core.pipeline import run as run_module
from scenefit.core.pipeline.run_config import RunConfig
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.workers.jobs import load_jobs

# What runs, written out (the names' declarations must give the same): convert and/or light alone, or the pipeline.
RUNS = {("convert",), ("light",), ("convert", "light"), ("convert", "light", "compose"),
        ("convert", "light", "adapt", "compose"), ("convert", "light", "compose", "bake"),
        ("convert", "light", "adapt", "compose", "bake")}
SUBSETS = [subset for n in range(1, len(STAGES) + 1) for subset in itertools.combinations(STAGES, n)]


def make_inputs(folder):
    maps = PBRMaps(base_color=np.full((16, 16, 3), 0.5, np.float32), roughness=0.5, metallic=0.0)
    save_asset_folder(uv_sphere(segments=16, rings=8), maps, folder / "ball")
    write_image(folder / "room.png", np.full((48, 64, 3), 0.5, np.float32))


def jobs_file(folder, line: str):
    path = folder / "jobs.toml"
    path.write_text('[[job]]\nname = "a"\nasset = "ball"\nphoto = "room.png"\nat = [0.5, 0.7]\n' + line)
    return path


def test_the_stage_declarations_give_the_subsets_that_run():
    alone = {subset for subset in SUBSETS if set(subset) <= set(ALONE_STAGES)}
    pipeline = {tuple(s for s in STAGES if s in PIPELINE_STAGES + extra)
                for n in range(len(OPTIONAL_STAGES) + 1) for extra in itertools.combinations(OPTIONAL_STAGES, n)}
    assert alone | pipeline == RUNS


@pytest.mark.parametrize("stages", sorted(RUNS))
def test_a_subset_that_runs_is_read_in_the_runs_order(tmp_path, stages):
    make_inputs(tmp_path)
    listed = ", ".join(f'"{s}"' for s in reversed(stages))
    assert load_jobs(jobs_file(tmp_path, f"stages = [{listed}]\n")).jobs[0].stages == stages


@pytest.mark.parametrize("stages", [s for s in SUBSETS if s not in RUNS])
def test_a_subset_that_does_not_run_is_refused_when_the_file_is_read(tmp_path, stages):
    make_inputs(tmp_path)
    listed = ", ".join(f'"{s}"' for s in stages)
    with pytest.raises(InputError) as error:
        load_jobs(jobs_file(tmp_path, f"stages = [{listed}]\n"))
    text = str(error.value)
    assert text.startswith("jobs.toml job 'a': ") and "do not run together" in text and "\n" not in text.strip()


def test_scenefit_batch_refuses_such_a_jobs_file_with_exit_2_before_any_work(tmp_path, capsys):
    make_inputs(tmp_path)
    path = jobs_file(tmp_path, 'stages = ["light", "adapt"]\n')
    assert main(["batch", str(path), "--out", str(tmp_path / "out")]) == 2
    assert "do not run together" in capsys.readouterr().err and not (tmp_path / "out").exists()


@pytest.fixture()
def steps(monkeypatch):
    """run_pipeline's steps, recorded instead of run (the inputs are still read and checked)."""
    called: list[str] = []
    monkeypatch.setattr(run_module.PipelineRun, "run_stage", lambda self, record: called.append(record.name))
    monkeypatch.setattr(run_module.PipelineRun, "finish", lambda self: called)
    return called


@pytest.mark.parametrize("stages, expected", [
    (("convert",), ["convert"]),
    (("light",), ["camera", "light"]),
    (("convert", "light"), ["convert", "camera", "light"]),
    (("convert", "light", "compose"), ["convert", "camera", "light", "compose"]),   # (adapt: no guidance, skipped)
])
def test_run_pipeline_runs_the_steps_of_the_subset_it_is_given(tmp_path, steps, stages, expected):
    make_inputs(tmp_path)
    mesh, maps = uv_sphere(0.5, 12, 6), PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.5, 0.0)
    photo = tmp_path / "room.png" if set(stages) - {"convert"} else None   # convert alone reads no photo
    run_module.run_pipeline(mesh, maps, photo, (0.5, 0.7), tmp_path / "run", RunConfig(guidance_type="none"),
                            cancel=threading.Event(), stages=stages)
    assert steps == expected


def test_run_pipeline_refuses_a_subset_that_does_not_run_before_any_work(tmp_path, steps):
    mesh, maps = uv_sphere(0.5, 12, 6), PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.5, 0.0)
    with pytest.raises(InputError, match="do not run together"):
        run_module.run_pipeline(mesh, maps, None, None, tmp_path / "run", stages=("convert", "adapt"))
    with pytest.raises(InputError, match="read a photo, and none was given"):
        run_module.run_pipeline(mesh, maps, None, None, tmp_path / "run", stages=("light",))
    assert steps == [] and not (tmp_path / "run").exists()


def test_the_light_alone_runs_without_an_asset_and_nothing_else_does(tmp_path, steps):
    make_inputs(tmp_path)
    run_module.run_pipeline(None, None, tmp_path / "room.png", (0.5, 0.7), tmp_path / "run",
                            RunConfig(guidance_type="none"), stages=("light",))
    assert steps == ["camera", "light"]
    for stages in [s for s in sorted(RUNS) if s != ("light",)]:
        with pytest.raises(InputError, match="need an asset; only light runs on a photo alone") as error:
            run_module.run_pipeline(None, None, tmp_path / "room.png", (0.5, 0.7), tmp_path / "other",
                                    RunConfig(guidance_type="none"), stages=stages)
        assert "\n" not in str(error.value)
    assert not (tmp_path / "other").exists()
