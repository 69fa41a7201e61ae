"""scenefit light's small promises: strict JSON from --dry-run, a silent --quiet, the depth
model's absence decided once per process, and the artist's --sun."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scenefit.core.data.imageio import write_image


def _strict(text: str):
    def refuse(constant):
        raise ValueError(f"non-strict JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_dry_run_prints_strict_json(capsys):
    from scenefit.cli import main

    assert main(["light", "--dry-run"]) == 0
    config = _strict(capsys.readouterr().out)["config"]
    # The distance threshold is +inf (every texel of finite depth is near): null in strict JSON.
    assert config["thresholds"]["distance"] is None


def test_quiet_prints_nothing_on_success(tmp_path, capsys):
    from scenefit.cli import main

    pixels = np.full((24, 32, 3), 0.4, np.float32)
    pixels[:6] = 1.0
    write_image(tmp_path / "photo.png", pixels)
    code = main(["light", "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.8", "--out", str(tmp_path / "out"),
                 "--preset", "draft", "--depth", "geometric", "--critic", "none", "--outpaint", "prior", "--quiet"])
    captured = capsys.readouterr()
    assert code == 0 and (tmp_path / "out" / "light.exr").is_file()
    assert captured.out == "" and captured.err == ""


def test_quiet_is_one_rule_for_every_command_and_keeps_what_was_asked_for(tmp_path, capsys):
    """convert --quiet printed its per-material lines and summary; now --quiet prints nothing on stdout in
    every command, while an output asked for (--dry-run's JSON) still comes."""
    from scenefit.cli import main
    from scenefit.core.data.asset_io import save_asset_folder
    from scenefit.core.data.maps import PBRMaps
    from scenefit.core.data.primitives import uv_sphere

    asset = save_asset_folder(uv_sphere(0.5, 12, 6), PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0),
                              tmp_path / "asset")
    for out, quiet in (("loud", ()), ("quiet", ("--quiet",))):
        assert main(["convert", str(asset), "--out", str(tmp_path / out), "--preset", "draft", *quiet]) == 0
        printed = capsys.readouterr().out
        assert ("converted" in printed and "material" in printed) if not quiet else printed == "", printed
    write_image(tmp_path / "photo.png", np.full((24, 32, 3), 0.4, np.float32))
    assert main(["light", "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.8", "--dry-run", "--quiet"]) == 0
    assert "config" in _strict(capsys.readouterr().out)


def test_an_absent_depth_model_is_looked_for_once_per_process(tmp_path, monkeypatch):
    import time

    from scenefit.core.stages.light import depth
    from scenefit.core.scene.camera import PhotoCamera
    from scenefit.core.scene.floor import place_on_floor

    calls = []
    monkeypatch.setattr(depth, "load_depth_estimator", lambda *a, **k: calls.append(a) or (_ for _ in ()).throw(
        depth.ModelMissingError("not here")))
    camera = PhotoCamera(width=32, height=24)
    placement = place_on_floor(camera, (16.0, 20.0))
    photo = np.full((24, 32, 3), 0.5, np.float32)
    config = depth.DepthConfig(model="nobody/no-such-depth-model", cache_dir=str(tmp_path))
    for _ in range(3):
        start = time.perf_counter()
        result = depth.estimate_ray_distance(photo, camera, placement, config)
        assert result.method == "geometric" and time.perf_counter() - start < 0.1
    # Not in the cache: decided by a file-system look, the loader (transformers) never asked.
    assert calls == [] and "no-such-depth-model" in result.detail["why"]
    # A folder that fails to load is asked once, then remembered.
    folder = tmp_path / "broken"
    folder.mkdir()
    broken = depth.DepthConfig(model=str(folder))
    for _ in range(3):
        assert depth.estimate_ray_distance(photo, camera, placement, broken).method == "geometric"
    assert len(calls) == 1


def _evenly_lit_estimate(sun_deg):
    from scenefit.core.stages.light import estimate_light
    from scenefit.core.stages.light.depth import DepthConfig
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.scene.camera import PhotoCamera

    photo = np.full((48, 64, 3), 0.45, np.float32)
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=64, height=48)   # looks along +Y
    config = stage_config("light", "draft", scene_type="indoor", critic_type="none", sun_deg=sun_deg,
                          depth=DepthConfig(depth_type="geometric"))
    return estimate_light(photo, (32.0, 40.0), config, photo_camera=camera)


