"""`scenefit run` writes the photo's camera as a stage, camera/camera.json, and light, adapt and compose read
that file as a PhotoCamera: a camera value changed reruns the camera and what reads it, never convert; a
damaged camera.json is one sentence."""
from __future__ import annotations

import json

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.base.errors import InputError
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.stages.camera_stage import read_camera, write_camera


def test_run_writes_the_camera_stage_that_light_and_compose_read(tmp_path, capsys):
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 12, 6), maps, tmp_path / "asset")
    photo = write_image(tmp_path / "photo.png", np.full((48, 64, 3), 0.5))
    out = tmp_path / "run"
    args = ["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
            "--guidance", "none", "--spp", "1", "--no-bake", "--quiet", "--pitch", "-12", "--fov", "50"]
    assert main(args) == 0, capsys.readouterr().err
    saved = json.loads((out / "camera" / "camera.json").read_text())
    assert (saved["photo_camera"]["pitch_deg"], saved["photo_camera"]["fov_deg"]) == (-12.0, 50.0)
    assert saved["estimate"]["pitch_source"] == "user"
    report = json.loads((out / "report.json").read_text())
    assert report["camera"]["status"] == "ran" and "camera" not in report["stages"]
    light = report["stages"]["light"]["report"]["decisions"]["photo_camera"]
    assert (light["pitch_deg"], light["fov_deg"]) == (-12.0, 50.0)
    assert report["stages"]["compose"]["report"]["inputs"]["camera_from"] == "the camera stage (camera/camera.json)"

    # Another pitch: the camera and the stages that read it run again; convert is reused.
    assert main(args[:-4] + ["--pitch", "-20", "--fov", "50"]) == 0
    again = json.loads((out / "report.json").read_text())
    assert again["reused"] == ["convert"] and again["camera"]["status"] == "ran"
    assert json.loads((out / "camera" / "camera.json").read_text())["photo_camera"]["pitch_deg"] == -20.0
    assert again["stages"]["light"]["report"]["decisions"]["photo_camera"]["pitch_deg"] == -20.0


def test_a_camera_file_reads_back_at_the_readers_size(tmp_path):
    camera = PhotoCamera(pitch_deg=-7.5, fov_deg=44.0, width=64, height=48, roll_deg=1.5)
    report = write_camera(camera, {"source": "lines"}, tmp_path / "camera")
    back, estimate = read_camera(report["outputs"]["camera"], 640, 480)
    assert back == PhotoCamera(pitch_deg=-7.5, fov_deg=44.0, width=640, height=480, roll_deg=1.5)
    assert estimate == {"source": "lines"}


@pytest.mark.parametrize("text", ["[]", "{}", '{"photo_camera": {"yaw_deg": 90, "pitch_deg": NaN, "fov_deg": 50, '
                                  '"roll_deg": 0}}', '{"photo_camera": {"yaw_deg": 90, "pitch_deg": 95, "fov_deg": 50, '
                                  '"roll_deg": 0}}', '{"photo_camera": {"yaw_deg": "x", "pitch_deg": 0, "fov_deg": 50, '
                                  '"roll_deg": 0}}', "[" * 100000, "\xff\xfe"])
def test_a_damaged_camera_file_is_one_sentence(tmp_path, text):
    path = tmp_path / "camera.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(InputError, match="camera stage") as error:
        read_camera(path, 64, 48)
    assert "\n" not in str(error.value)
