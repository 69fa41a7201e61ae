"""The sun from a shadow the artist points at: the foot of something upright, its
top and its shadow's tip, through the photo's camera, give --sun's azimuth and elevation."""
from __future__ import annotations

import json

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.stages.light.estimate import sun_direction
from scenefit.core.stages.light.shadow_hint import CLICK_SLIP, sun_from_shadow, sun_uncertainty_deg
from scenefit.core.scene.camera import CAMERA_HEIGHT, PhotoCamera

from conftest import printed_json

CAMERA = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=60.0, width=640, height=480, roll_deg=2.0)
ORIGIN = np.array([0.0, 0.0, CAMERA_HEIGHT])


def shadow_pixels(sun_deg, foot=(0.4, 4.0), height=1.2, camera=CAMERA):
    """The photo pixels of a post's foot and top and of its shadow's tip under the sun `sun_deg`."""
    d = sun_direction(sun_deg, camera)
    base = np.array([foot[0], foot[1], 0.0])
    top = base + np.array([0.0, 0.0, height])
    tip = top - d * (top[2] / d[2])
    return [tuple(camera.project(p[None], ORIGIN)[0]) for p in (base, top, tip)]


@pytest.mark.parametrize("sun", [(40.0, 35.0), (-120.0, 20.0), (170.0, 8.0), (0.0, 60.0), (-15.0, 30.0)])  # (a shadow toward the camera stays in front of it)
def test_the_shadow_gives_back_the_sun_that_cast_it(sun):
    az, el = sun_from_shadow(CAMERA, *shadow_pixels(sun))
    assert (az, el) == (pytest.approx(sun[0], abs=1e-6), pytest.approx(sun[1], abs=1e-6))


def test_a_sun_straight_overhead_casts_the_shadow_onto_the_foot():
    foot, top, _ = shadow_pixels((10.0, 45.0))
    assert sun_from_shadow(CAMERA, foot, top, foot)[1] == pytest.approx(90.0, abs=1e-6)


def test_a_turned_camera_measures_azimuth_from_its_own_view():
    turned = PhotoCamera(yaw_deg=30.0, pitch_deg=-20.0, fov_deg=50.0, width=400, height=300)
    foot = (3.0, 1.5)     # in front of a camera looking along yaw 30
    az, el = sun_from_shadow(turned, *shadow_pixels((65.0, 30.0), foot=foot, camera=turned))
    assert (az, el) == (pytest.approx(65.0, abs=1e-6), pytest.approx(30.0, abs=1e-6))


def test_points_that_cannot_be_a_shadow_are_one_sentence():
    foot, top, tip = shadow_pixels((40.0, 35.0))
    with pytest.raises(InputError, match="above the horizon"):
        sun_from_shadow(CAMERA, (320.0, 20.0), top, tip)          # the foot in the sky
    with pytest.raises(InputError, match="not above the foot"):
        sun_from_shadow(CAMERA, foot, (foot[0], foot[1] + 40.0), tip)   # the top below the foot
    with pytest.raises(InputError, match="straight above"):
        sun_from_shadow(CAMERA, foot, (foot[0] + 150.0, top[1]), tip)   # the top beside it


def test_a_shorter_shadow_pins_the_sun_less_and_the_photos_size_does_not_matter():
    """The uncertainty is how far the sun turns when one click slips CLICK_SLIP of the width: it grows as
    the post (and its shadow) shrinks, and the same shadow in a photo twice as wide gives the same."""
    spreads = [sun_uncertainty_deg(CAMERA, *shadow_pixels((40.0, 35.0), foot=(0.4, 10.0), height=h))
               for h in (2.0, 1.0, 0.5, 0.2)]   # a post 10 m away
    assert all(a < b for a, b in zip(spreads, spreads[1:])), spreads
    assert spreads[0] < 15.0 < 30.0 < spreads[-1], spreads    # the lobe's two ends (cues.SURE_DEG, UNSURE_DEG)
    wide = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=60.0, width=1280, height=960, roll_deg=2.0)
    points = shadow_pixels((40.0, 35.0), height=1.0)
    twice = [(2 * x, 2 * y) for x, y in points]   # the same points in a photo of twice the pixels
    assert sun_uncertainty_deg(wide, *twice) == pytest.approx(sun_uncertainty_deg(CAMERA, *points), rel=0.02)
    assert CLICK_SLIP * CAMERA.width == pytest.approx(2.0)


