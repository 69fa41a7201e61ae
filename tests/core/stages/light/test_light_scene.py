"""An unsure indoor/outdoor call is reported and handled as unsure: the map hedges between both."""
from __future__ import annotations

import numpy as np
import pytest

from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.depth import DepthConfig
from scenefit.core.stages.light.scene_type import SKY_RATIO_AT, UNSURE_HIGH, UNSURE_LOW, scene_type_cue, scene_type_words
from scenefit.core.pipeline.presets import stage_config


def _photo_at_score(score: float) -> np.ndarray:
    """Smooth (no corners), the top eighth SKY_RATIO_AT ** score times brighter than the bottom: that score."""
    linear = np.full((80, 64, 3), 0.08, np.float32)
    linear[:10] = 0.08 * SKY_RATIO_AT ** score
    return linear_to_srgb(linear)


def _config(scene: str = "auto"):
    return stage_config("light", "draft", scene_type=scene, critic_type="none", map_height=16,
                        depth=DepthConfig(depth_type="geometric"), outpaint={"completion_type": "prior"})


@pytest.mark.parametrize("score", [0.7, 1.0, 1.5])
def test_scores_near_the_threshold_are_unsure_and_the_map_is_the_mean_of_both(score):
    photo = _photo_at_score(score)
    cue = scene_type_cue(photo)
    assert cue["score"] == pytest.approx(score, abs=0.03) and cue["unsure"]
    result = estimate_light(photo, (32.0, 70.0), _config())
    decision = result.decisions["scene_type"]
    assert decision["unsure"] and "mean of the indoor and outdoor" in decision["note"]
    both = [estimate_light(photo, (32.0, 70.0), _config(kind)).hdr for kind in ("indoor", "outdoor")]
    assert not np.allclose(both[0], both[1])          # the hedge matters on this photo
    assert np.allclose(result.hdr, 0.5 * (both[0] + both[1]), rtol=1e-5, atol=1e-6)
    assert result.decisions["cues"]["confidence"] <= 0.5
    # What the command line and Blender say: both types, never the one the blend was not.
    assert scene_type_words(decision) == f"indoor or outdoor (unsure, score {cue['score']:.2f}; the map is their mean)"


@pytest.mark.parametrize("score", [0.0, 2.5])
def test_clear_calls_are_not_hedged(score):
    photo = _photo_at_score(score)
    assert not UNSURE_LOW <= scene_type_cue(photo)["score"] <= UNSURE_HIGH
    result = estimate_light(photo, (32.0, 70.0), _config())
    assert "unsure" not in result.decisions["scene_type"]
    kind = result.decisions["scene_type"]["chosen"]
    assert np.array_equal(result.hdr, estimate_light(photo, (32.0, 70.0), _config(kind)).hdr)
    assert scene_type_words(result.decisions["scene_type"]) == kind
