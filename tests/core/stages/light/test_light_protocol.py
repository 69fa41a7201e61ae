"""The field's sphere protocol (core/stages/light/measure.py) on maps with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from scenefit.core.stages.light.measure import (DIFFUSE_ALBEDO, SILVER_F0, probe_geometry, probe_scores, render_probe,
                                            rgb_angular_error_deg, si_rmse, stylelight_tonemap)
from scenefit.core.scene.frame import blender_direction_to_equirect_uv

FORWARD = np.array([0.0, 1.0, 0.0])


@pytest.mark.parametrize("material, factor", [("mirror", 1.0), ("matte", SILVER_F0), ("diffuse", DIFFUSE_ALBEDO)])
def test_a_constant_map_renders_constant_spheres(material, factor):
    env = np.full((32, 64, 3), 0.7, np.float32)
    image = render_probe(env, material, FORWARD, size=24)
    mask = probe_geometry(FORWARD, 24)[0]
    assert np.allclose(image[mask], 0.7 * factor, rtol=2e-3) and (image[~mask] == 0).all()


def _spot_map(direction: np.ndarray, h: int = 64) -> np.ndarray:
    env = np.full((h, 2 * h, 3), 0.01, np.float32)
    u, v = blender_direction_to_equirect_uv(direction[None])[0]
    env[min(int(v * h), h - 1), min(int(u * 2 * h), 2 * h - 1)] = 500.0
    return env


def test_a_light_behind_the_camera_lights_the_sphere_where_its_normal_faces_it():
    light = np.array([0.3, -0.9, 0.3]) / np.linalg.norm([0.3, -0.9, 0.3])   # behind the camera, right, up
    env = _spot_map(light)
    mask, normals, reflected = probe_geometry(FORWARD, 32)
    diffuse = render_probe(env, "diffuse", FORWARD, 32)[mask].mean(axis=-1)
    assert normals[int(np.argmax(diffuse))] @ light > 0.95
    mirror = render_probe(env, "mirror", FORWARD, 32)[mask].mean(axis=-1)
    assert reflected[int(np.argmax(mirror))] @ light > 0.98
    matte = render_probe(env, "matte", FORWARD, 32)[mask].mean(axis=-1)
    assert reflected[int(np.argmax(matte))] @ light > 0.95
    # The matte lobe spreads the light over more of the sphere than the mirror does.
    assert (matte > 0.1 * matte.max()).sum() > (mirror > 0.1 * mirror.max()).sum()


def test_scores_are_scale_invariant_where_they_say_so():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 2.0, size=(16, 16, 3)).astype(np.float32)
    mask = np.ones((16, 16), bool)
    scores = probe_scores(3.0 * truth, truth, mask)
    assert scores["linear"]["si_rmse"] == pytest.approx(0.0, abs=1e-6) and scores["linear"]["rmse"] > 1.0
    assert scores["linear"]["angular_deg"] == pytest.approx(0.0, abs=1e-3)
    assert si_rmse(truth * 0.5 + 0.3, truth) > 0.01 and rgb_angular_error_deg(truth[..., ::-1], truth) > 1.0
    # StyleLight's tone map puts the sphere's 99th percentile (after the 1/2.4 power) at 0.99.
    mapped = stylelight_tonemap(truth, mask)
    assert np.percentile(mapped[mask], 99) == pytest.approx(0.99, abs=0.01) and mapped.max() <= 1.0


def test_mean_radiance_weights_texels_by_their_solid_angle():
    from scenefit.core.stages.light.measure import mean_radiance
    from scenefit.core.scene.frame import equirect_directions

    assert mean_radiance(np.full((32, 64, 3), 0.7, np.float32)) == pytest.approx(0.7, rel=1e-6)
    # |z| averages to 1/2 over the sphere; an unweighted texel mean gives about 2/pi, the poles over-counted.
    z = np.abs(equirect_directions(256, 512)[..., 2])
    env = np.repeat(z[..., None], 3, axis=-1)
    assert mean_radiance(env) == pytest.approx(0.5, rel=1e-3)
    assert env.mean() == pytest.approx(2 / np.pi, rel=1e-2)
