"""benchmarks/light_ceiling.py: the region scales fitted to a true map's diffuse sphere (the bench's
measure of what the paper's parametrisation can reach) recover known scales and match the light stage's
own composition of the map."""
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))

from light_ceiling import LOG_LIMIT, ceiling_map, fitted_scales, region_bases  # noqa: E402
from scenefit.core.data.imageio import linear_to_srgb  # noqa: E402
from scenefit.core.scene.frame import equirect_directions  # noqa: E402
from scenefit.core.stages.light.hdr import hdr_from_scales  # noqa: E402
from scenefit.core.stages.light.measure import probe_geometry, render_probe  # noqa: E402

H, W = 32, 64
FORWARD = np.array([1.0, 0.0, 0.0])   # the sphere is seen along +X: it shows the light from -X


def _panorama() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A grey LDR map (sRGB) with a warm lamp up behind the camera, a blue window low to its side
    and a region in front of the sphere (behind it, as seen), which no pixel of the sphere sees much of."""
    d = equirect_directions(H, W)
    linear = np.full((H, W, 3), 0.2, np.float32)
    regions = {"lamp": (d @ np.array([-0.6, 0.0, 0.8])) > 0.85,
               "window": (d @ np.array([-0.7, -0.7, -0.1])) > 0.85}
    linear[regions["lamp"]] = (0.9, 0.6, 0.3)
    linear[regions["window"]] = (0.3, 0.5, 0.9)
    return linear_to_srgb(linear), regions


def test_bases_compose_exactly_as_the_light_stage_does():
    ldr, regions = _panorama()
    scales = {"lamp": 7.5, "window": 0.3}
    rest, bases = region_bases(ldr, regions)
    np.testing.assert_allclose(ceiling_map(rest, bases, scales), hdr_from_scales(ldr, regions, scales), rtol=1e-5,
                               atol=1e-6)


@pytest.mark.parametrize("true", [{"lamp": 12.0, "window": 0.5}, {"lamp": 0.2, "window": 40.0}])
def test_fit_recovers_known_scales_from_the_cue_start(true):
    ldr, regions = _panorama()
    truth = hdr_from_scales(ldr, regions, true)
    rest, bases = region_bases(ldr, regions)
    fitted = fitted_scales(rest, bases, truth, FORWARD, start={"lamp": 1.0, "window": 1.0})
    for name, value in true.items():
        assert fitted[name] == pytest.approx(value, rel=0.02), (name, fitted)
    sphere = lambda env: render_probe(env, "diffuse", FORWARD)[probe_geometry(FORWARD)[0]]
    residual = sphere(ceiling_map(rest, bases, fitted)) - sphere(truth)
    assert np.sqrt(np.mean(residual ** 2)) < 1e-3 * np.sqrt(np.mean(sphere(truth) ** 2))


def test_a_region_the_sphere_cannot_see_stays_finite():
    """Light straight behind the sphere lights none of the pixels seen from the camera: its scale is not
    determined, and the fit keeps it within exp(+-LOG_LIMIT) rather than running off."""
    ldr, regions = _panorama()
    d = equirect_directions(H, W)
    regions["hidden"] = (d @ FORWARD) > 0.97
    truth = hdr_from_scales(ldr, regions, {"lamp": 3.0, "window": 1.0, "hidden": 1.0}) * 5.0   # unreachable
    rest, bases = region_bases(ldr, regions)
    fitted = fitted_scales(rest, bases, truth, FORWARD, start={})
    assert all(np.isfinite(v) and np.exp(-LOG_LIMIT) * 0.999 <= v <= np.exp(LOG_LIMIT) * 1.001 for v in fitted.values())
