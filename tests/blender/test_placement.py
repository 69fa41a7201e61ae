"""Pick Placement's click handling and the composite camera, as plain maths (no window, no bpy)."""
import json
import math

import numpy as np
import pytest

from scenefit.blender_io.placement import (CANCEL, CLICK, PASS, classify_event, frame_rect,
                                           placement_from_click, region_from_placement)
from scenefit.core.base.errors import InputError
from scenefit.core.scene.asset_pose import asset_in_view, camera_for_placement
from scenefit.core.scene.camera import PhotoCamera

from conftest import printed_json
from conftest import ROOT

RECT = frame_rect([(300.0, 500.0), (300.0, 200.0), (100.0, 200.0), (100.0, 500.0)])  # view_frame order


def test_events_left_press_places_esc_and_right_press_cancel():
    assert classify_event("LEFTMOUSE", "PRESS") == CLICK
    assert classify_event("ESC", "PRESS") == CANCEL and classify_event("RIGHTMOUSE", "PRESS") == CANCEL
    assert classify_event("LEFTMOUSE", "RELEASE") == PASS and classify_event("MOUSEMOVE", "NOTHING") == PASS


def test_click_maps_to_photo_fractions_from_the_top_left():
    assert RECT == (100.0, 200.0, 300.0, 500.0)
    assert placement_from_click((100.0, 500.0), RECT) == (0.0, 0.0)        # top-left corner of the photo
    assert placement_from_click((300.0, 200.0), RECT) == (1.0, 1.0)        # bottom-right
    assert placement_from_click((150.0, 275.0), RECT) == pytest.approx((0.25, 0.75))
    assert placement_from_click((99.0, 300.0), RECT) is None               # outside the frame: ignored
    assert placement_from_click((200.0, 501.0), RECT) is None
    assert placement_from_click((5.0, 5.0), (10.0, 10.0, 10.0, 20.0)) is None  # a degenerate frame


def test_marker_is_drawn_where_the_click_was():
    rng = np.random.default_rng(0)
    for u, v in rng.uniform(0, 1, (20, 2)):
        assert placement_from_click(region_from_placement((u, v), RECT), RECT) == pytest.approx((u, v))


def _project(point, camera, fov_deg, elevation_deg, aspect):
    """Photo fractions (x from left, y from top) of a world point seen by the composite camera."""
    pitch = math.radians(-elevation_deg)
    forward = np.array([0.0, math.cos(pitch), math.sin(pitch)])
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(right, forward)
    rel = np.asarray(point) - camera
    depth = rel @ forward
    tan_w = math.tan(math.radians(fov_deg) / 2)
    return (0.5 + rel @ right / depth / tan_w / 2, 0.5 - rel @ up / depth / (tan_w / aspect) / 2)


def test_the_camera_puts_the_asset_base_on_the_placement_at_the_asked_size():
    base, height = np.array([1.0, 2.0, 0.5]), 2.0
    camera = camera_for_placement(base, height, (0.3, 0.8), 0.25, PhotoCamera(pitch_deg=-10.0, fov_deg=60.0, width=400, height=300))
    assert _project(base, camera, 60.0, 10.0, 4 / 3) == pytest.approx((0.3, 0.8))
    # At the base's depth, the asset's height spans `size` of the frame (the top is nearer the centre).
    top = base + np.array([0.0, 0.0, height])
    assert camera[2] > base[2]
    _, y_top = _project(top, camera, 60.0, 10.0, 4 / 3)
    assert 0.8 - y_top == pytest.approx(0.25, rel=0.15)


def test_a_placement_above_the_horizon_is_refused_with_a_sentence():
    with pytest.raises(InputError, match="above the horizon"):
        camera_for_placement(np.zeros(3), 1.0, (0.5, 0.1), 0.3, PhotoCamera(pitch_deg=-10.0, fov_deg=60.0, width=300, height=200))


def _blender_camera(yaw: float, pitch: float, roll: float, location) -> np.ndarray:
    """A Blender camera's world matrix (looks down local -Z, +Y up) from core's PhotoCamera basis."""
    forward, right, up, _, _ = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, roll_deg=roll).basis()
    matrix = np.eye(4)
    matrix[:3, :3] = np.column_stack([right, up, -forward])
    matrix[:3, 3] = location
    return matrix


