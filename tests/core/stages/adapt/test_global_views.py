"""The adapt stage's global views are the compose stage's composite (camera, placement, shadow, rule)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.stages.adapt.global_views import GlobalScene, turn_for_azimuth
from scenefit.core.stages.compose import ComposeConfig, ComposeInputs, compose
from scenefit.core.guidance.views import global_view
from scenefit.core.data.mesh import normalize_to_unit_sphere
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.asset_pose import envmap_in_object_frame, place_asset
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.frame import blender_direction_to_equirect_uv, equirect_directions
from scenefit.core.scene.placement import Placement

SPP = 256
CAMERA = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=60.0, width=64, height=48)


def _maps(res: int = 16) -> np.ndarray:
    """A texture that tells the sphere's sides apart: base colour ramps across u and v."""
    u, v = np.meshgrid(np.linspace(0, 1, res), np.linspace(0, 1, res))
    return np.stack([0.2 + 0.6 * u, 0.2 + 0.6 * v, np.full_like(u, 0.3), np.full_like(u, 0.6),
                     np.zeros_like(u)], axis=-1).astype(np.float32)


def _env() -> np.ndarray:
    """Dim sky with a sun high in front-left, so the shadow falls back-right onto the floor."""
    env = np.full((16, 32, 3), 0.3, np.float32)
    env[3:5, 9:11] = 200.0
    return env


@pytest.fixture(scope="module")
def setting():
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    placement = Placement((0.5, 0.75), 0.4)
    mesh = uv_sphere(0.5, 32, 16)
    scene = GlobalScene(mesh, (16, 16), photo, placement, CAMERA, _env(), [0.0], max_depth=3,
                        shadow_type="ratio", shadow_spp=SPP, seed=0)
    composed = compose(ComposeInputs(mesh, _maps(), photo, placement.pixel(photo.shape[:2]), _env(), CAMERA),
                       ComposeConfig(size=placement.size, spp=SPP, max_depth=3))
    return photo, scene, composed


def _global(scene: GlobalScene, photo: np.ndarray, seed: int, grad: bool = False):
    maps = torch.from_numpy(_maps()).requires_grad_(grad)
    x0, y0, x1, y1 = scene.window
    side = max(x1 - x0, y1 - y0)
    placed = scene.render(maps[..., 0:3], maps[..., 3:4], maps[..., 4:5], torch.from_numpy(_env()), 0.0, side,
                          SPP, seed)
    # Rendered at the photo's own scale and cropped on whole pixels: no resampling anywhere.
    image, alpha = global_view(placed.rgb, placed.alpha, placed.rect, photo, placed.matte, (x0, y0, side), side)
    return image, alpha, placed, maps, (x0, y0, side)


def test_global_view_is_the_compose_composite_and_its_gradient_reaches_the_texture(setting):
    photo, scene, composed = setting
    image, alpha, placed, maps, (x0, y0, side) = _global(scene, photo, seed=1, grad=True)
    # One shadow: compose's own floor passes, for the same camera and placement.
    np.testing.assert_array_equal(placed.matte, composed.matte)
    assert (composed.matte < 0.9).any(), "the sun must cast a shadow for this test to mean anything"
    assert placed.rect == (scene.window[0], scene.window[1], scene.window[2] - scene.window[0],
                           scene.window[3] - scene.window[1])
    ours = image[0].permute(1, 2, 0).detach().numpy()
    h, w = min(side, 48 - y0), min(side, 64 - x0)
    theirs = composed.composite_srgb[y0:y0 + h, x0:x0 + w]
    ours, cover = ours[:h, :w], alpha[0, 0, :h, :w].detach().numpy()
    shadow_only = (cover == 0) & (composed.alpha[y0:y0 + h, x0:x0 + w] == 0)
    # Off the asset both apply the same matte to the same photo: the only difference is float32
    # rounding of the sRGB curve there and back (a few ulps of values <= 1).
    assert shadow_only.sum() > 100 and np.abs(ours - theirs)[shadow_only].max() < 1e-5
    # Same coverage up to sampling noise at the silhouette's edge pixels.
    np.testing.assert_allclose(cover.mean(), composed.alpha[y0:y0 + h, x0:x0 + w].mean(), atol=0.01)
    # The texture gets the critic's gradient through the differentiable render.
    image.sum().backward()
    assert maps.grad is not None and torch.isfinite(maps.grad).all() and maps.grad[..., :3].abs().sum() > 0
    # On the asset: equal within the sampling noise, measured here as the difference of two of our own
    # renders with different seeds (compose's is denoised, so its own noise is smaller than ours).
    again = _global(scene, photo, seed=2)[0][0].permute(1, 2, 0).numpy()[:h, :w]
    on = cover > 0.999
    noise, error = np.sqrt(np.mean((ours - again)[on] ** 2)), np.sqrt(np.mean((ours - theirs)[on] ** 2))
    print(f"global view vs compose on the asset: RMS {error:.4f}, our seed-to-seed RMS {noise:.4f}")
    assert on.sum() > 50 and error < 1.5 * noise + 2e-3


