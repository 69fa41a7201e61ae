"""Neural texture: UV rasteriser, hash grid, appearance model, direct fit, bake round trip."""
from __future__ import annotations

import dataclasses
import threading
from functools import partial

import numpy as np
import pytest
import torch

from scenefit.core.base.errors import Cancelled, InputError
from scenefit.core.data.imageio import linear_to_srgb, read_image
from scenefit.core.data.mesh import Mesh
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.texture.fit_direct import fit_direct
from scenefit.core.texture import (
    HashGrid3D,
    NeuralTexture,
    NeuralTextureConfig,
    bake_maps,
    load_neural_texture,
    masked_psnr,
)
from scenefit.core.data.uv_raster import rasterize_uv, seam_fill_index

SMALL = NeuralTextureConfig(resolution=64, n_levels=6, log2_table=14, base_resolution=4, finest_resolution=128, hidden=32)


# -- meshes built here -----------------------------------------------------------------------------

def plane(n: int = 8, uv_lo=(0.0, 0.0), uv_hi=(1.0, 1.0)) -> Mesh:
    """An n x n grid on z = 0.1, x in [-0.4, 0.4], y in [-0.3, 0.3]; UVs map the grid linearly."""
    s = np.linspace(0.0, 1.0, n + 1)
    gu, gv = np.meshgrid(s, s)
    positions = np.stack((-0.4 + 0.8 * gu, -0.3 + 0.6 * gv, np.full_like(gu, 0.1)), axis=-1).reshape(-1, 3)
    uvs = np.stack((uv_lo[0] + (uv_hi[0] - uv_lo[0]) * gu, uv_lo[1] + (uv_hi[1] - uv_lo[1]) * gv), -1).reshape(-1, 2)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate((np.stack((a, b, c), 1), np.stack((a, c, d), 1)))
    normals = np.tile([0.0, 0.0, 1.0], (len(positions), 1))
    return Mesh.from_arrays(positions, faces, uvs, normals)


def cube() -> Mesh:
    """A unit cube (side 0.7) with each face its own UV island in a 3 x 2 atlas (seams everywhere)."""
    positions, uvs, faces = [], [], []
    axes = [(0, 1, 2, 1), (0, 1, 2, -1), (1, 2, 0, 1), (1, 2, 0, -1), (2, 0, 1, 1), (2, 0, 1, -1)]
    for k, (i, j, n, sign) in enumerate(axes):
        col, row = k % 3, k // 3
        for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
            p = np.zeros(3)
            p[i], p[j], p[n] = (du - 0.5) * 0.7, (dv - 0.5) * 0.7, sign * 0.35
            positions.append(p)
            # Islands inset by 0.12 so there is background (several texels at 64^2) between them.
            uvs.append(((col + 0.12 + 0.76 * du) / 3.0, (row + 0.12 + 0.76 * dv) / 2.0))
        base = 4 * k
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return Mesh.from_arrays(np.array(positions), np.array(faces), np.array(uvs))


def smooth_target(position: np.ndarray) -> np.ndarray:
    """(H, W, 5) linear maps that vary smoothly with 3D position."""
    x, y, z = position[..., 0], position[..., 1], position[..., 2]
    rgb = np.stack((0.5 + 0.4 * np.sin(6 * x + 1), 0.5 + 0.4 * np.cos(5 * y - 2 * z), 0.5 + 0.3 * np.sin(4 * (x + z))), -1)
    rough = 0.5 + 0.3 * np.cos(7 * y + 3 * x)
    metal = 0.5 + 0.4 * np.sin(5 * z - 4 * y)
    return np.concatenate((rgb ** 2.2, rough[..., None], metal[..., None]), axis=-1).astype(np.float32)


# -- UV rasteriser --------------------------------------------------------------------------------

def test_single_quad_gives_exact_positions_and_image_orientation():
    mesh = Mesh.from_arrays([[0, 0, 3], [2, 0, 3], [2, 1, 3], [0, 1, 3]], [[0, 1, 2], [0, 2, 3]],
                            [[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 0, 1]] * 4)
    r = rasterize_uv(mesh, 8, 4)
    assert r.mask.all() and r.border.all()
    j, i = np.meshgrid(np.arange(4), np.arange(8))
    u, v = (j + 0.5) / 4, 1.0 - (i + 0.5) / 8  # row 0 is the top of the image, v near 1
    np.testing.assert_allclose(r.position[..., 0], 2 * u, atol=1e-6)
    np.testing.assert_allclose(r.position[..., 1], v, atol=1e-6)
    np.testing.assert_allclose(r.position[..., 2], 3.0, atol=1e-6)
    np.testing.assert_allclose(r.normal, np.broadcast_to([0, 0, 1], r.normal.shape), atol=1e-6)
    np.testing.assert_allclose(r.barycentric.sum(-1), 1.0, atol=1e-6)
    assert (r.face >= 0).all()