def _turn(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("yaw, pitch, roll, object_yaw", [(90.0, -10.0, 0.0, 0.0), (30.0, -18.0, 4.0, 25.0),
                                                          (-140.0, -6.0, -3.0, 200.0)])
def test_the_pipeline_composes_the_asset_as_the_artists_camera_shows_it(yaw, pitch, roll, object_yaw):
    """asset_in_view turns an artist's arrangement (their camera, the asset where they put it) into the
    placement, size and turn core's place_asset takes: every vertex lands on the same photo pixel."""
    from scenefit.core.data.mesh import Mesh, normalize_to_unit_sphere
    from scenefit.core.data.primitives import uv_sphere
    from scenefit.core.scene.asset_pose import place_asset, placed_mesh
    from scenefit.core.scene.camera import camera_origin

    width, height, fov = 640, 480, 55.0
    sphere = uv_sphere(0.5, 12, 6)
    asset = Mesh.from_arrays(sphere.positions * np.array([1.2, 0.5, 2.0]) + np.array([0.3, 0.0, 1.0]),
                             sphere.faces, sphere.uvs, name="box")
    camera_at = np.array([2.0, -1.0, 1.7])
    forward = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch).basis()[0]
    floor_point = camera_at + forward * (1.7 / -forward[2])           # where the view meets the floor z = 0
    world = asset.positions @ _turn(object_yaw).T * 0.6 + floor_point + np.array([0.1, 0.2, 0.0])
    view = asset_in_view(_blender_camera(yaw, pitch, roll, camera_at), fov, width, height, world, object_yaw)
    assert (view.pitch_deg, view.roll_deg) == pytest.approx((pitch, roll), abs=1e-9)
    assert view.yaw_deg == pytest.approx(yaw, abs=1e-9)

    seen = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=fov, width=width, height=height,
                       roll_deg=roll).project(world, camera_at)
    core_camera = PhotoCamera(pitch_deg=pitch, fov_deg=fov, width=width, height=height, roll_deg=roll)
    normalized, _ = normalize_to_unit_sphere(asset)
    placement = place_asset(normalized, core_camera, (view.placement[0] * width, view.placement[1] * height),
                            view.size, view.turn_deg)
    composed = core_camera.project(placed_mesh(normalized, placement).positions, camera_origin())
    assert np.abs(composed - seen).max() < 0.02    # pixels (the fixed-point sizing converges to ~1e-6)


def test_an_asset_behind_the_scene_camera_is_refused_in_one_sentence():
    points = np.array([[0.0, -1.0, 0.0], [0.0, 3.0, 0.0], [0.0, 3.0, 1.0]])
    with pytest.raises(InputError, match="behind the scene camera"):
        asset_in_view(_blender_camera(90.0, -10.0, 0.0, (0.0, 0.0, 1.0)), 60.0, 64, 48, points, 0.0)


def test_quality_panel_times_are_the_bench_measurements():
    from scenefit.workers import time_model as quality   # (the panel's numbers, without bpy)

    root = ROOT
    EXPECTED_SECONDS = quality.EXPECTED_SECONDS
    runs = json.loads((root / "benchmarks/results/trade_run.json").read_text())["rows"]
    measured = {(stage, row["preset"]): seconds for row in runs for stage, seconds in row["stage_seconds"].items()}
    shown = 0
    for stage, presets in EXPECTED_SECONDS.items():
        for preset, seconds in presets.items():
            if seconds is not None:
                assert seconds == pytest.approx(measured[stage, preset], abs=0.01), (stage, preset)
                shown += 1
    assert shown >= 9   # convert, light and compose at every preset
    from scenefit.core.pipeline.registry import expected_seconds

    assert EXPECTED_SECONDS == expected_seconds()   # the panel's copy is the stage registry's


def test_adapts_projected_time_is_the_sd2_bench_measurement():
    """The panel's adapt time and the warning before hours of local work come from the SD2-size bench
    (benchmarks/results/adapt_sd2.json: the cached bf16 rows, warm step) and the presets' iterations."""
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.workers import time_model as quality   # (the panel's numbers, without bpy)

    root = ROOT
    rows = json.loads((root / "benchmarks/results/adapt_sd2.json").read_text())["rows"]
    measured = {row["preset"]: row["warm_s"] for row in rows if row["cache"] and "bfloat16" in row["dtype"]}
    for preset, seconds in quality.ADAPT_SECONDS_PER_ITERATION.items():
        assert (seconds is None and preset not in measured) or seconds == pytest.approx(measured[preset], abs=0.1)
        iterations = stage_config("adapt", preset, prompt="a test").iterations
        assert quality.preset_iterations(preset) == iterations   # (the table, read without loading torch)
        if seconds is not None:   # the projection takes the preset's iterations from the presets themselves
            assert quality.adapt_projection(preset) == pytest.approx(seconds * iterations)
    assert quality.adapt_projection("draft", 10) == pytest.approx(10 * quality.ADAPT_SECONDS_PER_ITERATION["draft"])
    # On a GPU: `make gpu-check`'s rows (one H200), the step without the per-view constant work it still
    # held while the views came up.
    gpu = json.loads((root / "benchmarks/results/gpu.json").read_text())
    assert not gpu["machine"]["dry_run"] and gpu["machine"]["device"] in quality.GPU_BENCH_MACHINE
    steady = {row["preset"]: row["iteration_s"] - row["phases"]["constants"] for row in gpu["rows"]}
    assert set(steady) == set(quality.ADAPT_GPU_SECONDS_PER_ITERATION)
    for preset, seconds in quality.ADAPT_GPU_SECONDS_PER_ITERATION.items():
        assert seconds == pytest.approx(steady[preset], abs=0.01)
        assert quality.adapt_projection(preset, gpu=True) < quality.adapt_projection(preset) / 20
    where = quality.LocalWork(quality.adapt_projection("final", gpu=True), on_gpu=True).where()
    assert where.startswith("on this GPU for about 5.5 h") and "H200" in where, where
    assert [quality.duration_text(s) for s in (30, 600, 12000, 4 * 86400)] == ["30 s", "10 min", "3.3 h", "4.0 days"]


