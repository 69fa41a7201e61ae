"""Several materials on one mesh (core only): the atlas used for fitting, and the per-material bake back
into the asset's own UV layout, on a sphere whose two hemispheres carry known colours."""
from __future__ import annotations

import numpy as np
import pytest

from scenefit.core.stages.convert import convert_materials
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.base.errors import InputError
from scenefit.core.stages.bake.game_bake import bake_game_maps
from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.materials import AssetMaterials, Material, atlas_mesh, material_submesh
from scenefit.core.data.mesh import Mesh, normalize_to_unit_sphere
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.data.primitives import uv_sphere

RED, BLUE = (0.8, 0.1, 0.05), (0.05, 0.2, 0.9)


def two_material_sphere() -> AssetMaterials:
    sphere = uv_sphere(segments=24, rings=12)
    centre_z = sphere.positions[sphere.faces].mean(axis=1)[:, 2]
    index = (centre_z < 0).astype(np.int32)  # 0: upper hemisphere, 1: lower
    mesh = Mesh.from_arrays(sphere.positions * 3.0 + 1.0, sphere.faces, sphere.uvs, sphere.normals, "two",
                            material_index=index)
    materials = tuple(Material(name=name, maps=PBRMaps(np.broadcast_to(np.float32(color), (32, 32, 3)).copy(),
                                                       roughness=rough, metallic=0.0))
                      for name, color, rough in (("Red", RED, 0.3), ("Blue", BLUE, 0.8)))
    return AssetMaterials(mesh=mesh, materials=materials)


def test_atlas_moves_each_material_into_its_cell_and_keeps_the_surface():
    asset = two_material_sphere()
    atlas = atlas_mesh(asset.mesh)
    for index, (u_range, v_range) in enumerate((((0.0, 0.5), (0.5, 1.0)), ((0.5, 1.0), (0.5, 1.0)))):
        uv = atlas.uvs[atlas.faces[atlas.material_index == index]].reshape(-1, 2)
        assert u_range[0] - 1e-6 <= uv[:, 0].min() and uv[:, 0].max() <= u_range[1] + 1e-6
        assert v_range[0] - 1e-6 <= uv[:, 1].min() and uv[:, 1].max() <= v_range[1] + 1e-6
    # Same triangles in space, face for face.
    np.testing.assert_array_equal(atlas.positions[atlas.faces], asset.mesh.positions[asset.mesh.faces])
    sub = material_submesh(asset.mesh, 1)
    assert len(sub.faces) == int((asset.mesh.material_index == 1).sum())
    with pytest.raises(InputError, match="uses 2 materials"):
        AssetMaterials(mesh=asset.mesh, materials=asset.materials[:1])


def test_one_texture_fits_both_materials_and_bakes_back_per_material():
    asset = two_material_sphere()
    result = convert_materials(asset, stage_config("convert", "draft", iterations=60))
    per = {m["name"]: m["psnr_db"] for m in result.decisions["materials"]}
    assert per["Red"] > 30.0 and per["Blue"] > 30.0, per
    assert result.decisions["resolution"] == 32 and result.raster.resolution == (64, 64)
    baked = bake_game_maps(result.texture, asset.mesh, ["Red", "Blue"], 32,
                           [{"roughness": 0.3, "metallic": 0.0}, {"roughness": 0.8, "metallic": 0.0}])
    normalized, _ = normalize_to_unit_sphere(asset.mesh)
    for index, (material, color, rough) in enumerate(zip(baked, (RED, BLUE), (0.3, 0.8))):
        mask = rasterize_uv(material_submesh(normalized, index), 32).mask  # the material's own UV layout
        assert 0.3 < mask.mean() < 0.7
        covered = material.base_color[mask]
        want = np.round(linear_to_srgb(np.array(color, np.float32)) * 255)
        # A 60-step draft fit is within ~15 sRGB steps (32 dB); the two colours are 150+ steps apart.
        assert np.abs(np.median(covered, axis=0) - want).max() <= 20, (material.name, np.median(covered, axis=0), want)
        # The asset's constants come back exactly (the fit's scatter around them is not a change).
        assert material.roughness == rough and material.metallic == 0.0
        assert material.report()["roughness"].startswith("factor")


def test_a_constant_channel_bakes_to_the_assets_value_unless_adaptation_moved_it():
    from scenefit.core.stages.bake.game_bake import CONSTANT_SCATTER, _channel

    rng = np.random.default_rng(0)
    mask = np.ones((16, 16), bool)
    fitted = (0.0033 + rng.normal(0, 0.005, (16, 16))).clip(0, 1).astype(np.float32)   # a draft fit of metallic 0
    assert _channel(fitted, mask, 0.0) == 0.0                       # the asset's own value, exactly
    assert isinstance(_channel(fitted, mask, None), np.ndarray)     # not a constant in the asset: a map
    assert _channel(np.full((16, 16), 0.5, np.float32), mask, None) == 0.5   # flat anyway: a value
    moved = np.full((16, 16), 0.7, np.float32)                      # adaptation made a 0.35 roughness 0.7
    assert _channel(moved, mask, 0.35) == pytest.approx(0.7)
    varied = rng.uniform(0, 1, (16, 16)).astype(np.float32)         # adaptation painted a pattern: a map
    assert float(varied.std()) > CONSTANT_SCATTER and isinstance(_channel(varied, mask, 0.5), np.ndarray)
