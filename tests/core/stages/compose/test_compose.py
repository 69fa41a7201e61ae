"""Composition: placement on the photo camera's floor, shadows from the light map, untouched pixels."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.stages.compose import ComposeConfig, ComposeInputs, compose
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import Mesh, normalize_to_unit_sphere
from scenefit.core.render.environment import sun_environment
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.asset_pose import place_asset
from scenefit.core.scene.camera import PhotoCamera, horizon_row

from conftest import scenefit_here

CAMERA = PhotoCamera(yaw_deg=90.0, pitch_deg=-20.0, fov_deg=60.0, width=128, height=96)
SPHERE = uv_sphere(0.5, 24, 12)
GREY_MAPS = np.concatenate([np.full((8, 8, 3), 0.6, np.float32), np.full((8, 8, 1), 0.5, np.float32),
                            np.zeros((8, 8, 1), np.float32)], axis=-1)


def textured_photo(seed: int = 0) -> np.ndarray:
    """A photo with texture everywhere, so an unchanged pixel cannot match by chance."""
    rng = np.random.default_rng(seed)
    return (np.round(rng.uniform(0.2, 0.9, (CAMERA.height, CAMERA.width, 3)) * 255) / 255).astype(np.float32)


def run(env, at=(64.0, 66.0), shadow="ratio", spp=16, photo=None, camera=CAMERA, **overrides):
    photo = textured_photo() if photo is None else photo
    config = ComposeConfig(**{"size": 0.3, "shadow_type": shadow, "spp": spp, **overrides})
    return compose(ComposeInputs(SPHERE, GREY_MAPS, photo, at, env, camera), config)


def centroid(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()])


def test_shadow_falls_away_from_the_sun_and_flips_with_it():
    # The photo camera looks along +Y, so world +X is image right (see PhotoCamera.basis).
    offsets = {}
    for side in (+1, -1):
        result = run(sun_environment([side, 0.2, 0.8]))
        shadow = result.matte.mean(axis=-1) < 0.5
        assert result.report["shadow"]["floor_pass"]["ran"]
        assert shadow.sum() > 30, "a sun this strong must darken a visible patch of floor"
        offsets[side] = centroid(shadow & (result.alpha < 0.01))[0] - centroid(result.alpha > 0.5)[0]
    assert offsets[+1] < -3 and offsets[-1] > 3, offsets


def test_asset_stands_on_the_picked_point_at_the_asked_size():
    result = run(sun_environment([0.0, 0.5, 1.0]), at=(40.0, 70.0), shadow="none")
    covered = result.alpha > 0.5
    ys, xs = np.nonzero(covered)
    assert abs(ys.max() + 0.5 - 70.0) <= 2.0          # bottom on the picked point
    assert abs(xs.mean() - 40.0) <= 2.0
    assert abs((ys.max() - ys.min() + 1) - 0.3 * CAMERA.height) <= 3.0


def test_placement_above_the_horizon_gets_no_floor_pass():
    level = PhotoCamera(yaw_deg=90.0, pitch_deg=-5.0, fov_deg=60.0, width=128, height=96)
    assert horizon_row(level) > 30
    result = run(sun_environment([1.0, 0.2, 0.8]), at=(64.0, 20.0), camera=level)
    assert not result.report["shadow"]["floor_pass"]["ran"]
    assert "above the horizon" in result.report["shadow"]["floor_pass"]["why"]
    assert not result.placement.on_floor and (result.matte == 1.0).all()
    assert abs(centroid(result.alpha > 0.5)[1] - 20.0) < 3  # the asset is still drawn where it was picked


def test_composite_is_the_photo_outside_the_object_and_its_shadow():
    import cv2

    photo = textured_photo(1)
    result = run(sun_environment([1.0, -0.3, 0.6]), photo=photo)
    touched = (result.alpha > 0) | (result.matte < 1.0).any(axis=-1)
    assert touched.mean() < 0.3
    far = cv2.dilate(touched.astype(np.uint8), np.ones((3, 3), np.uint8)) == 0
    assert far.mean() > 0.6
    np.testing.assert_array_equal(result.composite_srgb[far], photo[far])
    # and the shadow really darkens the photo where the matte says so
    dark = (result.matte.mean(axis=-1) < 0.5) & (result.alpha == 0)
    assert (result.composite_srgb[dark] < photo[dark]).all()


def test_paper_and_ratio_shadows_agree_on_a_hard_edged_case():
    env = sun_environment([0.6, 0.3, 0.8], sun_radius_deg=2.0, sky_radiance=0.2)
    ratio, paper = run(env, shadow="ratio", spp=32), run(env, shadow="paper", spp=32)
    free = ratio.alpha < 0.01
    a, b = (ratio.matte.mean(-1) < 0.5) & free, (paper.matte.mean(-1) < 0.5) & free
    iou = (a & b).sum() / max((a | b).sum(), 1)
    assert a.sum() > 30 and iou > 0.8, iou
    inside = a & b
    assert abs(ratio.matte.mean(-1)[inside].mean() - paper.matte.mean(-1)[inside].mean()) < 0.1


def test_noise_target_sets_the_sample_count():
    env = sun_environment([0.6, 0.3, 0.8], sun_radiance=20.0, sun_radius_deg=10.0)
    loose = run(env, spp=None, shadow="none", noise_target=0.5, max_spp=64)
    tight = run(env, spp=None, shadow="none", noise_target=0.005, max_spp=64)
    assert loose.report["decisions"]["spp"]["from"] == "noise target"
    assert loose.report["spp"] < tight.report["spp"] == 64


def test_bad_inputs_are_sentences():
    with pytest.raises(InputError):
        ComposeConfig(shadow_type="soft")
    with pytest.raises(InputError):
        ComposeConfig(size=0.0)
    steep = PhotoCamera(yaw_deg=90.0, pitch_deg=-80.0, fov_deg=120.0, width=128, height=96)
    with pytest.raises(InputError, match="smaller size or a point") as error:
        run(sun_environment([0, 0, 1]), at=(64.0, 95.5), shadow="none", spp=1, camera=steep, size=2.0)
    assert str(error.value).count(". ") == 0
    # A wide ground plane around a small thing (bevy's PalmTree: 80:1) reaches behind at any size.
    plane = Mesh(positions=np.array([[-40, -40, 0], [40, -40, 0], [40, 40, 0], [-40, 40, 0], [0, 0, 1]], np.float32),
                 faces=np.array([[0, 1, 2], [0, 2, 3], [0, 1, 4]], np.int32),
                 uvs=np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], np.float32))
    normalized, _ = normalize_to_unit_sphere(plane)
    for size in (0.3, 0.05):
        with pytest.raises(InputError, match="80 times as wide as it is tall.*--object NAME, or select only it in Blender"):
            place_asset(normalized, PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=64, height=48),
                        (32.0, 36.0), size)


def test_cli_compose_writes_every_layer_and_leaves_the_photo_alone(tmp_path):
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 16, 8), maps, tmp_path / "asset")
    photo_path = write_image(tmp_path / "photo.png", textured_photo(2))
    light_path = write_image(tmp_path / "light" / "light.exr", sun_environment([1.0, 0.0, 1.0], height=32))
    from scenefit.core.stages.camera_stage import write_camera

    # The run's camera stage beside its light stage: compose renders through it.
    write_camera(PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=50.0, width=128, height=96), {"source": "a test"},
                 tmp_path / "camera")
    before = hashlib.sha256(photo_path.read_bytes()).hexdigest()
    out = tmp_path / "out"
    proc = scenefit_here("compose", str(asset), "--photo", str(photo_path), "--at", "0.5,0.7", "--light",
                         str(light_path), "--out", str(out), "--spp", "8", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert hashlib.sha256(photo_path.read_bytes()).hexdigest() == before
    report = json.loads((out / "report.json").read_text())
    assert report["camera"]["pitch_deg"] == -15.0 and report["camera"]["fov_deg"] == 50.0
    assert report["spp"] == 8 and report["shadow"]["type"] == "ratio" and report["placement"]["distance_m"] > 0
    assert read_image(out / "composite.png").shape == (96, 128, 3)
    assert read_image(out / "composite.exr").shape == (96, 128, 3)
    rgba = read_image(out / "layers" / "object_rgba.png")
    assert rgba.shape == (96, 128, 4) and 0.0 < rgba[..., 3].mean() < 0.5
    import OpenImageIO as oiio
    assert oiio.ImageInput.open(str(out / "layers" / "object_rgba.png")).spec().format == oiio.UINT16
    assert read_image(out / "layers" / "shadow.png").min() < 0.5

    # The folder holds this run's results: a second compose into it is refused (one unit per run).
    again = scenefit_here("compose", str(asset), "--photo", str(photo_path), "--at", "0.5,0.7", "--light",
                          str(light_path), "--out", str(out), "--spp", "8", "--quiet")
    assert again.returncode == 2 and "--replace" in again.stderr, again.stderr
    bad = scenefit_here("compose", str(asset), "--photo", str(photo_path), "--at", "2000,5", "--light",
                        str(light_path), "--out", str(tmp_path / "bad"))
    assert bad.returncode == 2 and "outside" in bad.stderr and not (tmp_path / "bad").exists()


def test_photo_camera_projection_inverts_its_pixel_rays():
    from scenefit.core.scene.camera import pixel_ray

    origin = np.array([0.0, 0.0, 1.0])
    for x, y in ((0.5, 0.5), (100.25, 7.0), (64.0, 95.5)):
        point = origin + 3.7 * pixel_ray(CAMERA, x, y)
        np.testing.assert_allclose(CAMERA.project(point[None], origin)[0], [x, y], atol=1e-9)


def test_a_big_photo_gets_a_composite_at_its_own_size_with_a_scaled_up_shadow():
    """The floor passes render at most shadow_max_side pixels across; the matte scaled up to the photo
    matches the one rendered at full size, and the photo stays exact where no shadow falls."""
    import cv2

    env = sun_environment([1.0, 0.2, 0.8])
    full = run(env, spp=32)
    small = run(env, spp=32, shadow_max_side=64)              # the 128-px photo's floor at 64 x 48
    assert small.report["render_windows"]["floor_size"] == [64, 48]
    assert small.composite_srgb.shape == full.composite_srgb.shape
    a, b = full.matte.mean(-1), small.matte.mean(-1)
    assert (b < 0.5).sum() > 30 and np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.9
    touched = (small.alpha > 0) | (small.matte < 1.0).any(axis=-1)
    far = cv2.dilate(touched.astype(np.uint8), np.ones((3, 3), np.uint8)) == 0
    assert far.mean() > 0.6
    np.testing.assert_array_equal(small.composite_srgb[far], textured_photo()[far])


def test_cli_compose_keeps_a_photo_larger_than_the_light_stages_copy_at_its_size(tmp_path):
    """The light stage reads photos at most 1024 px across; the composite is made at the photo's own
    size, and --at in pixels means pixels of the photo as stored."""
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 16, 8), maps, tmp_path / "asset")
    rng = np.random.default_rng(3)
    photo_path = write_image(tmp_path / "photo.png", rng.uniform(0.2, 0.8, (600, 1200, 3)).astype(np.float32))
    light_path = write_image(tmp_path / "light.exr", sun_environment([1.0, 0.0, 1.0], height=32))
    out = tmp_path / "out"
    proc = scenefit_here("compose", str(asset), "--photo", str(photo_path), "--at", "600,480", "--light",
                         str(light_path), "--out", str(out), "--spp", "2", "--denoiser", "none", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert read_image(out / "composite.png").shape == (600, 1200, 3)
    assert json.loads((out / "report.json").read_text())["placement"]["pixel"] == [600.0, 480.0]


def test_compose_presets_are_the_one_preset_table_and_unset_options_keep_them():
    from scenefit.core.pipeline.presets import stage_config

    draft, final = stage_config("compose", "draft"), stage_config("compose", "final", size=0.5, spp=None)
    assert draft.noise_target > final.noise_target and draft.max_spp < final.max_spp
    assert final.size == 0.5 and final.spp is None and final.noise_target == 0.015
    with pytest.raises(InputError, match="preset"):
        stage_config("compose", "best")


def test_without_pyoidn_auto_composes_raw_and_says_why_while_oidn_is_refused(monkeypatch):
    """linux-arm64 has no pyoidn wheel: the default (auto) composes the raw render and the report says
    why; asking for oidn there is one sentence."""
    import scenefit.core.stages.compose as compose_module

    monkeypatch.setattr(compose_module, "oidn_available", lambda: (False, "pyoidn is not installed"))
    result = run(sun_environment([1.0, 0.2, 0.8]), spp=4)
    assert result.report["denoiser"] == "none: pyoidn is not installed"
    with pytest.raises(InputError, match="--denoiser oidn: pyoidn is not installed"):
        run(sun_environment([1.0, 0.2, 0.8]), spp=4, denoiser_type="oidn")
