"""Every stage sees the photo through one camera: `scenefit run` estimates it (fSpy, EXIF,
the photo's lines, else the defaults), the user's --fov / --pitch / --roll win, and the light
stage's report hands it to adapt and compose, roll included."""
from __future__ import annotations

import json

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere


@pytest.fixture
def inputs(tmp_path):
    asset = save_asset_folder(uv_sphere(0.5, 12, 6), PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0),
                              tmp_path / "asset")
    photo = write_image(tmp_path / "room.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                               (48, 64, 3)).astype(np.float32))
    return asset, photo


def run(tmp_path, asset, photo, *extra: str) -> dict:
    out = tmp_path / "run"
    assert main(["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
                 "--guidance", "none", "--spp", "2", "--quiet", *extra]) == 0
    light = json.loads((out / "light" / "report.json").read_text())
    compose = json.loads((out / "compose" / "report.json").read_text())
    return {"light": light["decisions"], "compose": compose}


def test_a_photo_without_lines_keeps_the_default_camera_and_says_so(tmp_path, inputs):
    got = run(tmp_path, *inputs)
    camera = got["light"]["camera"]
    assert camera["fallback"] is True and camera["pitch_source"] == "default" and camera["fov_source"] == "default"
    assert got["light"]["photo_camera"]["pitch_deg"] == -10.0 and got["light"]["photo_camera"]["roll_deg"] == 0.0
    assert got["compose"]["inputs"]["camera_from"] == "the camera stage (camera/camera.json)"


def test_the_users_pitch_roll_and_fov_win_and_reach_compose(tmp_path, inputs, monkeypatch):
    import scenefit.core.pipeline.steps.compose as compose_step

    seen = {}
    real = compose_step.compose_to_folder

    def spy(inputs_, *args, **kwargs):
        seen["camera"] = inputs_.camera
        return real(inputs_, *args, **kwargs)

    monkeypatch.setattr(compose_step, "compose_to_folder", spy)
    got = run(tmp_path, *inputs, "--pitch", "-20", "--roll", "3", "--fov", "50")
    camera = got["light"]["camera"]
    assert (camera["pitch_deg"], camera["roll_deg"], camera["fov_deg"]) == (-20.0, 3.0, 50.0)
    assert camera["pitch_source"] == camera["roll_source"] == camera["fov_source"] == "user"
    assert got["light"]["photo_camera"]["roll_deg"] == 3.0
    assert (seen["camera"].pitch_deg, seen["camera"].roll_deg, seen["camera"].fov_deg) == (-20.0, 3.0, 50.0)


def test_a_broken_fspy_file_is_one_sentence_before_any_work(tmp_path, inputs, capsys):
    broken = tmp_path / "photo.fspy"
    broken.write_bytes(b"not an fspy file")
    assert main(["run", str(inputs[0]), "--photo", str(inputs[1]), "--at", "0.5,0.8", "--out", str(tmp_path / "run"),
                 "--preset", "draft", "--guidance", "none", "--fspy", str(broken), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scenefit: error:") and "fSpy" in err and "\n" not in err
    assert not (tmp_path / "run").exists()


def test_scenefit_light_uses_the_estimate_and_the_users_values(tmp_path, inputs):
    _, photo = inputs
    out = tmp_path / "light"
    assert main(["light", "--photo", str(photo), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
                 "--roll", "2", "--pitch", "-15", "--quiet"]) == 0
    decisions = json.loads((out / "report.json").read_text())["decisions"]
    assert decisions["camera"]["roll_source"] == "user" and decisions["camera"]["fov_source"] == "default"
    assert (decisions["photo_camera"]["roll_deg"], decisions["photo_camera"]["pitch_deg"]) == (2.0, -15.0)


@pytest.mark.parametrize("made_by", ["run", "light"])
def test_scenefit_compose_keeps_the_lens_shift_of_the_runs_camera_stage(tmp_path, inputs, made_by):
    """An fSpy project whose principal point is off the photo's centre: the camera stage keeps the lens
    shift, and `scenefit compose` given that run's light map renders through the same camera, shift included
    (it once read the light report's camera, which had none). Either run: `scenefit run`'s or `scenefit light`'s."""
    from camera_scenes import fspy_project_bytes

    from scenefit.core.pipeline.layout import camera_of
    from scenefit.core.scene.camera import PhotoCamera

    asset, photo = inputs
    project = tmp_path / "room.fspy"
    project.write_bytes(fspy_project_bytes(PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=55.0, width=64,
                                                       height=48), principal=(0.3, -0.2)))
    made = tmp_path / made_by
    if made_by == "run":
        assert main(["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(made), "--fspy",
                     str(project), "--preset", "draft", "--guidance", "none", "--spp", "2", "--quiet"]) == 0
        light = made / "light" / "light.exr"
    else:
        assert main(["light", "--photo", str(photo), "--at", "0.5,0.8", "--out", str(made), "--fspy", str(project),
                     "--preset", "draft", "--critic", "none", "--quiet"]) == 0
        light = made / "light.exr"
    stage_camera, _ = camera_of(made, 64, 48)
    assert (stage_camera.shift_x, stage_camera.shift_y) != (0.0, 0.0)   # (fSpy's principal point, off centre)

    out = tmp_path / "composed"
    assert main(["compose", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--light", str(light),
                 "--out", str(out), "--preset", "draft", "--spp", "2", "--quiet"]) == 0
    composed = json.loads((out / "report.json").read_text())
    assert "camera stage" in composed["inputs"]["camera_from"]
    camera = composed["camera"]
    assert (camera["shift_x"], camera["shift_y"]) == pytest.approx((stage_camera.shift_x, stage_camera.shift_y))
    assert camera["fov_deg"] == pytest.approx(stage_camera.fov_deg)

    # --fov given to compose wins over the stage's, and the shift stays.
    assert main(["compose", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--light", str(light),
                 "--out", str(tmp_path / "wider"), "--fov", "70", "--preset", "draft", "--spp", "2", "--quiet"]) == 0
    wider = json.loads((tmp_path / "wider" / "report.json").read_text())["camera"]
    assert wider["fov_deg"] == 70.0 and wider["shift_x"] == pytest.approx(stage_camera.shift_x)