@pytest.mark.parametrize("sun, expected", [((90.0, 30.0), (1.0, 0.0)), ((-90.0, 30.0), (-1.0, 0.0)),
                                           ((180.0, 20.0), (0.0, -1.0))])
def test_the_artists_sun_is_the_dominant_light(sun, expected):
    from scenefit.core.stages.light.measure import dominant_direction

    result = _evenly_lit_estimate(sun)
    direction = np.array(result.decisions["cues"]["unseen"]["direction"])
    el = math.radians(sun[1])
    want = np.array([expected[0] * math.cos(el), expected[1] * math.cos(el), math.sin(el)])
    assert direction @ want > math.cos(math.radians(1.0)), direction
    assert result.decisions["sun"]["used"] and "--sun" in result.decisions["cues"]["direction"]["from"]
    # The map's brightest direction follows (the measure's blur and solid-angle weight move it a little).
    assert dominant_direction(result.hdr) @ want > math.cos(math.radians(25.0))
    # With or without the hint the cue prior sets the scales (S (2 / 0.25 - 1) over a lobe-shaded
    # mean colour: at least 7x), not the inverse tone curve (about 1 for a mid-grey photo).
    for estimate in (result, _evenly_lit_estimate(None)):
        assert estimate.scales["unseen"] > 7.0 and "sun" in result.decisions


def test_sun_on_the_command_line(capsys):
    from scenefit.cli import main

    assert main(["light", "--dry-run", "--sun", "45,-10"]) == 0
    assert _strict(capsys.readouterr().out)["config"]["sun_deg"] == [45.0, -10.0]
    # A sun on the left (negative azimuth) is a value, not an option argparse does not know.
    for given in (["--sun", "-45,10"], ["--sun=-45,10"], ["--sun", "-4.5e1,10"], ["--sun", "-45,+10"],
                  ["--sun", "-45.,10"]):
        assert main(["light", "--dry-run", *given]) == 0
        assert _strict(capsys.readouterr().out)["config"]["sun_deg"] == [-45.0, 10.0]
    assert main(["light", "--dry-run", "--sun", "-inf,10"]) == 2   # judged by --sun, not refused as an option
    assert "give e.g. --sun 30,45" in capsys.readouterr().err
    for bad in ("45", "north,10", "10,95"):
        assert main(["light", "--dry-run", "--sun", bad]) == 2
        assert "give e.g. --sun 30,45" in capsys.readouterr().err


def test_the_summary_line_does_not_claim_a_scene_type_it_was_unsure_of(tmp_path, capsys):
    from scenefit.cli import main
    from scenefit.core.data.imageio import linear_to_srgb
    from scenefit.core.stages.light.scene_type import SKY_RATIO_AT

    # Smooth, the top eighth SKY_RATIO_AT times brighter than the bottom: the scene-type score is 1 (unsure).
    linear = np.full((80, 64, 3), 0.1, np.float32)
    linear[:10] = 0.1 * SKY_RATIO_AT
    write_image(tmp_path / "photo.png", linear_to_srgb(linear))
    common = ["light", "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.85", "--preset", "draft",
              "--depth", "geometric", "--critic", "none", "--outpaint", "prior"]
    assert main(common + ["--out", str(tmp_path / "auto")]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "unsure" in line and "indoor {" in line and "outdoor {" in line, line
    assert "light direction guessed (--sun AZ,EL" in line, line
    assert main(common + ["--out", str(tmp_path / "told"), "--scene", "outdoor"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("light: outdoor scene, scales {") and "unsure" not in line, line
    assert main(common + ["--out", str(tmp_path / "sun"), "--sun", "30,45"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "sun 30,45 as given" in line and "guessed" not in line, line


def test_the_sun_in_a_summary_says_guessed_given_or_unused():
    from scenefit.core.stages.light.stage import sun_words

    assert sun_words({}, "Pick Sun") == "light direction guessed (Pick Sun sets it)"
    assert sun_words({"sun": {"deg": [30.0, 45.5], "used": True}}, "x") == "sun 30,45.5 as given"
    assert sun_words({"sun": {"deg": [30.0, 45.0], "used": False}}, "x").endswith("(unused by this prior)")
    # a shadow's sun: its angles as a person reads them, and how far off its clicks may leave it
    assert sun_words({"sun": {"deg": [40.000013, 35.2], "uncertainty_deg": 12.3}}, "x") == "sun 40,35.2 as given (±12°)"
    assert "(±43°: a longer shadow" in sun_words({"sun": {"deg": [-90.0, 56.8], "uncertainty_deg": 43.0}}, "x")
