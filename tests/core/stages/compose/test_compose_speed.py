"""What keeps a 12 MP photo's draft run under 30 s without changing what compose makes:
the pilot measures noise with fewer, larger pixels, and a draft composes at most 2048 px."""
from __future__ import annotations

import numpy as np
import pytest

from scenefit.core.stages.compose import (COMPOSE_MAX_SIDE, PILOT_MAX_SIDE, ComposeConfig, ComposeInputs, compose,
                                   pilot_view)
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.data.photo import load_photo
from scenefit.core.render.environment import sun_environment
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.camera import PhotoCamera


def test_the_pilot_sees_the_whole_box_with_fewer_larger_pixels():
    camera = PhotoCamera(width=4000, height=3000)
    assert pilot_view(camera, (10, 20, 110, 220)) == (camera, (10, 20, 110, 220))     # already small
    small, box = pilot_view(camera, (1236, 1626, 2766, 2531))                          # 1530 px: k = 6
    assert (small.width, small.height, small.fov_deg) == (666, 500, camera.fov_deg)
    assert box == (206, 271, 461, 422) and max(box[2] - box[0], box[3] - box[1]) <= PILOT_MAX_SIDE
    # (the box's corners, divided by 6, rounded outwards: every pixel of the asset is in it)


def test_a_pilot_with_larger_pixels_chooses_the_samples_the_full_pilot_would():
    """Noise per pixel barely depends on the pixel's size: a pilot at an eighth of the resolution picks
    about the sample count a full-resolution pilot picks."""
    import scenefit.core.stages.compose as module

    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-20.0, fov_deg=60.0, width=320, height=240)
    env = sun_environment([0.6, 0.3, 0.8], sun_radiance=20.0, sun_radius_deg=10.0)
    photo = np.full((240, 320, 3), 0.5, np.float32)
    maps = np.concatenate([np.full((8, 8, 3), 0.6, np.float32), np.full((8, 8, 2), 0.5, np.float32)], -1)
    chosen = {}
    original = module.pilot_view.__defaults__
    for side in (24, 4096):
        try:
            module.pilot_view.__defaults__ = (side,)
            result = compose(ComposeInputs(uv_sphere(0.5, 24, 12), maps, photo, (160.0, 190.0), env, camera),
                             ComposeConfig(size=0.8, spp=None, shadow_type="none", noise_target=0.02, max_spp=256))
        finally:
            module.pilot_view.__defaults__ = original
        chosen[side] = result.report["decisions"]["spp"]
    small, whole = chosen[24], chosen[4096]
    assert whole["from"] == small["from"] == "noise target"
    assert small["pilot_noise"] == pytest.approx(whole["pilot_noise"], rel=0.3)
    assert abs(np.log2(small["spp"] / whole["spp"])) <= 0.6    # measured: 35 and 35 spp (noise 0.0556, 0.0552)


def test_a_draft_composes_at_most_2048_px_and_the_others_at_the_photos_size(tmp_path):
    assert stage_config("compose", "draft").max_side == 2048
    assert stage_config("compose", "balanced").max_side == stage_config("compose", "final").max_side == COMPOSE_MAX_SIDE
    photo = write_image(tmp_path / "wide.png", np.full((1000, 2500, 3), 0.4, np.float32))
    assert load_photo(photo, max_side=stage_config("compose", "draft").max_side)[0].shape[:2] == (500, 1250)
    assert load_photo(photo, max_side=stage_config("compose", "balanced").max_side)[0].shape[:2] == (1000, 2500)
    for wrong in (10, COMPOSE_MAX_SIDE + 1):
        with pytest.raises(InputError, match="long side"):
            ComposeConfig(max_side=wrong)
