"""A plane in bands of materials, each with its own random texels, UVs and wrap mode, and the colour a glTF
sampler reads at each hit: known answers for the multi-material renderer tests."""
from __future__ import annotations

import numpy as np

from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.materials import AssetMaterials, Material
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.primitives import grid_plane

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
