"""Adaptation in a new UV layout where the asset's UVs share texels: mirrored halves, tiling
and palettes are measured, xatlas makes the layout, the asset's own maps read through it as through
its own UVs, a learned residual differs per surface there, and the layout travels with texture.pt."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.pipeline.preset_tables import texture_preset
from scenefit.core.render.backend import init_mitsuba
from scenefit.core.stages.convert import ConvertConfig, convert_asset, convert_materials
from scenefit.core.base.errors import InputError
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import Mesh, normalize_to_unit_sphere
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.renderer import AssetRenderer
from scenefit.core.texture.surface_layout import (SHARED_LIMIT, adapting_view, new_layout, own_uvs_at, texture_view,
                                          uv_sharing)
from scenefit.core.texture.bake import load_neural_texture, save_neural_texture

from material_scenes import albedo_and_position, banded_plane, expected_albedo


def sphere() -> Mesh:
    return uv_sphere(0.5, 32, 16)


def mirrored(mesh: Mesh) -> Mesh:
    """The right half's UVs laid over the left half's, as symmetric game assets are unwrapped."""
    uv = mesh.uvs.copy()
    uv[:, 0] = np.abs(uv[:, 0] - 0.5) * 2.0
    return Mesh.from_arrays(mesh.positions, mesh.faces, uv, mesh.normals, "mirrored")


def smooth_maps(size: int = 64) -> PBRMaps:
    y, x = np.mgrid[0:size, 0:size] / size
    base = np.stack([0.2 + 0.6 * x, 0.2 + 0.6 * y, 0.5 + 0.3 * np.sin(6.0 * x)], axis=2).astype(np.float32)
    return PBRMaps(base, np.full((size, size), 0.6, np.float32), np.zeros((size, size), np.float32))


def test_sharing_is_measured_for_mirrors_repeats_and_palettes():
    plain = sphere()
    assert uv_sharing(plain).shared < 0.01
    half = uv_sharing(mirrored(plain))
    assert half.overlapped == pytest.approx(0.5, abs=0.03) and half.collapsed == 0.0
    repeated = uv_sharing(Mesh.from_arrays(plain.positions, plain.faces, plain.uvs * 3.0, plain.normals))
    assert repeated.overlapped == pytest.approx(1.0 - 1.0 / 9.0, abs=0.03)          # nine copies of the square
    palette = uv_sharing(Mesh.from_arrays(plain.positions, plain.faces, np.full_like(plain.uvs, 0.3)))
    assert palette.collapsed == 1.0 and palette.needs_new_layout()
    assert not uv_sharing(plain).needs_new_layout() and half.shared > SHARED_LIMIT


def test_an_exact_start_keeps_the_asset_uvs_and_a_shared_layout_gets_new_ones():
    plain = convert_asset(sphere(), smooth_maps(), ConvertConfig(texture=texture_preset("draft"), resolution=64))
    assert adapting_view(plain.texture, plain.mesh)[0] is None
    shared = convert_asset(mirrored(sphere()), smooth_maps(), ConvertConfig(texture=texture_preset("draft"), resolution=64))
    view, layout, report = adapting_view(shared.texture, shared.mesh)
    assert report["uv_layout"] == "new (xatlas)" and report["shared_surface"] > 0.4 and "xatlas" in report["why"]
    corners = view.mesh.uvs[view.mesh.faces]
    assert corners.min() >= 0.0 and corners.max() <= 1.0 and len(view.mesh.faces) == len(shared.mesh.faces)
    # The new layout gives every face its own texels: nothing overlaps any more.
    assert uv_sharing(view.mesh).shared < 0.02
    assert layout.corner_uvs.shape == (len(shared.mesh.faces), 3, 2)


def test_the_asset_reads_the_same_through_the_new_layout_as_through_its_own_uvs():
    """Three materials tiling about 3.8 times, each with its own wrap mode: the exact start read through
    xatlas's layout renders (albedo) what each material's own sampler reads at the same point."""
    init_mitsuba()
    asset = banded_plane([("repeat", "repeat"), ("mirror", "mirror"), ("clamp", "clamp")])
    result = convert_materials(asset, ConvertConfig(texture=texture_preset("draft"), resolution=128))
    mesh, _ = asset.fitting_view()
    layout = new_layout(normalize_to_unit_sphere(mesh)[0], result.texture.config.resolution, uv_sharing(mesh))
    view = texture_view(result.texture, mesh, layout)
    assert view.mesh is not mesh and not view.mesh.atlas
    stack = torch.from_numpy(view.stack(result.texture))
    renderer = AssetRenderer(view.mesh, tuple(stack.shape[:2]), np.ones((8, 16, 3), np.float32))
    from scenefit.core.render.orbit_camera import Camera

    renderer.render(Camera(width=8, height=8), stack[..., :3], stack[..., 3:4], stack[..., 4:5],
                    torch.ones(8, 16, 3), spp=1)
    albedo, position = albedo_and_position(renderer.scene)
    expected, clear = expected_albedo(asset, position)
    error = np.abs(albedo - expected).max(axis=1)[clear]
    assert len(error) > 5000
    # Read twice (the asset's 8x8 texels into the layout, then the layout by the renderer): a few
    # hundredths where the random texels change fastest; a flipped axis or another material's map is tenths.
    assert np.median(error) < 0.02 and np.quantile(error, 0.95) < 0.08, np.quantile(error, [0.5, 0.95, 0.99])


def test_a_learned_residual_differs_between_mirrored_halves_only_in_the_new_layout():
    result = convert_asset(mirrored(sphere()), smooth_maps(), ConvertConfig(texture=texture_preset("draft"), resolution=64))
    texture = result.texture
    with torch.no_grad():   # a residual that varies over the surface, as adaptation learns one
        generator = torch.Generator().manual_seed(0)
        texture.encoding.table.normal_(0.0, 1.0, generator=generator)
        texture.mlp[2].weight.normal_(0.0, 1.0, generator=generator)
    view, _, _ = adapting_view(texture, result.mesh)
    # Texels of the new layout on one half, and the texel nearest each one's mirror image (y -> -y: the
    # sphere's u -> 1 - u, which the mirrored UVs read as the same point).
    raster = view.raster
    texels = np.flatnonzero(raster.mask.ravel())
    points = raster.position.reshape(-1, 3)[texels]
    half = texels[points[:, 1] < -0.1][::7]
    mirror = raster.position.reshape(-1, 3)[half] * [1.0, -1.0, 1.0]
    partner = texels[np.argmin(((points[None, :, :] - mirror[:, None, :]) ** 2).sum(axis=2), axis=1)]
    assert len(half) > 50
    # Through the asset's own UVs both read the same texels (to the texel the partner search is off by),
    # so its asset's maps agree there; in the new layout each point has its own texel and its own residual.
    own_uv = own_uvs_at(raster, result.mesh).reshape(-1, 2)
    assert np.quantile(np.abs(own_uv[half] - own_uv[partner]).max(axis=1) * 64, 0.9) < 1.5
    read_base = torch.sigmoid(view.base_logit).numpy().reshape(-1, 5)
    assert np.abs(read_base[half, :3] - read_base[partner, :3]).mean() < 0.02
    read_new = view.stack(texture).reshape(-1, 5)
    assert np.abs(read_new[half, :3] - read_new[partner, :3]).mean() > 0.1


def test_the_layout_is_saved_with_the_texture_and_read_for_the_same_asset_only(tmp_path):
    mesh = mirrored(sphere())
    result = convert_asset(mesh, smooth_maps(), ConvertConfig(texture=texture_preset("draft"), resolution=64))
    view, layout, _ = adapting_view(result.texture, result.mesh)
    result.texture.layout = layout
    again = load_neural_texture(save_neural_texture(result.texture, tmp_path / "texture.pt"))
    np.testing.assert_array_equal(again.layout.corner_uvs, layout.corner_uvs)
    in_object_space = texture_view(again, mesh)          # compose reads the asset as it is, not normalised
    assert in_object_space.report["uv_layout"] == "new (xatlas)"
    np.testing.assert_allclose(in_object_space.mesh.positions, mesh.positions[mesh.faces].reshape(-1, 3))
    np.testing.assert_allclose(in_object_space.stack(again), view.stack(result.texture), atol=1e-6)
    with pytest.raises(InputError, match="another mesh"):
        texture_view(again, sphere())


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory):
    from conftest import shared_tiny_pair

    return shared_tiny_pair()


def test_adaptation_works_in_the_new_layout_and_saves_it(tiny_models, tmp_path):
    """adapt_and_bake on mirrored UVs: the report says why it re-mapped, the saved texture carries the
    layout, and maps/ stay in the asset's own UVs."""
    from scenefit.core.stages.adapt import AdaptConfig, StageSpec, adapt_and_bake
    from scenefit.core.guidance import ModelConfig
    from scenefit.core.scene.placement import Placement
    from scenefit.core.data.uv_raster import rasterize_uv

    mesh = mirrored(uv_sphere(0.5, 16, 8))
    texture = convert_asset(mesh, smooth_maps(32), ConvertConfig(texture=texture_preset("draft"), resolution=32)).texture
    base, inpaint = tiny_models
    config = AdaptConfig(prompt="a mossy sphere", iterations=3, model_resolution=32, views=4, views_per_step=1,
                         stages=(StageSpec(1.0, 16, 2, (30, 990)),), lr_texture=5e-2, views_type="local",
                         models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    result, report = adapt_and_bake(mesh, texture, config, tmp_path, photo=photo, placement=Placement((0.5, 0.6), 0.5))
    assert report["uv_layout"]["uv_layout"] == "new (xatlas)" and report["uv_layout"]["shared_surface"] > 0.4
    saved = load_neural_texture(report["outputs"]["weights"])
    assert saved.layout is not None and not saved.residual_is_zero() and texture.layout is None
    from scenefit.core.data.imageio import read_image

    own = rasterize_uv(normalize_to_unit_sphere(mesh)[0], 32)
    assert read_image(report["outputs"]["base_color"]).shape[:2] == own.resolution
    view = texture_view(saved, mesh)
    assert view.report["uv_layout"] == "new (xatlas)" and len(view.mesh.faces) == len(mesh.faces)


def test_an_unwrapper_that_fails_leaves_adaptation_in_the_asset_uvs_and_says_why(monkeypatch):
    import scenefit.core.texture.surface_layout as surface_layout

    def failing(*_, **__):
        raise RuntimeError("xatlas: no charts")

    monkeypatch.setattr(surface_layout, "new_layout", failing)
    shared = convert_asset(mirrored(sphere()), smooth_maps(), ConvertConfig(texture=texture_preset("draft"), resolution=64))
    view, layout, report = adapting_view(shared.texture, shared.mesh)
    assert view is None and layout is None and report["uv_layout"] == "own"
    assert "no new layout could be made (xatlas: no charts)" in report["why"] and report["shared_surface"] > 0.4
