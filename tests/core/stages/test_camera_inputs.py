"""Numbers about the photo's camera that come from elsewhere (an fSpy project, a photo's EXIF, options, a jobs
file) are finite and in range before use, or one sentence: never an OverflowError or ValueError."""
from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.stages import camera_exif
from scenefit.core.stages.camera import check_camera_values, estimate_photo_camera, read_fspy
from scenefit.core.data import photo as photo_reading
from scenefit.core.data.photo import load_photo

PARAMS = {"principalPoint": {"x": 0.0, "y": 0.0}, "horizontalFieldOfView": 1.0,
          "cameraTransform": {"rows": np.eye(4).tolist()}, "imageWidth": 96, "imageHeight": 64}


def fspy_file(path, state_text: str):
    state = state_text.encode()
    path.write_bytes(struct.pack("<4sIII", b"fspy", 1, len(state), 0) + state)
    return path


@pytest.mark.parametrize("key, raw", [("imageWidth", "1e400"), ("imageHeight", "-1e400"), ("imageWidth", "1e300"),
                                      ("horizontalFieldOfView", "1e400"), ("imageWidth", "NaN")])
def test_an_fspy_number_out_of_range_is_one_sentence(tmp_path, key, raw):
    text = json.dumps({"cameraParameters": dict(PARAMS, **{key: 12345})}).replace("12345", raw)
    path = fspy_file(tmp_path / "room.fspy", text)
    with pytest.raises(InputError, match="room.fspy") as error:
        read_fspy(path)
    assert "\n" not in str(error.value)


def test_a_principal_point_that_is_not_a_number_is_one_sentence(tmp_path):
    text = json.dumps({"cameraParameters": dict(PARAMS, principalPoint={"x": 12345, "y": 0})}).replace("12345", "NaN")
    with pytest.raises(InputError, match="NaN is not a number") as refused:
        read_fspy(fspy_file(tmp_path / "p.fspy", text))
    assert "p.fspy" in str(refused.value) and len(str(refused.value).splitlines()) == 1


def test_the_camera_command_says_an_fspy_overflow_in_one_sentence(tmp_path, capsys):
    write_image(tmp_path / "photo.png", np.full((64, 96, 3), 0.5, np.float32))
    text = json.dumps({"cameraParameters": dict(PARAMS, imageWidth=12345)}).replace("12345", "1e400")
    fspy_file(tmp_path / "room.fspy", text)
    assert main(["camera", "--photo", str(tmp_path / "photo.png"), "--fspy", str(tmp_path / "room.fspy")]) == 2
    said = capsys.readouterr().err.strip()
    assert len(said.splitlines()) == 1 and "room.fspy" in said


@pytest.mark.parametrize("focal35", ["35 mm", "", -5, 0, 65531, 1e30, math.inf, math.nan, True])
def test_an_exif_focal_length_that_is_not_one_is_left_aside(tmp_path, monkeypatch, focal35):
    """Text, zero, negative (65531: -5 written unsigned), huge: the photo reads, the field of view is not
    taken from it, and the camera's notes say why when it was a value at all."""
    photo = tmp_path / "photo.png"
    write_image(photo, np.full((80, 120, 3), 0.5, np.float32))
    monkeypatch.setattr(photo_reading, "_metadata", lambda path: {"size": [120, 80], "focal35": focal35})
    _, info = load_photo(photo)
    assert "fov_from_metadata_deg" not in info
    estimate = estimate_photo_camera(photo)
    assert estimate.fov_source != "exif_35mm" and math.isfinite(estimate.fov_deg)
    if focal35 not in (0, ""):
        assert any("FocalLengthIn35mmFilm" in note for note in estimate.notes)


def test_a_real_focal_length_still_gives_the_field_of_view(tmp_path, monkeypatch):
    photo = tmp_path / "photo.png"
    write_image(photo, np.full((80, 120, 3), 0.5, np.float32))
    monkeypatch.setattr(photo_reading, "_metadata", lambda path: {"size": [120, 80], "focal35": 26})
    width_mm = 43.27 * 120 / math.hypot(120, 80)
    assert load_photo(photo)[1]["fov_from_metadata_deg"] == pytest.approx(
        math.degrees(2 * math.atan(width_mm / 52.0)), abs=1e-3)


def test_an_exif_focal_length_with_a_sensor_is_in_range_too(monkeypatch, tmp_path):
    class Spec:
        def __init__(self, focal):
            self.focal = focal

        def getattribute(self, name):
            return {"Exif:FocalLength": self.focal, "Model": "Canon EOS 5D"}.get(name)

    class Input:
        def __init__(self, focal):
            self.focal = focal

        def spec(self):
            return Spec(self.focal)

        def close(self):
            pass

    import OpenImageIO as oiio

    for focal, expected in ((1e30, None), (-3.0, None), ("50", None), (math.inf, None), (50.0, 50.0)):
        monkeypatch.setattr(oiio.ImageInput, "open", staticmethod(lambda path, focal=focal: Input(focal)))
        assert camera_exif.exif_focal_and_model(tmp_path / "x.jpg")[0] == expected


@pytest.mark.parametrize("values", [{"pitch_deg": 90.0}, {"pitch_deg": -89.5}, {"fov_deg": 0.5}, {"fov_deg": 171.0},
                                    {"fov_deg": math.inf}, {"roll_deg": math.nan}, {"yaw_deg": 3.0},
                                    {"pitch_deg": "ten"}])
def test_camera_values_out_of_range_are_one_sentence(values):
    with pytest.raises(InputError):
        check_camera_values(values)


@pytest.mark.parametrize("option", [["--pitch", "90"], ["--fov", "180"], ["--fov", "1e308"], ["--pitch", "-89.5"]])
def test_the_camera_and_light_commands_refuse_a_camera_that_cannot_be(tmp_path, capsys, option):
    write_image(tmp_path / "photo.png", np.full((64, 96, 3), 0.5, np.float32))
    assert main(["light", "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.7", "--out", str(tmp_path / "out"),
                 "--critic", "none", *option]) == 2
    said = capsys.readouterr().err.strip()
    assert len(said.splitlines()) == 1 and ("pitch" in said or "field of view" in said)
    assert not (tmp_path / "out").exists()
