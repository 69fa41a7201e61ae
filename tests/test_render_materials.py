"""Several materials rendered as several Mitsuba shapes, each sampling its own maps with its own UVs and
its sampler's wrap mode (issues 20 and 23), against the colour a glTF sampler reads at each hit."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.render.backend import init_mitsuba
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.materials import AssetMaterials, Material
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.primitives import grid_plane
from scenefit.core.render.renderer import AssetRenderer

TEXELS = 8                      # each material's own base colour is TEXELS² random colours
UV_SCALE, UV_OFFSET = 3.8, -0.9  # own UVs run from -0.9 to 2.9 across the plane: tiles in both directions
BANDS = 3                       # the plane's columns of faces, left to right, are materials 0, 1, 2


def sample(texture: np.ndarray, uv: np.ndarray, wrap: tuple[str, str]) -> np.ndarray:
    """Bilinear lookup as a glTF sampler reads `texture` (rows top first) at OpenGL UVs: texel centres at
    (j + 0.5) / W and v = 1 - (i + 0.5) / H, neighbours wrapped per axis (REPEAT, MIRRORED_REPEAT,
    CLAMP_TO_EDGE)."""
    h, w = texture.shape[:2]

    def index(i: np.ndarray, n: int, mode: str) -> np.ndarray:
        if mode == "repeat":
            return np.mod(i, n)
        if mode == "mirror":
            m = np.mod(i, 2 * n)
            return np.where(m < n, m, 2 * n - 1 - m)
        return np.clip(i, 0, n - 1)

    x, y = uv[:, 0] * w - 0.5, (1.0 - uv[:, 1]) * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    cols = [index(x0, w, wrap[0]), index(x0 + 1, w, wrap[0])]
    rows = [index(y0, h, wrap[1]), index(y0 + 1, h, wrap[1])]
    return ((1 - fy) * ((1 - fx) * texture[rows[0], cols[0]] + fx * texture[rows[0], cols[1]])
            + fy * ((1 - fx) * texture[rows[1], cols[0]] + fx * texture[rows[1], cols[1]]))


def banded_plane(wraps: list[tuple[str, str]], seed: int = 0) -> AssetMaterials:
    """A square (x, z in [-0.5, 0.5], facing -Y) cut into BANDS columns of materials with `wraps`, every
    material's own UVs the same affine function of the position, tiling past [0, 1]."""
    plane = grid_plane(size=1.0, divisions=4 * BANDS)
    centre_x = plane.positions[plane.faces].mean(axis=1)[:, 0]
    index = np.minimum(((centre_x + 0.5) * BANDS).astype(np.int32), BANDS - 1) % len(wraps)
    uv = (plane.positions[:, [0, 2]] + 0.5) * UV_SCALE + UV_OFFSET
    mesh = Mesh.from_arrays(plane.positions, plane.faces, uv, plane.normals, "bands", index)
    rng = np.random.default_rng(seed)
    materials = tuple(Material(name=f"m{i}", maps=PBRMaps(rng.uniform(0.05, 0.95, (TEXELS, TEXELS, 3)).astype(np.float32),
                                                          roughness=0.5, metallic=0.0), wrap=wrap)
                      for i, wrap in enumerate(wraps))
    return AssetMaterials(mesh=mesh, materials=materials)


def albedo_and_position(scene, size: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """One sample per pixel of the scene's base colour (the albedo AOV) and the point it hit, seen head on."""
    import mitsuba as mi

    sensor = mi.load_dict({"type": "perspective", "fov": 24.0, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, -2.5, 0], target=[0, 0, 0], up=[0, 0, 1]),
                           "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgba",
                                    "rfilter": {"type": "box"}}, "sampler": {"type": "independent"}})
    integrator = mi.load_dict({"type": "aov", "aovs": "albedo:albedo,p:position,d:depth"})
    image = np.array(mi.render(scene, sensor=sensor, integrator=integrator, spp=1), dtype=np.float64)
    hit = image[..., 6] > 0
    return image[..., 0:3][hit], image[..., 3:6][hit]


def expected_albedo(asset: AssetMaterials, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What each material's own sampler reads at each hit point, and which hits lie clear of the bands'
    borders (a hit on a border may be either material's)."""
    x = position[:, 0] + 0.5
    band = np.minimum((x * BANDS).astype(np.int64), BANDS - 1)
    clear = np.abs(x * BANDS - np.round(x * BANDS)) > 1e-3
    uv = (position[:, [0, 2]] + 0.5) * UV_SCALE + UV_OFFSET
    out = np.zeros_like(position)
    for i, material in enumerate(asset.materials):
        own = band % len(asset.materials) == i
        out[own] = sample(material.maps.base_color, uv[own], material.wrap)
    return out, clear


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
