"""The photo camera estimate: fSpy projects, EXIF, the photo's own lines, `scenefit camera`."""
from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.stages.camera import estimate_photo_camera, sensor_width_mm
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.frame import look_frame
from camera_scenes import box_room, fspy_project_bytes as _fspy_bytes, jpeg_with_exif, lineless_photo as _photo

SIZE = (96, 64)


@pytest.mark.parametrize("fov, pitch, roll", [(55.0, -12.5, 0.0), (83.2, 7.25, -4.4), (40.0, -31.0, 12.0)])
def test_fspy_project_round_trips_to_the_same_camera(tmp_path, fov, pitch, roll):
    camera = PhotoCamera(yaw_deg=37.0, pitch_deg=pitch, fov_deg=fov, width=SIZE[0], height=SIZE[1], roll_deg=roll)
    (tmp_path / "scene.fspy").write_bytes(_fspy_bytes(camera))
    est = estimate_photo_camera(_photo(tmp_path / "photo.png"), tmp_path / "scene.fspy")
    assert (est.fov_deg, est.pitch_deg, est.roll_deg) == pytest.approx((fov, pitch, roll), abs=0.01)
    assert (est.source, est.fov_source, est.pitch_confidence, est.fallback) == ("fspy", "fspy", 1.0, False)
    # The reported horizon is where the camera sees far level points (yaw does not matter to it).
    level = PhotoCamera(yaw_deg=90.0, pitch_deg=pitch, fov_deg=fov, width=SIZE[0], height=SIZE[1], roll_deg=roll)
    far = level.project(np.array([[x, 1000.0, 0.0] for x in (-200.0, 0.0, 200.0)]))
    (x0, y0), (x1, y1) = est.horizon
    assert far[:, 1] == pytest.approx(y0 + (y1 - y0) * far[:, 0] / SIZE[0], abs=0.05)