def test_mask_area_matches_uv_triangle_area():
    h, w = 200, 160
    uv = np.array([[0.1, 0.15], [0.83, 0.3], [0.35, 0.9]])
    mesh = Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv)
    r = rasterize_uv(mesh, h, w, border_width=2.0)
    area = 0.5 * abs(np.cross(uv[1] - uv[0], uv[2] - uv[0])) * h * w
    perimeter = sum(np.linalg.norm((uv[(k + 1) % 3] - uv[k]) * [w, h]) for k in range(3))
    assert abs(r.mask.sum() - area) < 0.5 * perimeter  # within half a texel along the edges
    # The border ring extends coverage by about border_width texels all round, and holds points on the triangle.
    assert r.mask.sum() + 1.0 * perimeter < r.border.sum() < r.mask.sum() + 3.0 * perimeter
    ring = r.border & ~r.mask
    p = r.position[ring]
    assert (p >= -1e-6).all() and (p.sum(axis=1) <= 1 + 1e-6).all() and np.allclose(p[:, 2], 0)
    assert not r.border[0, 0] and r.face[0, 0] == -1


def test_seam_fill_index_points_at_nearest_covered_texel():
    mask = np.zeros((6, 7), dtype=bool)
    mask[1, 1] = mask[4, 5] = True
    fill = seam_fill_index(mask)
    assert fill.shape == (42,) and fill.dtype == np.int64
    assert mask.reshape(-1)[fill].all()
    assert fill[1 * 7 + 1] == 8 and fill[4 * 7 + 5] == 33  # covered texels point at themselves
    assert fill[0] == 8 and fill[5 * 7 + 6] == 33
    with pytest.raises(InputError):
        seam_fill_index(np.zeros((4, 4), dtype=bool))


def test_a_triangle_collapsed_in_uv_holds_the_texel_it_samples():
    """A palette face (UVs collapsed to a point) was refused "no UV area"; it samples one texel,
    the one under its UV point, at its centre."""
    flat = Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], [[0.5, 0.5]] * 3)
    raster = rasterize_uv(flat, 32)
    assert np.array_equal(np.argwhere(raster.mask), [[16, 16]]) and raster.face[16, 16] == 0
    np.testing.assert_allclose(raster.position[16, 16], [1 / 3, 1 / 3, 0], atol=1e-6)
    assert raster.border.sum() > 1  # the seam border around it reads the same face (bilinear lookups)


# -- hash grid and network ------------------------------------------------------------------------

def test_hash_grid_shape_levels_and_determinism():
    grid = HashGrid3D(n_levels=8, n_features=2, log2_table=12, base_resolution=4, finest_resolution=256)
    assert grid.resolutions[0] == 4 and grid.resolutions[-1] == 256
    assert grid.n_dense >= 1 and grid.n_dense < 8  # coarse levels dense, fine ones hashed
    assert grid.table.abs().max() <= 1e-4
    x = torch.rand(100, 3, generator=torch.Generator().manual_seed(1))
    a, b = grid(x), grid(x)
    assert a.shape == (100, 16) and torch.equal(a, b)
    # The planned (sparse matrix) path computes the same encoding as the gather path.
    torch.testing.assert_close(grid.forward_planned(grid.plan(x)), a, rtol=1e-5, atol=1e-9)
    c = HashGrid3D(n_levels=8, n_features=2, log2_table=12, base_resolution=4, finest_resolution=256)
    c.load_state_dict(grid.state_dict())
    assert torch.equal(c(x), a)