def test_a_slip_that_leaves_the_floor_is_as_unsure_as_can_be():
    level = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=60.0, width=640, height=480)
    foot, top, _ = shadow_pixels((0.0, 10.0), foot=(0.0, 4.0), camera=level)
    x, horizon_y = level.project(np.array([[0.0, 1e6, CAMERA_HEIGHT]]), ORIGIN)[0]   # far along the view
    tip = (x, horizon_y + 1.0)   # a pixel below the horizon: a 2-pixel slip puts it in the sky
    sun_from_shadow(level, foot, top, tip)   # (itself a shadow, of a sun just above the horizon)
    assert sun_uncertainty_deg(level, foot, top, tip) == 90.0


def test_the_unseen_lights_lobe_widens_with_the_suns_uncertainty():
    from scenefit.core.stages.light.cues import SURE_DEG, UNSURE_DEG, CueConfig, sun_lobe

    c = CueConfig()
    narrow, wide = (c.sun_lobe_floor, c.sun_lobe_sharpness), (c.lobe_floor, c.lobe_sharpness)
    assert sun_lobe(c, 0.0) == narrow and sun_lobe(c, SURE_DEG) == narrow
    assert sun_lobe(c, UNSURE_DEG) == pytest.approx(wide) and sun_lobe(c, 90.0) == pytest.approx(wide)
    middle = sun_lobe(c, (SURE_DEG + UNSURE_DEG) / 2)
    assert middle == pytest.approx(((narrow[0] + wide[0]) / 2, (narrow[1] + wide[1]) / 2))