@pytest.mark.parametrize("content, words", [
    (b"fspy\x01\x00", "shorter than"),
    (b"PK\x03\x04" + bytes(40), "not an fSpy project"),
    (struct.pack("<4sIII", b"fspy", 2, 2, 0) + b"{}", "version 2"),
    (struct.pack("<4sIII", b"fspy", 1, 5000, 10) + b"{}", "truncated"),
    (struct.pack("<4sIII", b"fspy", 1, 9, 0) + b"{not json", "its state is not valid JSON"),
    (struct.pack("<4sIII", b"fspy", 1, 26, 0) + b'{"cameraParameters": null}', "no solved camera"),
])
def test_a_damaged_fspy_file_is_one_sentence(tmp_path, content, words, capsys):
    from scenefit.cli import main

    photo = _photo(tmp_path / "photo.png")
    (tmp_path / "bad.fspy").write_bytes(content)
    with pytest.raises(InputError) as error:
        estimate_photo_camera(photo, tmp_path / "bad.fspy")
    message = str(error.value)
    assert words in message and "\n" not in message and message.endswith(".") and "bad.fspy" in message
    assert main(["camera", "--photo", str(photo), "--fspy", str(tmp_path / "bad.fspy"), "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == f"scenefit: error: {message}\n"


# -- EXIF ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("size", [(120, 80), (80, 120)])
def test_exif_35mm_focal_length_gives_the_field_of_view(tmp_path, size):
    photo = jpeg_with_exif(tmp_path / "phone.jpg", size, **{"Exif:FocalLengthIn35mmFilm": 26})
    est = estimate_photo_camera(photo)
    # 26 mm on the 43.27 mm diagonal: 3:2 landscape 69.4 deg wide (36 mm of film), upright 49.6 (24 mm).
    width_mm = 43.27 * size[0] / math.hypot(*size)
    assert est.fov_deg == pytest.approx(math.degrees(2 * math.atan(width_mm / 52.0)), abs=0.01)
    assert est.fov_deg == pytest.approx(69.4 if size[0] > size[1] else 49.6, abs=0.05)
    assert (est.fov_source, est.fov_confidence) == ("exif_35mm", 0.9)
    assert est.pitch_source == "default" and est.fallback   # a flat grey photo has no lines


def test_exif_focal_length_with_a_known_sensor(tmp_path):
    photo = jpeg_with_exif(tmp_path / "dslr.jpg", (90, 60), **{"Exif:FocalLength": 35.0, "Model": "NIKON D850"})
    est = estimate_photo_camera(photo)
    assert est.fov_source == "exif_sensor"
    assert est.fov_deg == pytest.approx(math.degrees(2 * math.atan(35.9 / 70.0)), abs=0.01)
    assert (sensor_width_mm("Canon EOS R5"), sensor_width_mm("Canon EOS R50"), sensor_width_mm("ILCE-7M3")) == \
        (36.0, None, 35.8)
    unknown = jpeg_with_exif(tmp_path / "odd.jpg", (90, 60), **{"Exif:FocalLength": 35.0, "Model": "Obscura 1"})
    est = estimate_photo_camera(unknown)
    assert est.fov_source == "default" and any("Obscura 1" in note for note in est.notes)


# -- the photo's lines -----------------------------------------------------------------------------


@pytest.mark.parametrize("fov, pitch, roll, yaw", [(65.0, -14.0, 3.0, 105.0), (48.0, 6.0, -4.0, 70.0)])
def test_lines_of_abox_room_give_its_camera(tmp_path, fov, pitch, roll, yaw):
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=fov, width=384, height=288, roll_deg=roll)
    write_image(tmp_path / "room.png", box_room(camera))
    est = estimate_photo_camera(tmp_path / "room.png")
    # Tolerances: 2 deg of field of view, 0.5 of pitch, 0.3 of roll (measured: within a third of these).
    assert (est.fov_source, est.pitch_source, est.roll_source) == ("lines",) * 3
    assert est.fov_deg == pytest.approx(fov, abs=2.0)
    assert est.pitch_deg == pytest.approx(pitch, abs=0.5)
    assert est.roll_deg == pytest.approx(roll, abs=0.3)
    assert min(est.fov_confidence, est.pitch_confidence, est.roll_confidence) >= 0.5 and not est.fallback
    assert est.vanishing_points["vertical"] is not None and est.lines["vertical"] >= 12
    # The vertical segments handed out for drawing point at the vertical vanishing point.
    vx, vy = est.vanishing_points["vertical"]
    vertical = [s for s in est.segments if s[4] == 0]
    assert len(vertical) == est.lines["vertical"] and "segments" not in est.to_dict()
    for x1, y1, x2, y2, _ in vertical:
        along = np.degrees(np.arctan2(y2 - y1, x2 - x1) - np.arctan2(vy - (y1 + y2) / 2, vx - (x1 + x2) / 2))
        assert abs((along + 90.0) % 180.0 - 90.0) < 2.0


def test_exif_field_of_view_with_the_lines_pitch_and_roll(tmp_path):
    import OpenImageIO as oiio

    camera = PhotoCamera(yaw_deg=80.0, pitch_deg=-17.0, fov_deg=70.0, width=384, height=288, roll_deg=-2.0)
    pixels = np.round(box_room(camera) * 255).astype(np.uint8)
    focal35 = 43.27 * 384 / math.hypot(384, 288) / 2 / math.tan(math.radians(35.0))   # 70 deg wide
    spec = oiio.ImageSpec(384, 288, 3, oiio.UINT8)
    spec.attribute("Exif:FocalLengthIn35mmFilm", int(round(focal35)))
    out = oiio.ImageOutput.create(str(tmp_path / "room.jpg"))
    assert out.open(str(tmp_path / "room.jpg"), spec) and out.write_image(pixels)
    out.close()
    est = estimate_photo_camera(tmp_path / "room.jpg")
    assert (est.fov_source, est.pitch_source, est.roll_source, est.source) == \
        ("exif_35mm", "lines", "lines", "exif_35mm+lines")
    assert est.fov_deg == pytest.approx(70.0, abs=1.0)   # the EXIF value is a whole number of mm
    assert (est.pitch_deg, est.roll_deg) == (pytest.approx(-17.0, abs=0.7), pytest.approx(-2.0, abs=0.3))


def test_a_photo_without_lines_reports_the_fallback(tmp_path):
    est = estimate_photo_camera(_photo(tmp_path / "sky.png", size=(320, 240)))
    assert (est.fov_deg, est.pitch_deg, est.roll_deg) == (60.0, -10.0, 0.0)
    assert (est.fov_source, est.pitch_source, est.roll_source, est.source) == ("default",) * 4
    assert est.fallback and est.fov_confidence == 0.0
    assert any(note.startswith("lines:") for note in est.notes) and any("pitch: the default" in n for n in est.notes)


def test_camera_json_is_one_strict_object(tmp_path, capsys):
    from scenefit.cli import main

    camera = PhotoCamera(yaw_deg=100.0, pitch_deg=-8.0, fov_deg=60.0, width=320, height=240, roll_deg=1.5)
    write_image(tmp_path / "room.png", box_room(camera, n=100))
    assert main(["camera", "--photo", str(tmp_path / "room.png"), "--json"]) == 0

    def refuse(token):
        raise AssertionError(f"non-standard JSON token {token}")

    out = capsys.readouterr().out
    data = json.loads(out, parse_constant=refuse)
    assert out.count("\n") == 1 and isinstance(data, dict)
    assert {"fov_deg", "pitch_deg", "roll_deg", "source", "horizon", "notes"} <= set(data)
    assert data["roll_deg"] == pytest.approx(1.5, abs=0.3) and data["source"] == "lines"
    assert main(["camera", "--photo", str(tmp_path / "missing.png")]) == 2


# -- the photo camera's roll -----------------------------------------------------------------------
def test_roll_turns_the_horizon_clockwise_and_zero_roll_changes_nothing():
    level = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=64, height=48)
    yaw, pitch = np.radians(90.0), np.radians(-10.0)   # the frame as PhotoCamera built it before roll
    f, right, up = look_frame([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
    basis = level.basis()
    assert all(np.array_equal(a, b) for a, b in zip(basis[:3], (f, right, up)))   # bit-identical at roll 0
    assert np.array_equal(PhotoCamera(**{**level.__dict__, "roll_deg": 0.0}).ray_directions(), level.ray_directions())
    rolled = PhotoCamera(yaw_deg=90.0, pitch_deg=0.0, fov_deg=60.0, width=64, height=48, roll_deg=5.0)
    left, right_px = rolled.project(np.array([[-100.0, 1000.0, 0.0], [100.0, 1000.0, 0.0]]))
    # Turned counter-clockwise, the camera sees the horizon fall to the right (y grows downwards).
    assert right_px[1] > left[1]
    slope = math.degrees(math.atan2(right_px[1] - left[1], right_px[0] - left[0]))
    assert slope == pytest.approx(5.0, abs=0.01)


def test_user_values_override_the_estimate_and_move_the_horizon(tmp_path):
    est = estimate_photo_camera(_photo(tmp_path / "sky.png", size=(160, 120)))
    given = est.overridden(pitch_deg=0.0, roll_deg=None)
    assert (given.pitch_deg, given.pitch_source, given.pitch_confidence) == (0.0, "user", 1.0)
    assert given.fov_source == "default" and given.source == "user+default"
    # Level, unrolled: the horizon runs through the middle of the photo.
    assert given.horizon == ((0.0, 60.0), (160.0, 60.0)) and est.horizon[0][1] < 60.0
    assert est.overridden() is est


def test_theta_votes_equal_every_segment_scored_in_every_bin():
    """The coarse search adds each segment only to the theta bins its kernel reaches; scored directly in
    all 45 bins (max of the vertical and horizontal kernels, weighted) the table is the same, for segments
    anywhere, along the horizon (slope near 0: nearly every bin) and through the image centre."""
    import scenefit.core.stages.camera as pc

    rng = np.random.default_rng(3)
    ends = rng.uniform(-1.0, 1.0, (60, 4))
    ends[:5, 1], ends[:5, 3] = 0.01, 0.012   # just above the horizon of a level camera: slopes near 0
    # (exactly on it a segment's circle is the horizon and its theta is undefined, in either computation)
    ends[5:8, :2] = 0.0                      # from the centre
    weights = rng.uniform(0.1, 1.0, 60)
    pitch, roll = np.array([0.0, -12.0, 7.0, -24.0]), np.array([0.0, 2.5, -5.0, 1.0])
    focal = pc.focal_from_fov(65.0)
    votes = pc._theta_votes(ends, weights, focal, pitch, roll, chunk=3)
    n, m = pc._great_circles(ends, focal)
    for p in range(len(pitch)):
        for b in range(pc.THETA_BINS):
            frame = pc.camera_frame(pitch[p], roll[p], b * pc.THETA_STEP_DEG)
            vertical = pc._kernel(pc._signed_residual_deg(n, m, frame[0]), pc.COARSE_TOLERANCE_DEG)
            # the two horizontal families, 90 deg apart: the kernel of the nearer, in degrees of theta
            meet = np.cross(n, frame[0])
            meet /= np.maximum(np.linalg.norm(meet, axis=-1, keepdims=True), 1e-12)
            theta = np.degrees(np.arctan2(meet @ frame[2], meet @ frame[1])) % 90.0
            turned = np.cos(0.02) * meet + np.sin(0.02) * np.cross(frame[0], meet)
            slope = np.abs(pc._signed_residual_deg(n, m, turned)) / np.degrees(0.02)
            off = np.abs((-theta + 45.0) % 90.0 - 45.0)
            horizontal = pc._kernel(slope * off, pc.COARSE_TOLERANCE_DEG)
            expected = np.sum(weights * np.maximum(vertical, horizontal)) / np.sum(weights)
            assert votes[p, b] == pytest.approx(expected, abs=1e-9), (p, b)
    assert votes.max() > votes.min() + 0.05   # the table is not flat: the check compares something


def test_a_segments_residual_is_its_angle_in_the_image_even_far_off_a_wide_lens_axis():
    """Known answers from plain 2D geometry: the angle, in the photo, between a segment and the line from
    its midpoint to the vanishing point. On the sphere that angle shrinks far off the axis of a wide
    lens, which once made every tolerance wider there and the fit prefer 120-170 deg lenses."""
    import scenefit.core.stages.camera as pc

    focal = pc.focal_from_fov(150.0)
    rng = np.random.default_rng(5)
    for _ in range(50):
        ends = rng.uniform(-1.0, 1.0, (1, 4))
        ends[0, :2] = rng.uniform(0.7, 1.0, 2) * rng.choice([-1, 1], 2)   # near a corner, far off the axis
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        n, m = pc._great_circles(ends, focal)
        got = float(pc._signed_residual_deg(n, m, d)[0])
        mid = (ends[0, :2] + ends[0, 2:]) / 2
        along = ends[0, 2:] - ends[0, :2]
        to_vp = focal * d[:2] - mid * d[2]          # the vanishing point f d_xy / d_z, homogeneous
        expected = np.degrees(np.arctan2(along[0] * to_vp[1] - along[1] * to_vp[0], along @ to_vp))
        assert abs(got) == pytest.approx(abs((expected + 90.0) % 180.0 - 90.0), abs=1e-6)
    # a segment pointing at the vanishing point has none; one across it, 90 deg
    ends = np.array([[0.8, 0.6, 0.4, 0.3]])
    n, m = pc._great_circles(ends, focal)
    assert float(pc._signed_residual_deg(n, m, np.array([0.0, 0.0, 1.0]))[0]) == pytest.approx(0.0, abs=1e-9)
    assert abs(float(pc._signed_residual_deg(n, m, np.array([-0.6, 0.8, 0.0]))[0])) == pytest.approx(90.0)


def test_a_frontal_level_view_says_its_lines_hardly_fix_the_lens(tmp_path):
    """Level and square to the room, only the depth edges converge (one vanishing point, at the centre):
    every lens fits them alike. The estimate stays among the usual lenses and says it is unsure, while
    pitch and roll, which the lines do fix, are found."""
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=0.0, fov_deg=40.0, width=384, height=288, roll_deg=0.0)
    write_image(tmp_path / "room.png", box_room(camera, n=160))
    est = estimate_photo_camera(tmp_path / "room.png")
    assert est.fov_source == "lines" and est.fov_confidence < 0.5
    assert 24.0 < est.fov_deg < 115.0   # the prior's one-sigma range of lenses, not an end of the search
    assert any("hardly fix the lens" in note for note in est.notes)
    assert est.pitch_deg == pytest.approx(0.0, abs=0.5) and est.roll_deg == pytest.approx(0.0, abs=0.3)


def test_the_lens_posterior_at_its_extremes(monkeypatch):
    """Known answers: a lens holding all the likelihood is the median, exactly (its bin's middle, not
    half a step off); two equal neighbours (no prior) put it on their shared edge; no information gives
    the prior's median, the default 60 deg, with its one-sigma interval of log focal length."""
    import scenefit.core.stages.camera as pc

    focals = np.geomspace(pc.focal_from_fov(120.0), pc.focal_from_fov(20.0), 21)
    fovs = [pc.fov_from_focal(f) for f in focals]
    for k in (3, 10, 17):
        median, low, high = pc.lens_posterior(fovs, [200.0 if i == k else 0.0 for i in range(21)])
        assert median == pytest.approx(fovs[k], abs=1e-9) and low < median < high
        assert math.log(pc.focal_from_fov(low) / pc.focal_from_fov(high)) < math.log(focals[1] / focals[0])
    with monkeypatch.context() as m:
        m.setattr(pc, "LENS_PRIOR_SIGMA", 1e9)
        median, _, _ = pc.lens_posterior(fovs, [200.0 if i in (6, 7) else 0.0 for i in range(21)])
    assert pc.focal_from_fov(median) == pytest.approx(math.sqrt(focals[6] * focals[7]), rel=1e-9)
    # flat likelihood over a fine, wide grid: the prior itself
    focals = np.geomspace(pc.focal_from_fov(170.0), pc.focal_from_fov(2.0), 2001)
    median, low, high = pc.lens_posterior([pc.fov_from_focal(f) for f in focals], np.zeros(2001))
    sigma = pc.LENS_PRIOR_SIGMA
    assert median == pytest.approx(60.0, abs=0.1)
    assert math.log(pc.focal_from_fov(low) / pc.focal_from_fov(60.0)) == pytest.approx(0.9945 * sigma, rel=0.01)
    assert math.log(pc.focal_from_fov(60.0) / pc.focal_from_fov(high)) == pytest.approx(0.9945 * sigma, rel=0.01)


def test_a_room_under_clutter_keeps_the_default_lens_and_says_so(tmp_path):
    """Straight strokes in every direction (a forest's branches, say) over a room's edges: the lines
    still show its horizon, but explain too little of the photo to pick a lens. The lens is the default,
    said in the notes; pitch and roll come from the lines at that lens."""
    import cv2

    camera = PhotoCamera(yaw_deg=105.0, pitch_deg=-14.0, fov_deg=65.0, width=384, height=288, roll_deg=3.0)
    img = box_room(camera)
    rng = np.random.default_rng(1)
    for _ in range(340):
        x, y, angle, length = rng.uniform(0, 384), rng.uniform(0, 288), rng.uniform(0, np.pi), rng.uniform(15, 60)
        ends = ((x, y), (x + length * np.cos(angle), y + length * np.sin(angle)))
        a, b = (tuple(int(v * 16) for v in p) for p in ends)
        cv2.line(img, a, b, (0.1, 0.1, 0.1), 2, cv2.LINE_AA, shift=4)
    write_image(tmp_path / "cluttered.png", img)
    est = estimate_photo_camera(tmp_path / "cluttered.png")
    from scenefit.core.stages.camera import LENS_MIN_INLIER_SHARE, MIN_INLIER_SHARE
    assert MIN_INLIER_SHARE <= est.lines["inlier_share"] < LENS_MIN_INLIER_SHARE   # the case meant
    assert (est.fov_deg, est.fov_source, est.fov_confidence) == (60.0, "default", 0.0)
    assert any("explain too little of the photo" in note for note in est.notes)
    assert (est.pitch_source, est.roll_source) == ("lines", "lines")
    assert est.pitch_deg == pytest.approx(-14.0, abs=1.5) and est.roll_deg == pytest.approx(3.0, abs=0.7)
