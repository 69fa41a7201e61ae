"""The seam between Blender and the pipeline, without bpy: a Run All's request survives its run folder's
request.json whole (Resume reads it back), and one builder reads a run folder here and a worker's job folder
alike, the camera from the camera stage with its lens shift."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.guidance.models import ModelConfig
from scenefit.core.pipeline.run_config import RunConfig
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.stages.camera_stage import write_camera
from scenefit.workers.job_seam import (RunRequest, read_request, read_run_outcome, run_guidance, write_request)


def _request(out: Path) -> RunRequest:
    config = RunConfig(preset="draft", prompt="a mossy fox", negative_prompt="blurry", seed=7, size=0.3, turn_deg=15.0,
                       guidance_type="none", camera_overrides={"fov_deg": 41.0, "shift_x": 0.05},
                       camera_source="blender", camera_why="the scene camera", stage_overrides={"adapt": {"iterations": 6}},
                       models=ModelConfig(base_model="my/base"))
    return RunRequest(asset_id="a" * 32, asset_name="animal-fox", object_ids=("a" * 32,), slots=((("a" * 32, 0),),),
                      photo="/photos/swamp.jpg", placement=(0.4, 0.75), config=config, out=str(out),
                      why_no_adapt="the Style section has no prompt", scene_camera="Camera", scene="Scene")


def test_a_request_comes_back_from_its_run_folder_whole(tmp_path):
    sent = _request(tmp_path / "run-1")
    hidden = tmp_path / ".run-1.partial"   # an unfinished run keeps it in its hidden part
    hidden.mkdir()
    write_request(hidden, sent)
    back = read_request(tmp_path / "run-1", ModelConfig(base_model="my/base"))
    assert back == sent
    assert read_request(tmp_path / "run-1", ModelConfig()).config.models == ModelConfig()   # today's models
    (hidden / "request.json").write_text(json.dumps({"format": "something else"}))
    with pytest.raises(InputError, match="cannot be resumed"):
        read_request(tmp_path / "run-1", ModelConfig())
    with pytest.raises(InputError, match="kept no request.json"):
        read_request(tmp_path / "run-2", ModelConfig())


def test_run_alls_guidance_is_decided_once_for_here_and_a_worker():
    assert run_guidance("skip", "sd2", "a fox") == ("none", "skipped at the question before the run (Skip adaptation)")
    assert run_guidance("ask", "auto", "  ") == ("none", "the Style section has no prompt")
    assert run_guidance("start", "auto", "a fox") == ("auto", "") and run_guidance("ask", "sd2", "") == ("sd2", "")


def _run_report(folder: Path, adapt: str) -> dict:
    def outputs(stage):
        return {"report": {"outputs": {"weights": f"{stage}/maps/texture.pt", "base_color": f"{stage}/maps/base.png",
                                       "roughness": 0.5, "metallic": f"{stage}/maps/metallic.png"}}}
    stages = {"convert": {"status": "reused", **outputs("convert")}, "light": {"status": "ran"},
              "adapt": {"status": adapt, **(outputs("adapt") if adapt == "ran" else {"why": "no prompt"})},
              "compose": {"status": "ran"}}
    (folder / "light").mkdir(parents=True)
    (folder / "light" / "light.exr").write_bytes(b"x")
    write_camera(PhotoCamera(pitch_deg=-12.0, fov_deg=44.0, roll_deg=1.5, shift_x=0.08, shift_y=-0.03), {},
                 folder / "camera")
    return {"stage": "run", "stages": stages}


def test_one_builder_reads_a_run_here_and_a_workers_job_folder(tmp_path):
    here, there = tmp_path / "here", tmp_path / "worker" / "run-1"
    (here / "report.json").parent.mkdir(parents=True)
    report = _run_report(here, "ran")
    (here / "report.json").write_text(json.dumps(report))
    (there / "report.json").parent.mkdir(parents=True)
    job = {"status": "done", "stages": {"run": _run_report(there, "skipped")}}   # a batch job's report
    (there / "report.json").write_text(json.dumps(job))
    local, remote = read_run_outcome(here), read_run_outcome(there, ({"name": "Trim"},))
    assert local.stage == "adapt" and local.texture == str(here / "adapt/maps/texture.pt")
    assert local.maps["roughness"] == 0.5 and local.maps["base_color"] == str(here / "adapt/maps/base.png")
    assert remote.stage == "convert" and remote.adapt_skipped == "no prompt" and remote.material_maps == ({"name": "Trim"},)
    assert remote.stages == {"convert": "reused", "light": "ran", "adapt": "skipped", "compose": "ran"}
    assert local.hdr == str(here / "light/light.exr") and local.composite == ""   # (no composite written here)
    for outcome in (local, remote):   # the camera stage's camera, its lens shift kept
        camera = outcome.camera
        assert (camera.fov_deg, camera.pitch_deg, camera.roll_deg) == (44.0, -12.0, 1.5)
        assert (camera.shift_x, camera.shift_y) == (0.08, -0.03)