def test_scenefit_light_takes_the_shadow_and_reports_where_the_sun_came_from(tmp_path, capsys):
    photo = write_image(tmp_path / "yard.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                               (48, 64, 3)).astype(np.float32))
    camera = PhotoCamera(pitch_deg=-15.0, fov_deg=60.0, width=64, height=48)
    points = [f"{x / 64:.6f},{y / 48:.6f}" for x, y in shadow_pixels((40.0, 35.0), foot=(0.3, 5.0), camera=camera)]
    common = ["light", "--photo", str(photo), "--at", "0.5,0.8", "--fov", "60", "--pitch", "-15", "--roll", "0",
              "--preset", "draft", "--critic", "none", "--quiet"]
    assert main(common + ["--sun-from-shadow", *points, "--out", str(tmp_path / "light")]) == 0
    sun = json.loads((tmp_path / "light" / "report.json").read_text())["decisions"]["sun"]
    assert sun["deg"] == [pytest.approx(40.0, abs=0.05), pytest.approx(35.0, abs=0.05)]
    assert "shadow" in sun["from"]
    # A long shadow pins the sun (the narrow lobe); a short one far away does not, and the light hedges
    # with the guess's wide lobe (every shadow once got the narrow one)
    report = json.loads((tmp_path / "light" / "report.json").read_text())["decisions"]
    assert sun["uncertainty_deg"] < 15.0 and report["cues"]["unseen"]["lobe"] == {"floor": 0.05, "sharpness": 8.0}
    short = [f"{x / 64:.6f},{y / 48:.6f}" for x, y in shadow_pixels((40.0, 35.0), foot=(0.3, 12.0), height=0.5,
                                                                     camera=camera)]
    assert main(common + ["--sun-from-shadow", *short, "--out", str(tmp_path / "short")]) == 0
    report = json.loads((tmp_path / "short" / "report.json").read_text())["decisions"]
    assert report["sun"]["uncertainty_deg"] > 30.0
    assert report["cues"]["unseen"]["lobe"] == {"floor": 0.25, "sharpness": 4.0}
    capsys.readouterr()
    assert main(common + ["--sun", "10,20", "--sun-from-shadow", *points, "--out", str(tmp_path / "both")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1 and not (tmp_path / "both").exists()


@pytest.mark.blender
def test_pick_sun_in_blender_sets_the_light_stages_sun(run_py, tmp_path):
    """Pick Sun's three points (as EXEC_DEFAULT takes them) become the Scene section's sun, which the
    light stage then uses: its report says so."""
    photo = write_image(tmp_path / "yard.png", np.broadcast_to(np.linspace(0.9, 0.3, 120)[:, None, None],
                                                               (120, 160, 3)).astype(np.float32))
    camera = PhotoCamera(pitch_deg=-15.0, fov_deg=60.0, width=160, height=120)
    foot, top, tip = ([x / 160, y / 120] for x, y in shadow_pixels((-50.0, 30.0), foot=(0.2, 5.0), camera=camera))
    proc = run_py(f"""
        import json, math
        from pathlib import Path
        import bpy, addon_utils
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        settings = bpy.context.scene.scenefit
        settings.photo_path, settings.preset = {str(photo)!r}, "draft"
        settings.camera_from, settings.fov, settings.pitch = "panel", math.radians(60.0), math.radians(-15.0)
        out = {{"before": settings.sun_from}}
        out["ops"] = list(bpy.ops.scenefit.pick_sun(foot={foot}, top={top}, tip={tip}))
        out["sun"] = [settings.sun_from, math.degrees(settings.sun_azimuth), math.degrees(settings.sun_elevation)]
        out["spread"] = math.degrees(settings.sun_uncertainty)
        from scenefit.operators.sun import set_sun
        class Op:
            def report(self, kind, text):
                out["said"] = text
        set_sun(Op(), bpy.context, -50.0, 30.0, "the shadow", out["spread"])
        out["light"] = list(bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior"))
        report = Path(bpy.path.abspath(settings.light_path)).parent / "report.json"
        out["decision"] = json.loads(report.read_text())["decisions"]["sun"]
        settings.sun_azimuth = math.radians(-45.0)   # the artist types a direction over the picked one
        out["typed_spread"] = settings.sun_uncertainty
        settings.sun_uncertainty = math.radians(20.0)   # then how sure they are, then nudges the direction
        settings.sun_elevation = math.radians(35.0)
        settings.sun_azimuth = math.radians(-40.0)
        out["own_spread"] = math.degrees(settings.sun_uncertainty)
        set_sun(Op(), bpy.context, -50.0, 30.0, "the shadow", 7.0)   # a new pick's ± replaces it, and a typed
        settings.sun_azimuth = math.radians(-45.0)                   # direction resets that one again
        out["repicked_typed_spread"] = settings.sun_uncertainty
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    assert out["before"] == "estimate" and out["ops"] == ["FINISHED"] and out["light"] == ["FINISHED"]
    source, azimuth, elevation = out["sun"]
    assert source == "set" and (azimuth, elevation) == (pytest.approx(-50.0, abs=0.01), pytest.approx(30.0, abs=0.01))
    assert out["decision"]["deg"] == [pytest.approx(-50.0, abs=0.01), pytest.approx(30.0, abs=0.01)]
    # the clicks' uncertainty goes with them (it was dropped: every shadow got the narrow lobe)
    assert out["spread"] == pytest.approx(out["decision"]["uncertainty_deg"], abs=0.01) and out["spread"] > 0.0
    assert "for a slip of a click" in out["said"]
    assert out["typed_spread"] == 0.0   # a typed direction is as sure as typed (the pick's ± stayed)
    # an uncertainty the artist typed is theirs: nudging the angles keeps it (it was wiped)
    assert out["own_spread"] == pytest.approx(20.0, abs=1e-4) and out["repicked_typed_spread"] == 0.0


def test_scenefit_run_takes_the_sun_as_angles_or_as_a_shadow(tmp_path, capsys):
    """The whole pipeline takes the artist's sun as `scenefit light` does; the light stage's report says
    where it came from, and a second run with the same sun reuses the light stage."""
    from scenefit.core.data.asset_io import save_asset_folder
    from scenefit.core.data.maps import PBRMaps
    from scenefit.core.data.primitives import uv_sphere

    asset = save_asset_folder(uv_sphere(0.5, 12, 6), PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.6, 0.0),
                              tmp_path / "asset")
    photo = write_image(tmp_path / "yard.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                               (48, 64, 3)).astype(np.float32))
    camera = PhotoCamera(pitch_deg=-15.0, fov_deg=60.0, width=64, height=48)
    points = [f"{x / 64:.6f},{y / 48:.6f}" for x, y in shadow_pixels((-140.0, 40.0), foot=(0.3, 5.0), camera=camera)]
    common = ["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--fov", "60", "--pitch", "-15",
              "--roll", "0", "--preset", "draft", "--guidance", "none", "--spp", "2", "--no-bake", "--quiet"]

    def light_report(out):
        return json.loads((out / "report.json").read_text())["stages"]["light"]

    assert main(common + ["--sun-from-shadow", *points, "--out", str(tmp_path / "shadow")]) == 0
    sun = light_report(tmp_path / "shadow")["report"]["decisions"]["sun"]
    assert sun["deg"] == [pytest.approx(-140.0, abs=0.05), pytest.approx(40.0, abs=0.05)] and "shadow" in sun["from"]
    assert main(common + ["--sun", "30,45", "--out", str(tmp_path / "angles")]) == 0
    assert light_report(tmp_path / "angles")["report"]["decisions"]["sun"]["deg"] == [30.0, 45.0]
    assert main(common + ["--sun", "30,45", "--out", str(tmp_path / "angles")]) == 0
    assert light_report(tmp_path / "angles")["status"] == "reused"
    assert main(common + ["--sun", "-30,45", "--out", str(tmp_path / "angles")]) == 0
    assert light_report(tmp_path / "angles")["status"] == "ran"
    capsys.readouterr()
    # Both at once, or a point that is not one: one sentence, exit 2, nothing written.
    assert main(common + ["--sun", "10,20", "--sun-from-shadow", *points, "--out", str(tmp_path / "both")]) == 2
    assert main(common + ["--sun-from-shadow", "0.5", *points[1:], "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and not (tmp_path / "both").exists() and not (tmp_path / "bad").exists()


@pytest.mark.parametrize("yaw, pitch", [(90.0, -15.0), (-30.0, 5.0), (200.0, -40.0)])
@pytest.mark.parametrize("sun", [(40.0, 35.0), (-120.0, 20.0), (180.0, 8.0), (0.0, 89.0), (-90.0, -10.0)])
def test_a_direction_towards_the_sun_gives_back_its_angles(sun, yaw, pitch):
    from scenefit.core.stages.light.shadow_hint import sun_deg_from_direction

    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=60.0)
    az, el = sun_deg_from_direction(sun_direction(sun, camera), camera.basis()[0])
    assert ((az - sun[0] + 180.0) % 360.0 - 180.0, el) == (pytest.approx(0.0, abs=1e-9), pytest.approx(sun[1]))
    with pytest.raises(InputError, match="straight up or down"):
        sun_deg_from_direction(sun_direction(sun, camera), (0.0, 0.0, -1.0))


@pytest.mark.blender
def test_sun_from_light_reads_a_sun_lights_direction_from_the_photos_camera(run_py, tmp_path):
    """A Sun light turned until its shadows match the photo's gives the Scene section's sun: its azimuth from
    the camera that shows the photo, its elevation; one sentence without a camera or with two Sun lights."""
    photo = write_image(tmp_path / "yard.png", np.full((48, 64, 3), 0.5, np.float32))
    proc = run_py(f"""
        import json, math
        import bpy, addon_utils
        from mathutils import Euler, Vector
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        settings = bpy.context.scene.scenefit
        settings.photo_path = {str(photo)!r}
        out = {{}}
        def sun(name):
            light = bpy.data.objects.new(name, bpy.data.lights.new(name, "SUN"))
            bpy.context.scene.collection.objects.link(light)
            return light
        def call():   # an operator that reports an error raises it here, as RuntimeError
            try:
                return list(bpy.ops.scenefit.sun_from_lamp())
            except RuntimeError as error:
                return ["CANCELLED", str(error)]
        lamp = sun("Key")
        bpy.context.view_layer.objects.active = lamp
        out["no_camera"] = call()
        camera = bpy.data.objects.new("SceneFit Camera", bpy.data.cameras.new("SceneFit Camera"))
        camera["scenefit"] = True
        bpy.context.scene.collection.objects.link(camera)
        bpy.context.scene.camera = camera
        camera.rotation_euler = Euler((math.radians(80.0), 0.0, math.radians(-90.0)))   # looks along +X, 10 deg down
        # Towards the sun: 30 deg to the right of the view (-Y when looking along +X), 40 deg up.
        az, el = math.radians(30.0), math.radians(40.0)
        towards = Vector((math.cos(el) * math.cos(az), -math.cos(el) * math.sin(az), math.sin(el)))
        lamp.rotation_mode = "QUATERNION"
        lamp.rotation_quaternion = Vector((0.0, 0.0, 1.0)).rotation_difference(towards)
        out["ops"] = call()
        out["sun"] = [settings.sun_from, math.degrees(settings.sun_azimuth), math.degrees(settings.sun_elevation)]
        lamp.rotation_quaternion = Vector((0.0, 0.0, 1.0)).rotation_difference(Vector((0.3, 0.2, -0.5)))
        out["below"] = call()
        bpy.context.view_layer.objects.active = camera
        sun("Fill")
        out["two"] = call()
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    assert out["no_camera"][0] == "CANCELLED" and "camera that shows the photo" in out["no_camera"][1]
    assert out["ops"] == ["FINISHED"]
    source, azimuth, elevation = out["sun"]
    assert source == "set" and (azimuth, elevation) == (pytest.approx(30.0, abs=1e-3), pytest.approx(40.0, abs=1e-3))
    assert out["below"][0] == "CANCELLED" and "below the horizon" in out["below"][1]
    assert out["two"][0] == "CANCELLED" and "the scene has 2" in out["two"][1]
