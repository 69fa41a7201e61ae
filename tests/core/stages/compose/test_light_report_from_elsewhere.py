"""Compose reads the light stage's report beside a light map for its camera; a report from elsewhere that is
deep, not JSON, not UTF-8 or a FIFO gives the light stage's default camera, never an exception."""
from __future__ import annotations

import os

import pytest

from scenefit.core.stages.compose import light_camera


@pytest.mark.parametrize("content", [b"[" * 100_000 + b"]" * 100_000, b"\xff\xfe not utf-8", b"[]", b"{\"decisions\": 3}",
                                     b'{"decisions": {"photo_camera": {"yaw_deg": NaN}}}', "fifo"])
def test_a_damaged_light_report_gives_the_default_camera(tmp_path, content):
    report = tmp_path / "report.json"
    if content == "fifo":
        os.mkfifo(report)
    else:
        report.write_bytes(content)
    camera, source = light_camera(tmp_path / "light.exr", {}, 64, 48)
    assert "default" in source and (camera.width, camera.height) == (64, 48)


def test_the_light_stages_own_report_gives_its_camera(tmp_path):
    (tmp_path / "report.json").write_text('{"decisions": {"photo_camera": {"yaw_deg": 90, "pitch_deg": -7, '
                                          '"fov_deg": 50, "width": 64, "height": 48, "roll_deg": 2}}}')
    camera, source = light_camera(tmp_path / "light.exr", {}, 64, 48)
    assert "report" in source and (camera.pitch_deg, camera.fov_deg, camera.roll_deg) == (-7, 50, 2)
