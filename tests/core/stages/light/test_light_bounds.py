"""The light stage is never catastrophically wrong: clipped lights are bounded by what the
photo supports, the answer does not jump with a small exposure change or with the preset."""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenefit.core.data.imageio import srgb_to_linear
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.cues import exposure_clip_scale
from scenefit.core.stages.light.depth import DepthConfig
from scenefit.core.render.photo import camera_exposure, develop_photo
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.camera import PhotoCamera

OLD_CAP = 1e5          # the clipped scale's former cap, which two real indoor views reached
STABLE_FACTOR = 2.0    # a 0.12-stop exposure change may move the clipped scale by at most this
PRESET_TOLERANCE = 0.25   # draft (64 rows) and balanced (128 rows): map means within 25 %


def _room(width: int = 160, height: int = 120) -> np.ndarray:
    """A dim room (a ramp of matte walls) with one small lamp, about 0.6 % of the photo, radiance 60."""
    rows, cols = np.mgrid[0:height, 0:width]
    radiance = np.repeat((0.04 + 0.2 * cols / width + 0.05 * rows / height)[..., None], 3, axis=-1)
    lamp = (rows - 30) ** 2 + (cols - 110) ** 2 <= 4.5 ** 2
    radiance[lamp] = 60.0
    return radiance.astype(np.float32)


def _photo(radiance: np.ndarray, stops: float = 0.0) -> np.ndarray:
    """Metered as the exposure cue assumes (log-average -> 0.18), then `stops` brighter."""
    return develop_photo(radiance, camera_exposure(radiance) * 2.0 ** stops).astype(np.float32) / 255.0


def _estimate(photo: np.ndarray, preset: str = "balanced"):
    h, w = photo.shape[:2]
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=w, height=h)
    config = stage_config("light", preset, scene_type="indoor", critic_type="none",
                          depth=DepthConfig(depth_type="geometric"))
    return estimate_light(photo, (w / 2, h * 0.85), config, photo_camera=camera)


def _mean_radiance(hdr: np.ndarray) -> float:
    rows = (np.arange(hdr.shape[0]) + 0.5) / hdr.shape[0]
    weights = np.sin(np.pi * rows)[:, None] * np.ones((1, hdr.shape[1]))
    return float(np.average(hdr.mean(axis=-1), weights=weights))


def test_the_raw_exposure_cue_is_ill_conditioned_on_this_photo():
    # The premise: the metering equation alone jumps by orders of magnitude for a 0.12-stop change.
    radiance = _room()
    a, info = exposure_clip_scale(_photo(radiance), 0.98)
    b, _ = exposure_clip_scale(_photo(radiance, -0.12), 0.98)
    assert info["clipped_fraction"] < 0.01
    assert max(a, b) / min(a, b) > 100.0


def test_a_small_clipped_light_gets_a_bounded_stable_scale():
    radiance = _room()
    results = [_estimate(_photo(radiance, stops)) for stops in (0.0, -0.12)]
    scales = [r.scales["clipped"] for r in results]
    assert max(scales) / min(scales) < STABLE_FACTOR, scales
    for result, photo in zip(results, (_photo(radiance), _photo(radiance, -0.12))):
        cues = result.decisions["cues"]
        assert float(result.hdr.max()) < OLD_CAP
        # The map's mean stays within 4x of the mean the exposure implies (the report's figure).
        implied = cues["bound"]["implied_mean"]
        assert implied >= float(srgb_to_linear(photo).mean()) * 0.999
        assert _mean_radiance(result.hdr) < 4.0 * implied * 1.02
        # Weak evidence (a speck of clipped pixels) is reported as such.
        assert cues["clipped"]["evidence_weight"] < 0.5 and cues["confidence"] < 1.0


def test_draft_and_balanced_agree_on_the_same_photo():
    photo = _photo(_room())
    draft, balanced = _estimate(photo, "draft"), _estimate(photo, "balanced")
    a, b = _mean_radiance(draft.hdr), _mean_radiance(balanced.hdr)
    assert abs(a - b) / b < PRESET_TOLERANCE, (a, b)
    assert max(draft.hdr.max(), balanced.hdr.max()) < OLD_CAP


def test_the_mean_bound_scales_an_overclaiming_light_down():
    # A photo whose clipped area is a large share (the exposure cue trusted) but a cue too bright
    # for its surfaces: the map's mean is held at 4x the implied mean.
    from scenefit.core.stages.light.cues import CueConfig, bound_scales, solid_angles

    h = 16
    ldr = np.full((h, 2 * h, 3), 0.5, np.float32)
    lamp = np.zeros((h, 2 * h), bool)
    lamp[2:4, 5:9] = True
    ldr[lamp] = 1.0
    omega = solid_angles(h, 2 * h)
    scales, info = bound_scales(ldr, {"clipped": lamp}, {"clipped": 1e6}, omega, 0.2, CueConfig())
    assert info["bound"] and info["mean_after"] == pytest.approx(4 * 0.2, rel=1e-3)
    assert 1.0 <= scales["clipped"] < 1e6
    # Within the bound nothing changes.
    same, info = bound_scales(ldr, {"clipped": lamp}, {"clipped": 2.0}, omega, 0.2, CueConfig())
    assert same == {"clipped": 2.0} and not info["bound"]
    assert math.isclose(info["mean_before"], info["mean_after"])


def test_weak_evidence_leans_the_map_towards_the_flat_environment():
    from scenefit.core.stages.light.hdr import hdr_from_scales

    photo = _photo(_room())
    result = _estimate(photo)
    confidence = result.decisions["cues"]["confidence"]
    assert 0.0 < confidence < 1.0
    assert result.decisions["shrink"]["weight"] == pytest.approx(1.0 - confidence, abs=1e-4)
    flat = srgb_to_linear(photo).reshape(-1, 3).mean(axis=0)
    unshrunk = hdr_from_scales(result.ldr, result.regions, result.scales)
    assert np.allclose(result.hdr, confidence * unshrunk + (1.0 - confidence) * flat, rtol=1e-4, atol=1e-6)
    # Full confidence (nothing clipped, no bound reached): the map is the cues' own.
    plain = _estimate(np.full((120, 160, 3), 0.4, np.float32))
    assert plain.decisions["cues"]["confidence"] == 1.0 and "shrink" not in plain.decisions
    assert np.allclose(plain.hdr, hdr_from_scales(plain.ldr, plain.regions, plain.scales))