def test_a_turned_view_shows_the_side_the_orbit_camera_sees_and_turns_the_light_with_it():
    # Orbit azimuth 90 looks from +X; turning the asset by -90 brings that side to the front.
    assert turn_for_azimuth(90.0) == 270.0 and turn_for_azimuth(0.0) == 0.0
    mesh, _ = normalize_to_unit_sphere(uv_sphere(0.5, 16, 8))
    placement = place_asset(mesh, CAMERA, (32.0, 36.0), 0.4, turn_deg=270.0)
    env = np.random.default_rng(1).uniform(0, 1, (8, 16, 3)).astype(np.float32)
    turned = envmap_in_object_frame(env, placement)
    # Object-frame direction d sees the world's light from R d (R: the asset's turn about Z).
    rad = np.radians(placement.facing_deg)
    rotation = np.array([[np.cos(rad), -np.sin(rad), 0], [np.sin(rad), np.cos(rad), 0], [0, 0, 1]])
    dirs = equirect_directions(8, 16).reshape(-1, 3)
    uv = blender_direction_to_equirect_uv(dirs @ rotation.T)
    cols = np.floor(uv[:, 0] * 16).astype(int) % 16
    rows = np.clip(np.floor(uv[:, 1] * 8).astype(int), 0, 7)
    np.testing.assert_array_equal(turned.reshape(-1, 3), env[rows, cols])
    assert torch.equal(envmap_in_object_frame(torch.from_numpy(env), placement), torch.from_numpy(turned))


def test_a_shifted_photo_camera_covers_the_same_pixels_in_the_global_view_as_in_the_composite():
    # A lens shift of a tenth of the frame moves the asset's pixels by 6 px: a view that ignored it would
    # cover other pixels than the composite does.
    shifted = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=60.0, width=64, height=48, shift_x=0.1, shift_y=-0.08)
    photo = np.full((48, 64, 3), 0.5, np.float32)
    placement = Placement((0.45, 0.7), 0.35)
    mesh = uv_sphere(0.5, 24, 12)
    scene = GlobalScene(mesh, (16, 16), photo, placement, shifted, _env(), [0.0], max_depth=2,
                        shadow_type="none", shadow_spp=4, seed=0)
    maps = torch.from_numpy(_maps())
    x0, y0, x1, y1 = scene.window
    side = max(x1 - x0, y1 - y0)
    placed = scene.render(maps[..., 0:3], maps[..., 3:4], maps[..., 4:5], torch.from_numpy(_env()), 0.0, side, 16, 0)
    composed = compose(ComposeInputs(mesh, _maps(), photo, placement.pixel(photo.shape[:2]), _env(), shifted),
                       ComposeConfig(size=placement.size, spp=16, max_depth=2, shadow_type="none"))
    cx, cy, cw, ch = (int(v) for v in placed.rect)
    ours = placed.alpha[..., 0].detach().numpy()[:ch, :cw] > 0.5
    theirs = composed.alpha[cy:cy + ch, cx:cx + cw] > 0.5
    assert ours.sum() > 100
    assert (ours & theirs).sum() / (ours | theirs).sum() > 0.95
