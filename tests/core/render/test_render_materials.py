"""Several materials rendered as several Mitsuba shapes, each sampling its own maps with its own UVs and
its sampler's wrap mode, against the colour a glTF sampler reads at each hit."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.render.backend import init_mitsuba
from scenefit.core.data.materials import AssetMaterials
from scenefit.core.render.renderer import AssetRenderer
from material_scenes import TEXELS, albedo_and_position, banded_plane, expected_albedo











def rendered_by_renderer(asset: AssetMaterials):
    mesh, maps = asset.fitting_view()
    renderer = AssetRenderer(mesh, maps.resolution, np.ones((8, 16, 3), np.float32))
    stack = torch.from_numpy(maps.stacked())
    from scenefit.core.render.orbit_camera import Camera

    # A render sets the maps into the scene, which the AOV pass then reads.
    renderer.render(Camera(width=8, height=8), stack[..., :3], stack[..., 3:4], stack[..., 4:5],
                    torch.ones(8, 16, 3), spp=1)
    return renderer.scene


def rendered_by_compose(asset: AssetMaterials):
    import mitsuba as mi

    from scenefit.core.stages.compose import _scene

    mesh, maps = asset.fitting_view()
    return _scene(mi, np.ones((8, 16, 3), np.float32), mesh, maps.stacked(), black=False, floor_albedo=None)


@pytest.mark.parametrize("wraps", [
    [("repeat", "repeat"), ("mirror", "mirror"), ("clamp", "clamp")],
    [("mirror", "mirror"), ("repeat", "repeat")],
    [("repeat", "clamp"), ("clamp", "mirror"), ("mirror", "repeat")],   # per axis
], ids=["repeat-mirror-clamp", "mirror-repeat", "per-axis"])
@pytest.mark.parametrize("build", [rendered_by_renderer, rendered_by_compose], ids=["renderer", "compose"])
def test_each_material_reads_its_own_maps_with_its_own_wrap_mode(wraps, build):
    """UVs tiling to about 3 must read the material's own image wrapped as its sampler says: in an atlas
    they reached into the neighbouring material's cell, and every render repeated."""
    init_mitsuba()
    asset = banded_plane(wraps)
    albedo, position = albedo_and_position(build(asset))
    expected, clear = expected_albedo(asset, position)
    assert len(albedo) > 0.8 * 96 * 96 * 0.8 and clear.mean() > 0.95
    error = np.abs(albedo - expected).max(axis=1)[clear]
    # Mitsuba filters in float32; a lookup from another cell or wrapped otherwise is off by tenths.
    assert np.quantile(error, 0.999) < 2e-3, (np.quantile(error, [0.5, 0.9, 0.999]), error.max())


def test_one_material_renders_with_its_wrap_mode():
    init_mitsuba()
    asset = banded_plane([("mirror", "mirror")], seed=3)
    albedo, position = albedo_and_position(rendered_by_renderer(asset))
    expected, _ = expected_albedo(asset, position)
    assert np.quantile(np.abs(albedo - expected).max(axis=1), 0.999) < 2e-3


def test_gradients_reach_every_materials_texels_and_only_theirs():
    """An adapt-like step: the maps are one atlas tensor; each material's BSDF renders a slice of it, so the
    loss's gradient reaches every material's cell (through a mirrored-and-doubled one too) and no empty cell,
    and a step down it brings the render closer to the target."""
    from scenefit.core.render.orbit_camera import Camera
    from scenefit.core.data.materials import atlas_slices

    asset = banded_plane([("repeat", "repeat"), ("mirror", "repeat"), ("clamp", "clamp")], seed=5)
    mesh, maps = asset.fitting_view()
    renderer = AssetRenderer(mesh, maps.resolution, np.ones((8, 16, 3), np.float32))
    camera, env = Camera(azimuth_deg=0.0, elevation_deg=0.0, width=48, height=48), torch.ones(8, 16, 3)
    truth = torch.from_numpy(maps.stacked())
    with torch.no_grad():
        target = renderer.render(camera, truth[..., :3], truth[..., 3:4], truth[..., 4:5], env, spp=4, seed=1).rgb
    guess = torch.full_like(truth, 0.5).requires_grad_(True)

    def loss() -> torch.Tensor:
        out = renderer.render(camera, guess[..., :3], guess[..., 3:4], guess[..., 4:5], env, spp=4, seed=1)
        return ((out.rgb - target) ** 2).mean()

    before = loss()
    before.backward()
    grad = guess.grad.abs().sum(dim=-1)
    assert torch.isfinite(guess.grad).all()
    cells = atlas_slices(4, TEXELS)   # a 2 x 2 atlas: three materials and one empty cell
    for index, (rows, cols) in enumerate(cells):
        assert (grad[rows, cols].sum() > 0) == (index < 3), index
    for channel in range(5):   # base colour, roughness and metallic all receive gradients
        assert guess.grad[..., channel].abs().sum() > 0, channel
    with torch.no_grad():
        guess -= 0.05 * guess.grad / guess.grad.abs().max()   # each texel moves at most 0.05 down the gradient
        guess.clamp_(0.0, 1.0)
    guess.grad = None
    assert float(loss().detach()) < float(before.detach())
