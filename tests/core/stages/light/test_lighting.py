"""Light estimation: panorama geometry, hole filling, regions, prompt rule, scales, EXR, CLI."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scenefit.devtools.tiny_models import build_tiny_depth
import torch

from scenefit.core.base.errors import InputError, ModelMissingError
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.photo import load_photo
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.depth import DepthConfig, estimate_ray_distance
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.stages.light.hdr import (ApparatusConfig, ApparatusScene, CriticRequest, OptimiseConfig, compose_hdr,
                                        is_dark_environment, light_prompt, optimise_scales, prior_scales)
from scenefit.core.stages.light.panorama import fill_panorama, indoor_panorama
from scenefit.core.stages.light.reference_critic import ReferenceCritic
from scenefit.core.stages.light.regions import RegionThresholds, bright_regions
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.floor import ORIGIN_LIFT, place_on_floor
from scenefit.core.scene.frame import equirect_directions

# -- a synthetic box room with a smooth colour on every wall -----------------------------------------
ROOM_MIN = np.array([-3.0, -2.0, 0.0])
ROOM_MAX = np.array([3.0, 6.0, 2.5])


def room_hit(origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance along each ray from inside the box to its wall, and the colour there."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hi = np.where(dirs > 0, (ROOM_MAX - origins) / dirs, np.inf)
        t_lo = np.where(dirs < 0, (ROOM_MIN - origins) / dirs, np.inf)
    t = np.minimum(t_hi, t_lo).min(axis=-1)
    p = origins + dirs * t[..., None]
    color = 0.5 + 0.35 * np.stack([np.sin(0.9 * p[..., 0] + 0.3 * p[..., 2]),
                                   np.sin(0.7 * p[..., 1] + 1.0),
                                   np.cos(0.8 * p[..., 2] + 0.4 * p[..., 0])], axis=-1)
    return t, color.astype(np.float32)


@pytest.mark.parametrize("roll, shift", [(0.0, (0.0, 0.0)), (12.0, (0.1, -0.05))])
def test_synthetic_room_unwraps_to_the_known_panorama(roll, shift):
    # (a turned, shifted camera: the unwrap uses the camera's own rays, roll and lens shift included)
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=70.0, width=160, height=120, roll_deg=roll,
                         shift_x=shift[0], shift_y=shift[1])
    eye = np.array([0.0, 0.0, 1.0])
    dirs = camera.ray_directions()
    distance, photo = room_hit(np.broadcast_to(eye, dirs.shape), dirs)
    placement = place_on_floor(camera, (80.0, 100.0))
    pano = indoor_panorama(photo, distance.astype(np.float32), camera, placement, height=32)
    # The map the object would see: cast from its position into the same room.
    map_dirs = equirect_directions(32, 64)
    centre = placement.object_position + [0.0, 0.0, ORIGIN_LIFT]
    _, known = room_hit(np.broadcast_to(centre, map_dirs.shape), map_dirs)
    seen = pano.seen
    assert seen.mean() > 0.05
    error = np.abs(pano.ldr[seen] - known[seen]).mean()
    assert error < 0.03, error
    # A map mirrored left-right (the classic convention slip) would be far off.
    assert np.abs(pano.ldr[:, ::-1][seen] - known[seen]).mean() > 3 * error
    # What the photo never saw (behind the camera) holds the photo's mean colour.
    assert np.allclose(pano.ldr[pano.unseen], photo.reshape(-1, 3).mean(0), atol=1e-5)


def test_hole_filling_leaves_no_holes_and_drops_isolated_specks():
    h, w = 32, 64
    rows, cols = np.mgrid[0:h, 0:w]
    truth = np.stack([0.3 + 0.4 * rows / h, 0.2 + 0.5 * cols / w, np.full((h, w), 0.6)], axis=-1).astype(np.float32)
    region = (rows >= 8) & (rows < 24) & (cols >= 10) & (cols < 40)
    rng = np.random.default_rng(0)
    seen = region & (rng.uniform(size=(h, w)) > 0.3)
    seen[2, 55] = True                       # an isolated speck far from the rest
    splatted = np.where(seen[..., None], truth, 0.0)
    fill = np.array([0.1, 0.2, 0.3], np.float32)
    out, kept, holes, unseen = fill_panorama(splatted, seen, fill)
    assert np.isfinite(out).all()
    assert (kept | holes | unseen).all() and not (kept & holes).any() and not (holes & unseen).any()
    inner = region & (rows >= 10) & (rows < 22) & (cols >= 12) & (cols < 38)
    assert not unseen[inner].any()           # every hole inside the covered area was filled ...
    assert np.abs(out[inner & ~seen] - truth[inner & ~seen]).max() < 0.08   # ... from its neighbours
    assert unseen[2, 55]                     # the speck is gone
    assert np.allclose(out[unseen], fill)


def test_region_masks_follow_the_thresholds():
    t = RegionThresholds()
    assert (t.near, t.far, t.outdoor, t.distance) == (0.8, 0.95, 0.9, math.inf)
    levels = np.array([[0.5, 0.79, 0.8, 0.9, 0.95, 1.0]], np.float32)
    ldr = np.repeat(levels[..., None], 3, axis=-1)
    finite = np.ones(levels.shape, np.float32)
    far_away = np.full(levels.shape, np.inf, np.float32)
    near = bright_regions(ldr, finite, "indoor")
    assert list(near) == ["near"] and near["near"].tolist() == [[False, False, True, True, True, True]]
    far = bright_regions(ldr, far_away, "indoor")
    assert list(far) == ["far"] and far["far"].tolist() == [[False, False, False, False, True, True]]
    # A finite distance threshold splits the two.
    split = bright_regions(ldr, np.array([[1, 1, 1, 5, 5, 5]], np.float32), "indoor", RegionThresholds(distance=2.0))
    assert split["near"].tolist() == [[False, False, True, False, False, False]]
    assert split["far"].tolist() == [[False, False, False, False, True, True]]
    assert bright_regions(np.zeros((4, 8, 3), np.float32), None, "indoor") == {}


def test_outdoor_has_no_near_light_scale():
    ldr = np.full((8, 16, 3), 0.3, np.float32)
    ldr[6, 3] = 0.92
    regions = bright_regions(ldr, None, "outdoor")
    assert list(regions) == ["far"]
    expected = np.zeros((8, 16), bool)
    expected[:4] = True
    expected[6, 3] = True
    assert (regions["far"] == expected).all()
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-5.0, fov_deg=60.0, width=40, height=30)
    photo = np.full((30, 40, 3), 0.4, np.float32)
    photo[:10] = [0.6, 0.75, 0.98]
    paper = estimate_light(photo, (20.0, 25.0), stage_config("light", "draft", scene_type="outdoor", map_height=16,
                                                             prior_type="inverse_tonemap"), photo_camera=camera)
    assert set(paper.scales) == {"far"} and "near" not in paper.regions
    # The cues split off the unseen sky (and clipped texels) but never add a near light outdoors.
    result = estimate_light(photo, (20.0, 25.0), stage_config("light", "draft", scene_type="outdoor", map_height=16),
                            photo_camera=camera)
    assert "near" not in result.scales and set(result.scales) <= {"far", "clipped", "unseen"}
    assert result.hdr.shape == (16, 32, 3) and np.isfinite(result.hdr).all()


@pytest.mark.parametrize("background, lights, dark", [(0.1, 10.0, True), (0.3, 10.0, False), (0.1, 60.0, False),
                                                      (0.3, 60.0, False), (0.2, 10.0, False), (0.1, 50.0, False),
                                                      (0.199, 49.9, True)])
def test_dark_environment_rule_fires_exactly_when_both_conditions_hold(background, lights, dark):
    hdr = np.full((8, 16, 3), background, np.float32)
    mask = np.zeros((8, 16), bool)
    mask[1, 2:6] = True
    hdr[mask] = lights
    fired, info = is_dark_environment(hdr, {"near": mask})
    assert fired is dark
    assert info["background_mean"] == pytest.approx(background, rel=1e-5)
    prompt = light_prompt("A gigantic diffuse white (spray-painted) sphere (ball)", fired, "in blue tint")
    assert prompt.endswith(("in a dark environment, in blue tint" if dark else "(ball), in blue tint"))


def small_scene(map_shape=(16, 32)):
    maps = torch.cat([torch.full((4, 4, 3), 0.6), torch.full((4, 4, 1), 0.4), torch.zeros(4, 4, 1)], -1)
    config = ApparatusConfig(render_size=24, spp=4, object_azimuths=(0.0,), view_weights=(0.5, 0.5))
    return ApparatusScene(uv_sphere(radius=0.5, segments=16, rings=8), maps, map_shape, config)


def bright_spot_ldr(shape=(16, 32)):
    h, w = shape
    ldr = np.full((h, w, 3), 0.35, np.float32)
    mask = np.zeros((h, w), bool)
    dirs = equirect_directions(h, w)
    mask[dirs @ np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]) > np.cos(np.radians(30))] = True
    ldr[mask] = 1.0
    return ldr, {"near": mask}


@pytest.mark.parametrize("scale", [1e-3, 1e4])
def test_scales_stay_finite_and_gradients_point_home_at_extremes(scale):
    scene = small_scene()
    ldr, regions = bright_spot_ldr()
    from scenefit.core.data.imageio import srgb_to_linear

    ldr_lin = torch.from_numpy(srgb_to_linear(ldr))
    masks = {k: torch.from_numpy(v) for k, v in regions.items()}
    truth = compose_hdr(ldr_lin, masks, {"near": torch.tensor(math.log(30.0))}).detach()
    critic = ReferenceCritic.from_true_map(scene, truth.numpy(), spp=8)
    log_scale = torch.tensor(math.log(scale), requires_grad=True)
    hdr = compose_hdr(ldr_lin, masks, {"near": log_scale})
    assert torch.isfinite(hdr).all()
    loss = 0.0
    for v in range(len(scene.cameras)):
        render, _ = scene.render_view(hdr, v, seed=1)
        view_loss = scene.weights[v] * critic(render[None], CriticRequest(("p",), ("v",), 0, 1, view_indices=(v,))).sum()
        view_loss.backward(retain_graph=True)
        loss += float(view_loss)
    grad = log_scale.grad
    assert math.isfinite(loss) and torch.isfinite(grad) and abs(float(grad)) > 1e-6
    # Too dark: the loss falls as the scale grows; too bright: it falls as the scale shrinks.
    assert (float(grad) < 0) if scale < 30 else (float(grad) > 0)


def test_reference_critic_pulls_the_scale_towards_the_truth():
    scene = small_scene()
    ldr, regions = bright_spot_ldr()
    truth = compose_hdr(torch.from_numpy(read_linear(ldr)), {"near": torch.from_numpy(regions["near"])},
                        {"near": torch.tensor(math.log(20.0))}).numpy()
    critic = ReferenceCritic.from_true_map(scene, truth, spp=8)
    result = optimise_scales(scene, ldr, regions, {"near": 1.0}, critic, ("a", "b"),
                             OptimiseConfig(iterations=12, lr=0.25))
    assert all(np.isfinite(v) for v in result.log_scales.values())
    assert abs(result.log_scales["near"] - math.log(20.0)) < 0.5 * math.log(20.0)
    assert np.mean(result.loss_history[-3:]) < np.mean(result.loss_history[:3])


def read_linear(ldr):
    from scenefit.core.data.imageio import srgb_to_linear

    return srgb_to_linear(ldr)


def test_prior_is_the_documented_inverse_tone_curve():
    ldr, regions = bright_spot_ldr()
    scales = prior_scales(ldr, regions, l_white=64.0)
    assert scales["near"] == pytest.approx(64.0, rel=1e-4)        # fully clipped texels -> L_white
    half = np.full((4, 8, 3), 0.735, np.float32)                  # linear 0.5
    s = prior_scales(half, {"near": np.ones((4, 8), bool)}, l_white=64.0)["near"]
    lw2 = 64.0 ** 2
    expected = lw2 / 2 * (0.5 - 1 + math.sqrt(0.25 + 2.0 / lw2)) / 0.5
    assert s == pytest.approx(max(expected, 1.0), rel=2e-3)


def test_exr_round_trips_bit_exactly_for_float32(tmp_path):
    rng = np.random.default_rng(3)
    hdr = (10.0 ** rng.uniform(-4, 4.5, size=(7, 14, 3))).astype(np.float32)
    hdr[0, 0] = [0.0, 1e-30, 3.4e38]
    write_image(tmp_path / "light.exr", hdr, dtype="float")
    back = read_image(tmp_path / "light.exr")
    assert back.dtype == np.float32 and np.array_equal(back, hdr)


# -- depth ------------------------------------------------------------------------------------------


def test_depth_model_from_a_local_folder_goes_through_the_same_code_path(tmp_path):
    folder = build_tiny_depth(tmp_path / "tiny-depth")
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=45, height=31)
    photo = np.random.default_rng(1).uniform(size=(31, 45, 3)).astype(np.float32)
    placement = place_on_floor(camera, (22.0, 27.0))
    result = estimate_ray_distance(photo, camera, placement, DepthConfig(depth_type="model", model=str(folder)))
    assert result.method == "model" and result.ray_distance.shape == (31, 45)
    assert np.isfinite(result.ray_distance).all() and (result.ray_distance > 0).all()
    # Aligned so that the object stands on the floor: the placement pixel's distance is the floor's.
    eye = np.array([0.0, 0.0, 1.0])
    assert np.median(result.ray_distance[26:29, 21:24]) == pytest.approx(np.linalg.norm(placement.object_position - eye),
                                                                         rel=0.35)


def test_missing_depth_model_is_a_clear_error_or_the_geometric_fallback(tmp_path):
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=20, height=16)
    photo = np.full((16, 20, 3), 0.5, np.float32)
    placement = place_on_floor(camera, (10.0, 14.0))
    missing = str(tmp_path / "no-such-model")
    with pytest.raises(ModelMissingError, match="no-such-model") as error:
        estimate_ray_distance(photo, camera, placement, DepthConfig(depth_type="model", model=missing))
    assert "--depth geometric" in str(error.value)
    fallback = estimate_ray_distance(photo, camera, placement, DepthConfig(depth_type="auto", model=missing))
    assert fallback.method == "geometric" and "no-such-model" in fallback.detail["why"]
    # The fallback floor: pixels below the horizon see the floor at height / sin(depression).
    ray = camera.ray_directions()[15, 10]
    assert fallback.ray_distance[15, 10] == pytest.approx(1.0 / -ray[2], rel=1e-4)


# -- the command line -------------------------------------------------------------------------------
@pytest.mark.parametrize("name, size", [("photo.jpg", (23, 37)), ("photo.png", (61, 23)), ("photo.exr", (31, 50))])
def test_scenefit_light_works_on_any_photo(tmp_path, name, size):
    from scenefit.cli import main

    h, w = size
    rng = np.random.default_rng(5)
    pixels = rng.uniform(0.0, 1.0, size=(h, w, 3)).astype(np.float32)
    pixels[: h // 3] = [0.95, 0.97, 1.0]          # a bright top, so there is a light region
    if name.endswith(".exr"):
        pixels = pixels * 40.0
    write_image(tmp_path / name, pixels)
    out = tmp_path / "out"
    code = main(["light", "--photo", str(tmp_path / name), "--at", "0.5,0.8", "--out", str(out),
                 "--preset", "draft", "--depth", "geometric", "--quiet"])
    assert code == 0
    hdr = read_image(out / "light.exr")
    assert hdr.shape == (64, 128, 3) and np.isfinite(hdr).all() and hdr.min() >= 0
    assert (out / "light_preview.png").is_file() and (out / "light_ldr.png").is_file()
    report = json.loads((out / "report.json").read_text())
    for key in ("scene_type", "depth", "placement", "regions", "prior", "prompt", "critic"):
        assert key in report["decisions"] or (key == "depth" and report["decisions"]["scene_type"]["chosen"] == "outdoor")
    assert report["photo"]["size"] == [w, h]
    photo, info = load_photo(tmp_path / name)
    assert photo.shape == (h, w, 3) and 0.0 <= photo.min() and photo.max() <= 1.0


def test_bad_placement_and_config_are_rejected(tmp_path):
    from scenefit.cli import main

    write_image(tmp_path / "p.png", np.full((10, 12, 3), 0.5, np.float32))
    assert main(["light", "--photo", str(tmp_path / "p.png"), "--at", "40,3", "--out", str(tmp_path / "o"),
                 "--quiet"]) == 2
    with pytest.raises(InputError):
        stage_config("light", "draft", scene_type="underwater")


def test_a_photo_read_again_is_the_same_and_a_changed_file_is_read_anew(tmp_path):
    """A run reads its photo several times (inputs, camera, light) and decodes it once; what a caller
    does to its copy never reaches the next, and a file written again is decoded again."""
    import os

    path = tmp_path / "photo.png"
    write_image(path, np.full((40, 60, 3), 0.25, np.float32))
    first, info = load_photo(path)
    first[:] = 1.0
    info["size"] = [1, 1]
    again, info_again = load_photo(path)
    assert np.allclose(again, 0.25, atol=1 / 255) and info_again["size"] == [60, 40]
    write_image(path, np.full((40, 60, 3), 0.75, np.float32))
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))   # (a file system's coarse clock)
    assert np.allclose(load_photo(path)[0], 0.75, atol=1 / 255)
