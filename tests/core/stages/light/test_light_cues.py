"""The weight-free light cues on synthetic scenes with known answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenefit.core.data.imageio import srgb_to_linear
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.cues import CueConfig, build_cues, exposure_clip_scale
from scenefit.core.stages.light.hdr import is_dark_environment
from scenefit.core.stages.light.measure import dominant_direction
from scenefit.core.render.photo import develop_photo
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.frame import equirect_directions


def _sun_radiance(sun_value: float, size=(60, 80), radius=4):
    """Grey surfaces (0.05..0.3, a ramp) with a disc of `sun_value` radiance: a single sun in view."""
    h, w = size
    rows, cols = np.mgrid[0:h, 0:w]
    radiance = np.repeat((0.05 + 0.25 * cols / w)[..., None], 3, axis=-1).astype(np.float32)
    disc = (rows - 15) ** 2 + (cols - 50) ** 2 <= radius ** 2
    radiance[disc] = sun_value
    return radiance, disc


@pytest.mark.parametrize("sun", [40.0, 3000.0])
def test_exposure_cue_recovers_a_clipped_sun_from_the_photo_metering(sun):
    radiance, disc = _sun_radiance(sun)
    photo = develop_photo(radiance).astype(np.float32) / 255.0      # auto-exposed, clipped, 8 bits
    exposure = 0.18 / math.exp(np.log(radiance @ np.array([0.2126, 0.7152, 0.0722], np.float32)).mean())
    scale, info = exposure_clip_scale(photo, 0.98)
    # The clipped pixels are the disc (radiance x exposure above 1), their value is sun x exposure.
    assert info["clipped_fraction"] == pytest.approx(disc.mean(), abs=2e-3)
    assert scale == pytest.approx(sun * exposure, rel=0.1)
    # Nothing clipped: no scale beyond the stored value.
    assert exposure_clip_scale(np.full((8, 8, 3), 0.5, np.float32), 0.98)[0] == 1.0


def _uniform_map(level: float, h=16):
    ldr = np.full((h, 2 * h, 3), level, np.float32)
    unseen = np.ones((h, 2 * h), bool)
    dirs = equirect_directions(h, 2 * h)
    seen = dirs @ np.array([0.0, 1.0, 0.0]) > math.cos(math.radians(35))   # the photo looked along +Y
    unseen[seen] = False
    return ldr, unseen


def test_energy_cue_lights_the_unseen_upper_hemisphere_to_explain_the_surfaces():
    # A photo of matte surfaces of linear radiance S (no light in view): an unseen area light must light them.
    s_linear = 0.2
    photo = np.full((12, 16, 3), float(np.round(255 * (1.055 * s_linear ** (1 / 2.4) - 0.055)) / 255), np.float32)
    ldr, unseen = _uniform_map(float(photo[0, 0, 0]))
    config = CueConfig(albedo=0.25)
    cues = build_cues(photo, ldr, unseen, {}, config=config)
    hdr_unseen = srgb_to_linear(cues.ldr)[cues.regions["unseen"]].mean(axis=-1) * cues.scales["unseen"]
    solid = np.sin(np.pi * (np.arange(16) + 0.5) / 16)[:, None] * np.ones((1, 32))
    mean = np.average(hdr_unseen, weights=solid[cues.regions["unseen"]])
    expected = s_linear * (2 / config.albedo - 1)      # camera-facing surfaces: half unseen light, half ground
    assert mean == pytest.approx(expected, rel=0.03)
    # Brighter surfaces call for more light, in proportion; a darker albedo for more still.
    assert cues.report["unseen"]["mean_radiance_range"][0] < expected < cues.report["unseen"]["mean_radiance_range"][1]
    # The unseen light sits behind the camera (-Y) and above the horizon; the map's dominant light is there.
    direction = np.array(cues.report["unseen"]["direction"])
    assert direction[1] < -0.1 and direction[2] > 0.5
    from scenefit.core.stages.light.hdr import hdr_from_scales

    hdr = hdr_from_scales(cues.ldr, cues.regions, cues.scales)
    # (the measure weights texels by solid angle, which pulls a near-zenith lobe a little towards the horizon)
    assert dominant_direction(hdr) @ direction > math.cos(math.radians(35))


def test_a_single_area_light_indoors_is_found_where_it_is_and_as_bright_as_the_metering_says():
    # A window-like area light in view of a dim room: the photo clips it; its scale comes from the metering.
    h, w = 48, 64
    radiance = np.full((h, w, 3), 0.08, np.float32)
    radiance[8:20, 36:48] = 30.0
    photo = develop_photo(radiance).astype(np.float32) / 255.0
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=0.0, fov_deg=60.0, width=w, height=h)
    result = estimate_light(photo, (32.0, 44.0), stage_config("light", "draft", scene_type="indoor", map_height=32,
                                                              depth=_geometric()), photo_camera=camera)
    exposure = 0.18 / math.exp(np.log(radiance[..., 0]).mean())
    # 8-bit rounding of the unclipped pixels (0.5 %) is amplified by (1 - f) / f = 20 in the clipped log-mean.
    assert result.scales["clipped"] == pytest.approx(30.0 * exposure, rel=0.15)
    # The light is above the horizon in front of the camera (+Y), a little to the right (+X).
    light = dominant_direction(result.hdr)
    assert light[1] > 0.7 and light[2] > 0.1 and light[0] > 0.0
    assert "cues" in result.decisions and result.decisions["prior"]["type"] == "cues"


def _geometric():
    from scenefit.core.stages.light.depth import DepthConfig

    return DepthConfig(depth_type="geometric")


def test_a_dark_scene_stays_dark():
    # Night: dark surfaces, a few small street lights. The map must stay dark (the paper's dark rule fires).
    h, w = 48, 64
    radiance = np.full((h, w, 3), 0.002, np.float32)
    radiance[30:, :] = 0.004
    radiance[20:22, 10:12] = radiance[20:22, 50:52] = 3.0
    photo = develop_photo(radiance, exposure=1.0).astype(np.float32) / 255.0   # kept dark, not auto-exposed
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=0.0, fov_deg=60.0, width=w, height=h)
    result = estimate_light(photo, (32.0, 44.0), stage_config("light", "draft", scene_type="outdoor", map_height=32),
                            photo_camera=camera)
    dark, info = is_dark_environment(result.hdr, {k: v for k, v in result.regions.items() if k == "clipped"})
    assert dark, info
    assert result.decisions["cues"]["exposure"]["metered"] is False
    # Nothing brighter than the surfaces call for: the map's mean stays within the energy bound.
    surfaces = srgb_to_linear(photo)[photo.max(-1) < 0.8].mean()
    assert result.hdr.mean() < surfaces * (2 / 0.15 - 1)


# -- indoor or outdoor -----------------------------------------------------------------------------
DEVELOPMENT = {"studio": "indoor", "interior": "indoor", "city": "outdoor", "forest": "outdoor"}


@pytest.fixture(scope="module")
def development_photos():
    from scenefit.core.data.imageio import read_image
    from scenefit.core.render.photo import perspective_view, studiolight_path

    photos = []
    for name, truth in DEVELOPMENT.items():
        hdr = read_image(studiolight_path(name))[..., :3]
        for pitch in (-10.0, 10.0):
            for yaw in (0.0, 120.0, 240.0):
                camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=60.0, width=320, height=240)
                photos.append((name, yaw, pitch, truth, develop_photo(perspective_view(hdr, camera)) / 255.0))
    return photos


def test_auto_scene_type_is_right_on_every_development_photo(development_photos):
    from scenefit.core.stages.light.scene_type import scene_type_cue

    wrong = [(name, yaw, pitch, cue["score"]) for name, yaw, pitch, truth, photo in development_photos
             if (cue := scene_type_cue(photo.astype(np.float32)))["scene_type"] != truth]
    assert not wrong, wrong
    # The same call at another photo size (the cue works on a fixed width).
    name, _, _, truth, photo = development_photos[-1]
    import cv2

    assert scene_type_cue(cv2.resize(photo.astype(np.float32), (640, 480)))["scene_type"] == truth


def test_an_ambiguous_photo_is_called_unsure_and_the_report_says_so():
    from scenefit.core.stages.light.scene_type import SKY_RATIO_AT, scene_type_cue

    # Smooth, no clutter; the top eighth exactly SKY_RATIO_AT times brighter than the bottom: score 1.
    linear = np.full((80, 64, 3), 0.1, np.float32)
    linear[:10] = 0.1 * SKY_RATIO_AT
    from scenefit.core.data.imageio import linear_to_srgb

    photo = linear_to_srgb(linear)
    cue = scene_type_cue(photo)
    assert cue["unsure"] and cue["score"] == pytest.approx(1.0, abs=0.02) and cue["clutter"] == 0.0
    result = estimate_light(photo, (32.0, 70.0), stage_config("light", "draft", map_height=16, depth=_geometric()))
    assert "unsure" in result.decisions["scene_type"]["note"]
    assert result.decisions["scene_type"]["auto"]["score"] == cue["score"]
    # A clearly dark, smooth room is indoor and sure.
    room = linear_to_srgb(np.full((80, 64, 3), 0.05, np.float32))
    assert scene_type_cue(room)["scene_type"] == "indoor" and not scene_type_cue(room)["unsure"]


# -- what counts as clipped ------------------------------------------------------------------------
@pytest.mark.parametrize("painted", [False, True])
def test_only_clipped_texels_the_photo_or_a_model_made_take_the_exposure_scale(painted):
    # The unseen sky is filled with a clipped colour (as the sky prior's zenith often is): a fill the camera
    # never measured is part of the unseen light, at the mean the surfaces call for; lights a model painted
    # there stay lights (their own "clipped" region).
    s_linear = 0.2
    photo = np.full((12, 16, 3), float(np.round(255 * (1.055 * s_linear ** (1 / 2.4) - 0.055)) / 255), np.float32)
    ldr, unseen = _uniform_map(float(photo[0, 0, 0]))
    upper = equirect_directions(*unseen.shape)[..., 2] > 0
    ldr[unseen & upper] = 1.0
    config = CueConfig(albedo=0.25)
    cues = build_cues(photo, ldr, unseen, {"far": unseen & upper}, config=config, painted_unseen=painted)
    assert ("clipped" in cues.scales) == painted
    if not painted:
        assert np.array_equal(cues.regions["unseen"], unseen & upper)
        hdr = srgb_to_linear(cues.ldr)[cues.regions["unseen"]].mean(axis=-1) * cues.scales["unseen"]
        solid = np.sin(np.pi * (np.arange(16) + 0.5) / 16)[:, None] * np.ones((1, 32))
        mean = np.average(hdr, weights=solid[cues.regions["unseen"]])
        assert mean == pytest.approx(s_linear * (2 / config.albedo - 1), rel=0.03)



def test_a_clipped_floor_is_a_lit_surface_not_a_light():
    # A studio: the lamp and the white floor around the object both clip. The exposure cue's power is the
    # lamp's: clipped texels below the horizon (the floor the object stands on, seen all around it once
    # unwrapped) keep their stored level instead of spreading the lamp's scale around the object.
    photo = np.full((12, 16, 3), 0.25, np.float32)   # darker than mid-grey: the clipped pixels hold the rest
    photo[:2, 6:10] = 1.0      # the lamp
    photo[9:, :] = 1.0         # the floor
    ldr, unseen = _uniform_map(0.25)
    dirs = equirect_directions(*unseen.shape)
    lamp = ~unseen & (dirs[..., 2] > 0.3)
    floor = dirs[..., 2] < -0.2
    ldr[lamp | floor] = 1.0
    unseen &= ~floor
    cues = build_cues(photo, ldr, unseen, {"near": lamp | floor})
    assert cues.scales["clipped"] > 2.0
    assert np.array_equal(cues.regions["clipped"], lamp)
    assert np.array_equal(cues.regions["near"], floor) and cues.scales["near"] == 1.0


@pytest.mark.parametrize("sun", [None, np.array([0.0, -0.8, 0.6])])
def test_the_artists_sun_narrows_the_unseen_lobe_and_keeps_its_energy(sun):
    # A known direction need not hedge: the unseen light becomes cos^8 over 0.05 instead of cos^4 over 0.25,
    # with the same mean radiance (what the surfaces call for).
    s_linear = 0.2
    photo = np.full((12, 16, 3), float(np.round(255 * (1.055 * s_linear ** (1 / 2.4) - 0.055)) / 255), np.float32)
    ldr, unseen = _uniform_map(float(photo[0, 0, 0]), h=32)
    config = CueConfig()
    cues = build_cues(photo, ldr, unseen, {}, config=config, sun=sun)
    hidden = cues.regions["unseen"]
    shade = (srgb_to_linear(cues.ldr) / srgb_to_linear(ldr)).mean(axis=-1)[hidden]
    direction = np.array(cues.report["unseen"]["direction"])
    floor, sharpness = (config.lobe_floor, config.lobe_sharpness) if sun is None else \
        (config.sun_lobe_floor, config.sun_lobe_sharpness)
    lobe = np.maximum(equirect_directions(32, 64)[hidden] @ direction, 0.0) ** sharpness
    assert np.allclose(shade, floor + (1 - floor) * lobe, atol=2e-4)
    assert cues.report["unseen"]["lobe"] == {"floor": floor, "sharpness": sharpness}
    if sun is not None:
        assert direction @ sun > 0.999
        assert shade.min() == pytest.approx(config.sun_lobe_floor, abs=1e-3)
    solid = np.sin(np.pi * (np.arange(32) + 0.5) / 32)[:, None] * np.ones((1, 64))
    mean = np.average(srgb_to_linear(cues.ldr).mean(axis=-1)[hidden] * cues.scales["unseen"], weights=solid[hidden])
    assert mean == pytest.approx(s_linear * (2 / config.albedo - 1), rel=0.03)
