"""The unseen light's direction comes from the photo: the side its surfaces are brighter on."""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.cues import LOBE_ELEVATION_DEG, photo_bright_side
from scenefit.core.stages.light.depth import DepthConfig
from scenefit.core.stages.light.measure import dominant_direction
from scenefit.core.render.photo import develop_photo
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.camera import PhotoCamera


def _side_lit_room(side: str, width: int = 96, height: int = 72) -> np.ndarray:
    """Matte walls lit by a lamp out of frame on one side: radiance falls off as 1 / distance^2 from it."""
    cols = np.arange(width) / width if side == "right" else 1.0 - np.arange(width) / width
    radiance = 0.02 + 0.5 / (1.0 + 3.0 * (1.0 - cols)) ** 2
    return np.repeat(np.broadcast_to(radiance, (height, width))[..., None], 3, axis=-1).astype(np.float32)


def _estimate(photo: np.ndarray, scene: str = "indoor"):
    h, w = photo.shape[:2]
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=w, height=h)   # looks along +Y
    config = stage_config("light", "draft", scene_type=scene, critic_type="none", depth=DepthConfig(depth_type="geometric"))
    return estimate_light(photo, (w / 2, h * 0.85), config, photo_camera=camera)


@pytest.mark.parametrize("side, sign", [("right", 1.0), ("left", -1.0)])
@pytest.mark.parametrize("scene", ["indoor", "outdoor"])
def test_the_unseen_light_is_on_the_side_the_photo_is_brighter(side, sign, scene):
    photo = develop_photo(_side_lit_room(side)).astype(np.float32) / 255.0
    assert sign * photo_bright_side(photo)[0] > 0.2
    result = _estimate(photo, scene)
    direction = np.array(result.decisions["cues"]["unseen"]["direction"])
    # The camera's right is world +X: the light lies on that side, above the horizon, at the lobe's height.
    assert sign * direction[0] > 0.3, direction
    assert math.degrees(math.asin(direction[2])) == pytest.approx(LOBE_ELEVATION_DEG, abs=1.0)
    assert sign * dominant_direction(result.hdr)[0] > 0.2


def test_an_evenly_lit_photo_keeps_the_light_behind_the_camera():
    photo = np.full((72, 96, 3), 0.5, np.float32)
    direction = np.array(_estimate(photo).decisions["cues"]["unseen"]["direction"])
    assert abs(direction[0]) < 0.05 and direction[1] < -0.5 and direction[2] > 0.3