def test_blender_shows_a_sideways_stored_photo_upright_like_the_pipeline(tmp_path, run_py):
    """Blender ignores EXIF Orientation; the photo it shows behind the camera (where the artist clicks
    the placement) must be the upright picture the pipeline reads, and must survive save and reopen."""
    import OpenImageIO as oiio

    stored = np.full((40, 60, 3), 0.2, np.float32)
    stored[:8, :8] = 1.0
    spec = oiio.ImageSpec(60, 40, 3, oiio.UINT8)
    spec.attribute("Orientation", 6)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), stored)
    photo = tmp_path / "portrait.jpg"
    assert buf.write(str(photo))
    proc = run_py(f"""
        import json
        import bpy, numpy as np
        from scenefit.blender_io.compose import ensure_photo_camera, load_photo_image
        from scenefit.core.scene.camera import PhotoCamera
        from scenefit.core.data.photo import load_photo

        bpy.ops.wm.read_factory_settings(use_empty=True)
        image = load_photo_image({str(photo)!r})
        assert load_photo_image({str(photo)!r}) == image            # loaded once
        ensure_photo_camera(bpy.context.scene, image, PhotoCamera(pitch_deg=-11.5, fov_deg=57.3))
        bpy.ops.wm.save_as_mainfile(filepath={str(tmp_path / 'scene.blend')!r})
        bpy.ops.wm.open_mainfile(filepath={str(tmp_path / 'scene.blend')!r})
        cam = bpy.data.scenes["SceneFit Composite"].camera.data
        shown = cam.background_images[0].image
        w, h = shown.size
        px = np.array(shown.pixels[:]).reshape(h, w, 4)[::-1, :, :3]
        ours, _ = load_photo({str(photo)!r})
        print("JSON" + json.dumps({{"size": [w, h], "packed": shown.packed_file is not None,
                          "diff": float(np.abs(px - ours).max())}}))
    """)
    result = printed_json(proc)
    assert result["size"] == [40, 60] and result["packed"]
    assert result["diff"] < 2 / 255


def test_blenders_cameras_and_the_photo_camera_agree_on_a_lens_shift(run_py, tmp_path):
    """SceneFit's camera made from a shifted PhotoCamera shows a point where the PhotoCamera projects it
    (Blender's own projection), landscape and portrait; an artist's shifted camera read back as a PhotoCamera
    has its optical axis on the pixel Blender's shift puts it."""
    from scenefit.core.data.imageio import write_image

    for name, size in (("wide", (60, 40)), ("tall", (40, 60))):
        write_image(tmp_path / f"{name}.png", np.full((size[1], size[0], 3), 0.5, np.float32))
    proc = run_py(f"""
        import json
        import bpy
        from bpy_extras.object_utils import world_to_camera_view
        from mathutils import Vector
        from scenefit.blender_io.compose import ensure_photo_camera, load_photo_image
        from scenefit.blender_io.scene_camera import lens_shift, principal_point
        from scenefit.core.scene.camera import PhotoCamera, camera_origin, pixel_ray

        bpy.ops.wm.read_factory_settings(use_empty=True)
        seen = {{}}
        for name in ("wide", "tall"):
            image = load_photo_image({str(tmp_path)!r} + "/" + name + ".png")
            w, h = image.size
            camera = PhotoCamera(pitch_deg=-8.0, fov_deg=52.0, roll_deg=4.0, width=w, height=h, shift_x=0.12,
                                 shift_y=-0.07)
            cam = ensure_photo_camera(bpy.context.scene, image, camera)
            cam.location = tuple(camera_origin())
            own = bpy.data.scenes["SceneFit Composite"]
            own.view_layers[0].update()
            point = camera_origin() + 5.0 * pixel_ray(camera, 21.0, 13.0)
            co = world_to_camera_view(own, cam, Vector(tuple(point)))
            artist = bpy.data.objects.new("Artist" + name, bpy.data.cameras.new("Artist" + name))
            artist.data.sensor_fit, artist.data.shift_x, artist.data.shift_y = "AUTO", 0.2, 0.05
            read = PhotoCamera(width=w, height=h, **lens_shift(artist, w, h))
            seen[name] = {{"drawn": [co.x * w, (1.0 - co.y) * h], "axis": list(read.principal_px()),
                          "blender_axis": list(principal_point(artist, w, h))}}
        print("JSON" + json.dumps(seen))
    """)
    for name, result in printed_json(proc).items():
        assert result["drawn"] == pytest.approx([21.0, 13.0], abs=1e-3), name
        assert result["axis"] == pytest.approx(result["blender_axis"], abs=1e-9), name