def test_hash_grid_interpolates_trilinearly_inside_a_cell():
    grid = HashGrid3D(n_levels=1, n_features=1, log2_table=12, base_resolution=4, finest_resolution=4)
    with torch.no_grad():  # dense level: table row = x + 5 y + 25 z; make features a linear function
        k = torch.arange(125)
        grid.table[:, 0] = (k % 5 + 2 * ((k // 5) % 5) - 3 * (k // 25)).float()
    x = torch.tensor([[0.3, 0.55, 0.9], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    expected = 4 * (x[:, 0] + 2 * x[:, 1] - 3 * x[:, 2])
    torch.testing.assert_close(grid(x)[:, 0], expected, rtol=1e-5, atol=1e-5)


def test_gradients_reach_mlp_and_hash_grid_and_are_finite():
    r = rasterize_uv(plane(), 64)
    texture = NeuralTexture(SMALL, seed=0)
    maps = texture.texture(r.position, r.border, r.fill_index)
    assert maps.shape == (64, 64, 5)
    target = torch.from_numpy(smooth_target(r.position))
    ((maps - target) ** 2).mean().backward()
    for name, param in texture.named_parameters():
        assert param.grad is not None, name
        assert torch.isfinite(param.grad).all(), name
        assert param.grad.abs().sum() > 0, name
    assert {n for n, _ in texture.named_parameters()} == {"encoding.table", "mlp.0.weight", "mlp.2.weight"}


def test_outputs_stay_in_channel_ranges_and_mlp_has_no_bias():
    config = dataclasses.replace(SMALL, base_color_range=(0.1, 0.6), roughness_range=(0.2, 0.9), metallic_range=(0.0, 0.5))
    texture = NeuralTexture(config)
    with torch.no_grad():
        for p in texture.parameters():
            p.mul_(0).add_(torch.randn_like(p) * 50)  # saturate the sigmoid both ways
        out = texture(torch.rand(4000, 3) - 0.5)
    lo, hi = torch.tensor(config.channel_min), torch.tensor(config.channel_max)
    assert (out >= lo - 1e-6).all() and (out <= hi + 1e-6).all()
    assert (out.min(0).values < lo + 0.05).all() and (out.max(0).values > hi - 0.05).all()
    assert all(m.bias is None for m in texture.mlp if isinstance(m, torch.nn.Linear))


def test_same_seed_same_network():
    x = torch.rand(50, 3) - 0.5
    assert torch.equal(NeuralTexture(SMALL, seed=3)(x), NeuralTexture(SMALL, seed=3)(x))
    assert not torch.equal(NeuralTexture(SMALL, seed=3).mlp[0].weight, NeuralTexture(SMALL, seed=4).mlp[0].weight)


def test_texture_dilates_past_seams():
    r = rasterize_uv(cube(), 96)
    assert 0.5 < r.coverage < 0.98 and (~r.border).any()
    texture = NeuralTexture(SMALL)
    with torch.no_grad():
        maps = texture.texture(r.position, r.border, r.fill_index).numpy()
    flat = maps.reshape(-1, 5)
    np.testing.assert_array_equal(flat, flat[r.fill_index])  # every texel copies its nearest evaluated one
    assert np.isfinite(maps).all()


@pytest.mark.parametrize("change, message", [
    ({"n_levels": 0}, "n_levels"),
    ({"log2_table": 40}, "log2_table"),
    ({"finest_resolution": 8, "base_resolution": 16}, "finest_resolution"),
    ({"roughness_range": (0.5, 0.2)}, "roughness_range"),
    ({"base_color_range": (0.0, 1.5)}, "base_color_range"),
    ({"hidden": 2.5}, "hidden"),
    ({"resolution": 0}, "resolution"),
])
def test_config_validation(change, message):
    with pytest.raises(InputError, match=message):
        NeuralTextureConfig(**change)


def test_presets_and_config_round_trip():
    preset = partial(stage_config, "texture")
    assert preset("final") == NeuralTextureConfig()
    assert preset("draft").n_levels < preset("balanced").n_levels < preset("final").n_levels
    assert preset("balanced", resolution=256).resolution == 256
    with pytest.raises(InputError, match="preset"):
        preset("ultra")
    with pytest.raises(InputError, match="stage"):
        stage_config("bake", "final")
    config = preset("balanced")
    assert NeuralTextureConfig.from_dict(config.to_dict()) == config


# -- direct fit -----------------------------------------------------------------------------------

def test_fit_direct_reaches_high_psnr_on_a_smooth_texture():
    r = rasterize_uv(cube(), 64)
    target = smooth_target(r.position)
    texture = NeuralTexture(SMALL, seed=0)
    seen = []
    result = fit_direct(texture, r.position, r.mask, target, iterations=120, progress=lambda *a: seen.append(a))
    assert len(seen) == result.iterations == 120 and len(result.psnr_history) == 120
    assert result.psnr_history[0] < 20.0
    assert result.final_psnr > 33.0, result.final_psnr
    with torch.no_grad():
        maps = texture.texture(r.position, r.border, r.fill_index)
    assert masked_psnr(maps, target, r.mask) == pytest.approx(result.final_psnr, abs=0.05)


def test_fit_direct_with_batches_stop_and_cancel():
    r = rasterize_uv(plane(), 48)
    target = smooth_target(r.position)
    texture = NeuralTexture(SMALL, seed=1)
    result = fit_direct(texture, r.position, r.mask, target, iterations=200, batch_texels=700, seed=0)
    assert result.final_psnr > 30.0
    stopped = fit_direct(NeuralTexture(SMALL), r.position, r.mask, target, iterations=500, stop_at_psnr=25.0)
    assert stopped.iterations < 500 and stopped.psnr_history[-1] >= 25.0
    cancel = threading.Event()
    with pytest.raises(Cancelled):
        fit_direct(NeuralTexture(SMALL), r.position, r.mask, target, iterations=50,
                   progress=lambda it, *_: cancel.set() if it == 2 else None, cancel=cancel)
    with pytest.raises(InputError, match="target"):
        fit_direct(texture, r.position, r.mask, target[:10], iterations=1)


def test_masked_psnr_uses_srgb_base_colour_and_mask():
    target = np.full((4, 4, 5), 0.5, dtype=np.float32)
    pred = target.copy()
    pred[..., 3] += 0.1  # roughness off by 0.1 everywhere: MSE 0.01 / 5 channels
    mask = np.ones((4, 4), dtype=bool)
    assert masked_psnr(pred, target, mask) == pytest.approx(10 * np.log10(5 / 0.01), abs=1e-3)
    pred[0, 0] = 0.0  # outside the mask: ignored
    mask[0, 0] = False
    assert masked_psnr(pred, target, mask) == pytest.approx(10 * np.log10(5 / 0.01), abs=1e-3)
    dark = np.zeros((1, 1, 5), dtype=np.float32)
    darker = dark.copy()
    darker[..., :3] = 0.001  # tiny in linear, larger once sRGB-encoded (12.92x)
    assert masked_psnr(darker, dark, np.ones((1, 1), bool)) == pytest.approx(-10 * np.log10(0.6 * 0.01292**2), abs=1e-2)


# -- bake -----------------------------------------------------------------------------------------

def test_bake_round_trip_within_one_level(tmp_path):
    r = rasterize_uv(cube(), 64)
    texture = NeuralTexture(SMALL, seed=2)
    fit_direct(texture, r.position, r.mask, smooth_target(r.position), iterations=20)
    paths = bake_maps(texture, r.position, r.border, r.fill_index, tmp_path / "maps")
    assert {k: p.name for k, p in paths.items()} == {
        "base_color": "base_color.png", "roughness": "roughness.png", "metallic": "metallic.png", "weights": "texture.pt"}
    with torch.no_grad():
        maps = texture.texture(r.position, r.border, r.fill_index).numpy()
    base = read_image(paths["base_color"])
    assert base.shape == (64, 64, 3)
    assert np.abs(base - linear_to_srgb(maps[..., :3])).max() <= 1 / 255
    for k, name in ((3, "roughness"), (4, "metallic")):
        plane_ = read_image(paths[name])
        assert plane_.shape == (64, 64, 1)
        assert np.abs(plane_[..., 0] - maps[..., k]).max() <= 1 / 255
    assert not list((tmp_path / "maps").glob(".*"))  # no temp files left behind

    resumed = load_neural_texture(paths["weights"])
    assert resumed.config == texture.config
    with torch.no_grad():
        again = resumed.texture(r.position, r.border, r.fill_index).numpy()
    np.testing.assert_array_equal(again, maps)


def test_load_rejects_foreign_files(tmp_path):
    bad = tmp_path / "texture.pt"
    torch.save({"something": 1}, bad)
    with pytest.raises(InputError, match="not a SceneFit"):
        load_neural_texture(bad)
    with pytest.raises(InputError, match="No neural texture"):
        load_neural_texture(tmp_path / "missing.pt")
