"""A photo camera with a lens shift (an off-centre principal point, as fSpy solves and Blender cameras
carry): its rays, its projection, fSpy's principal point, camera.json, Mitsuba's render and Blender's
own camera all put the optical axis on the same pixel."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.scene.camera import PhotoCamera, camera_origin, pixel_ray
from scenefit.core.stages.camera import estimate_photo_camera, photo_camera_estimate
from scenefit.core.stages.camera_stage import read_camera, write_camera
from camera_scenes import fspy_project_bytes, lineless_photo

SIZE = (96, 64)

SHIFTED = dict(pitch_deg=-12.0, fov_deg=55.0, roll_deg=7.0)


def test_a_shifted_camera_sees_what_the_centred_one_sees_some_pixels_away():
    # On a 120x80 frame a shift of (0.1, -0.05) of the longer side moves the view 12 px right and 6 px
    # down, so what the centred camera shows at (u + 12, v + 6) the shifted one shows at (u, v).
    centred = PhotoCamera(width=120, height=80, **SHIFTED)
    shifted = PhotoCamera(width=120, height=80, shift_x=0.1, shift_y=-0.05, **SHIFTED)
    assert shifted.principal_px() == pytest.approx((48.0, 34.0))
    np.testing.assert_allclose(shifted.ray_directions()[:74, :108], centred.ray_directions()[6:, 12:], atol=1e-12)
    assert pixel_ray(shifted, 10.5, 20.5) == pytest.approx(pixel_ray(centred, 22.5, 26.5), abs=1e-12)
    # The axis's pixel looks straight ahead; an unshifted camera is the one it always was.
    assert pixel_ray(shifted, *shifted.principal_px()) == pytest.approx(shifted.basis()[0], abs=1e-12)
    assert centred.principal_px() == (60.0, 40.0) and centred.plane_offset() == (0.0, 0.0)


@pytest.mark.parametrize("size, shift", [((120, 80), (0.2, 0.1)), ((60, 90), (-0.3, 0.25)), ((64, 64), (0.0, -0.4))])
def test_projection_inverts_the_rays_of_a_shifted_camera(size, shift):
    camera = PhotoCamera(width=size[0], height=size[1], shift_x=shift[0], shift_y=shift[1], **SHIFTED)
    rays = camera.ray_directions()
    grid = np.stack(np.meshgrid(np.arange(size[0]) + 0.5, np.arange(size[1]) + 0.5), axis=-1)
    np.testing.assert_allclose(camera.project(rays.reshape(-1, 3) * 3.0).reshape(grid.shape), grid, atol=1e-9)


@pytest.mark.parametrize("size, principal", [((96, 64), (0.3, -0.1)), ((64, 96), (-0.2, 0.35))])
def test_fspys_principal_point_becomes_the_same_pixel(tmp_path, size, principal):
    w, h = size
    camera = PhotoCamera(yaw_deg=20.0, width=w, height=h, **SHIFTED)
    (tmp_path / "scene.fspy").write_bytes(fspy_project_bytes(camera, principal=principal))
    est = estimate_photo_camera(lineless_photo(tmp_path / "photo.png", size), tmp_path / "scene.fspy")
    # fSpy measures the principal point in half the longer side from the centre, y up.
    side = max(w, h)
    expected = (w / 2 + principal[0] * side / 2, h / 2 - principal[1] * side / 2)
    assert est.photo_camera().principal_px() == pytest.approx(expected, abs=1e-9)
    assert any("lens shift" in note for note in est.notes)
    # The reported horizon is where the shifted camera sees far level points.
    level = est.photo_camera()
    far = level.project(np.array([[x, 1000.0, 0.0] for x in (-300.0, 0.0, 300.0)]))
    (x0, y0), (x1, y1) = est.horizon
    assert far[:, 1] == pytest.approx(y0 + (y1 - y0) * far[:, 0] / w, abs=0.05)


def test_camera_json_keeps_the_shift_and_refuses_an_impossible_one(tmp_path):
    camera = PhotoCamera(width=120, height=80, shift_x=0.125, shift_y=-0.25, **SHIFTED)
    write_camera(camera, {"source": "fspy"}, tmp_path)
    read, _ = read_camera(tmp_path / "camera.json", 240, 160)
    assert (read.shift_x, read.shift_y, read.width) == (0.125, -0.25, 240)
    assert read.principal_px() == pytest.approx((2 * camera.principal_px()[0], 2 * camera.principal_px()[1]))
    saved = json.loads((tmp_path / "camera.json").read_text())
    del saved["photo_camera"]["shift_x"], saved["photo_camera"]["shift_y"]   # a camera.json without a shift
    (tmp_path / "camera.json").write_text(json.dumps(saved))
    assert read_camera(tmp_path / "camera.json", 120, 80)[0].principal_px() == (60.0, 40.0)
    saved["photo_camera"]["shift_x"] = 40.0
    (tmp_path / "camera.json").write_text(json.dumps(saved))
    with pytest.raises(InputError, match="cannot be used") as caught:
        read_camera(tmp_path / "camera.json", 120, 80)
    assert "\n" not in str(caught.value)


def test_a_given_shift_overrides_the_estimate_and_is_checked(tmp_path):
    photo = lineless_photo(tmp_path / "photo.png")
    given = {"fov_deg": 50.0, "pitch_deg": -5.0, "roll_deg": 0.0, "shift_x": 0.05, "shift_y": 0.1}
    est = photo_camera_estimate(photo, None, given, "blender", "the scene camera")
    assert (est.shift_x, est.shift_y) == (0.05, 0.1)
    assert est.photo_camera().principal_px() == pytest.approx((SIZE[0] / 2 - 0.05 * 96, SIZE[1] / 2 + 0.1 * 96))
    with pytest.raises(InputError, match="lens shift"):
        photo_camera_estimate(photo, None, {**given, "shift_y": 3.0})
    with pytest.raises(InputError, match="finite"):
        photo_camera_estimate(photo, None, {**given, "shift_x": math.nan})


def test_mitsuba_draws_a_point_where_the_shifted_camera_projects_it():
    from scenefit.core.render.backend import init_mitsuba
    from scenefit.core.stages.compose import _sensor

    init_mitsuba()
    import mitsuba as mi

    camera = PhotoCamera(width=96, height=64, pitch_deg=-10.0, fov_deg=50.0, shift_x=0.15, shift_y=-0.1)
    point = camera_origin() + 4.0 * pixel_ray(camera, 30.0, 20.0)
    scene = mi.load_dict({"type": "scene", "ball": {"type": "sphere", "center": point.tolist(), "radius": 0.06}})
    for window in ((0, 0, 96, 64), (10, 5, 60, 40)):   # the whole frame and a crop of it (compose renders crops)
        sensor = _sensor(mi, camera, window, "independent", 16)
        depth = np.array(mi.render(scene, sensor=sensor, integrator=mi.load_dict(
            {"type": "aov", "aovs": "d:depth"})))[..., 0]
        ys, xs = np.nonzero(depth > 0)
        centre = (xs.mean() + 0.5 + window[0], ys.mean() + 0.5 + window[1])
        assert centre == pytest.approx(camera.project(point[None], camera_origin())[0], abs=0.3)
        assert centre == pytest.approx((30.0, 20.0), abs=0.3)
