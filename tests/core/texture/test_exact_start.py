"""The asset itself as the exact start: the texture is the asset's own maps plus a residual
that is exactly zero at the start, in logit space per channel; nothing is fitted, and adaptation
starts from the asset exactly."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.pipeline.preset_tables import texture_preset
from scenefit.core.stages.convert import EXACT_PSNR_DB, ConvertConfig, convert_asset
from scenefit.core.base.errors import InputError
from scenefit.core.stages.bake.game_bake import bake_game_maps
from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import normalize_to_unit_sphere
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.texture.surface_layout import texture_view
from scenefit.core.texture.bake import bake_maps, load_neural_texture
from scenefit.core.data.uv_raster import rasterize_uv


def asset_maps(size: int = 32) -> PBRMaps:
    rng = np.random.default_rng(3)
    base = rng.uniform(0.02, 0.98, (size, size, 3)).astype(np.float32)
    rough = rng.uniform(0.05, 1.0, (size, size)).astype(np.float32)
    metal = (rng.uniform(size=(size, size)) > 0.5).astype(np.float32)   # the extremes 0 and 1
    return PBRMaps(base, rough, metal)


def exact(mesh, maps, **kw):
    return convert_asset(mesh, maps, ConvertConfig(init_type="exact", texture=texture_preset("draft"), resolution=32, **kw))


def test_the_exact_start_is_the_asset_and_fits_nothing():
    mesh, maps = uv_sphere(0.5, 16, 8), asset_maps()
    result = exact(mesh, maps)
    assert result.iterations == 0 and result.history == [] and result.texture.residual_is_zero()
    got, want = result.predicted(), result.target
    covered = torch.from_numpy(result.raster.mask.copy())
    assert torch.allclose(got[covered], want[covered], atol=2e-6)   # metallic 0 and 1 included
    assert result.psnr == EXACT_PSNR_DB and result.decisions["start"] == "exact"


def test_the_residual_learns_on_top_of_the_base_and_the_base_stays():
    mesh, maps = uv_sphere(0.5, 16, 8), asset_maps()
    result = exact(mesh, maps)
    texture, raster = result.texture, result.raster
    plan = texture.plan(raster.position, raster.border, raster.fill_index)
    before = texture.base_logit.clone()
    optimizer = torch.optim.Adam(texture.parameters(), lr=0.05)
    for _ in range(5):   # push the base colour up everywhere
        optimizer.zero_grad()
        (-texture.texture_from_plan(plan)[..., 0:3].mean()).backward()
        optimizer.step()
    assert not texture.residual_is_zero()
    assert torch.equal(texture.base_logit, before)                 # a buffer, never optimised
    covered = torch.from_numpy(raster.mask.copy())
    with torch.no_grad():
        moved = texture.texture_from_plan(plan)[covered][:, 0:3] - result.target[covered][:, 0:3]
    assert float(moved.mean()) > 0.01


def test_an_exact_start_saves_loads_and_bakes_back_to_the_asset(tmp_path):
    mesh, maps = uv_sphere(0.5, 16, 8), asset_maps()
    result = exact(mesh, maps)
    outputs = bake_maps(result.texture, result.raster.position, result.raster.border, result.raster.fill_index,
                        tmp_path)
    again = load_neural_texture(outputs["weights"])
    assert again.config.residual and torch.equal(again.base_logit, result.texture.base_logit)
    np.testing.assert_allclose(texture_view(again, result.mesh).stack(again), result.predicted().numpy(), atol=1e-6)
    # The game bake at the texture's own size writes the asset's own base colour back (8-bit sRGB).
    (baked,) = bake_game_maps(again, mesh, ["Ball"], 32)
    want = np.round(linear_to_srgb(result.target[..., 0:3].numpy()) * 255)
    covered = result.raster.mask
    assert np.abs(baked.base_color[covered].astype(float) - want[covered]).max() <= 1.0


def test_a_residual_texture_is_only_evaluated_where_its_base_is_known():
    result = exact(uv_sphere(0.5, 16, 8), asset_maps())
    with pytest.raises(InputError, match="evaluated on texels"):
        result.texture(torch.zeros(4, 3))
    raster = result.raster
    with pytest.raises(InputError, match="base is"):   # a raster of another size needs its own base
        result.texture.texture(raster.position[:16, :16], raster.border[:16, :16], np.zeros(256, np.int64))


def test_roughness_below_the_renderers_floor_is_held_at_the_floor():
    """The one place the start is not the asset: roughness under 0.03 (a perfect mirror the GGX lobe
    cannot render) is held at 0.03, as every neural texture's range says."""
    maps = PBRMaps(np.full((32, 32, 3), 0.5, np.float32), np.zeros((32, 32), np.float32), 0.0)
    result = exact(uv_sphere(0.5, 16, 8), maps)
    covered = torch.from_numpy(result.raster.mask.copy())
    assert torch.allclose(result.predicted()[covered][:, 3], torch.tensor(0.03), atol=1e-6)


def test_asking_for_fitting_settings_asks_for_the_fit():
    """Every entry point (command line, operator, remote, batch overrides) reads `iterations` or a
    method as the paper's fit, and nothing of that kind as the exact start."""
    from scenefit.core.pipeline.presets import stage_config

    assert stage_config("convert", "draft").init_type == "exact"
    assert stage_config("convert", "draft", iterations=5).init_type == "fit"
    assert stage_config("convert", "draft", method_type="inverse").init_type == "fit"
    assert stage_config("convert", "draft", iterations=5, init_type="exact").init_type == "exact"


def test_a_non_square_image_bakes_at_its_own_shape():
    """A 128x32 strip bakes as a 128x32 image (it baked 128², four times the texels, stretched), texel
    for texel the asset's own when nothing is adapted; --max-texture halves both sides together."""
    from scenefit.core.stages.bake.game_bake import own_texture_shape

    rng = np.random.default_rng(5)
    strip = PBRMaps(rng.uniform(0.05, 0.95, (32, 128, 3)).astype(np.float32), 0.5, 0.0)
    assert own_texture_shape(strip, 4096) == (32, 128)
    assert own_texture_shape(strip, 64) == (16, 64)
    assert own_texture_shape(PBRMaps(np.zeros((30, 100, 3), np.float32), 0.5, 0.0), 4096) == (32, 128)
    assert own_texture_shape(PBRMaps(np.zeros((4, 4096, 3), np.float32), 0.5, 0.0), 256) == (4, 256)
    mesh = uv_sphere(0.5, 16, 8)
    result = exact(mesh, strip)
    (baked,) = bake_game_maps(result.texture, mesh, ["Strip"], [own_texture_shape(strip, 4096)], own_maps=[strip])
    assert baked.base_color.shape == (32, 128, 3) and baked.report()["width"] == 128
    covered = rasterize_uv(normalize_to_unit_sphere(mesh)[0], 32, 128).mask
    assert covered.mean() > 0.5
    want = np.round(linear_to_srgb(strip.base_color) * 255)
    assert np.abs(baked.base_color[covered].astype(float) - want[covered]).max() <= 1.0
    assert "base_color" in baked.unchanged
