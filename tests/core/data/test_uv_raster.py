"""The UV rasteriser on layouts real game assets have: UVs tiling past [0, 1] under each glTF wrap mode,
and every triangle spanning the whole UV square (memory bounded by the texture and mesh size)."""
from __future__ import annotations


import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.uv_raster import _barycentric, _nearest_covered, rasterize_uv, seam_fill_index

from conftest import printed_json

WRAPS = (("clamp", "clamp"), ("repeat", "repeat"), ("mirror", "mirror"), ("repeat", "mirror"), ("clamp", "repeat"))


def _wrapped(coord: np.ndarray, size: int, mode: str) -> np.ndarray:
    """Texel index of integer texel coordinates in the plane tiled with copies of the image."""
    if mode == "mirror":
        coord = coord % (2 * size)
        return np.where(coord < size, coord, 2 * size - 1 - coord)
    return coord % size


def _same_copy(near: np.ndarray, near_index: np.ndarray, index: np.ndarray, size: int, mode: str) -> np.ndarray:
    """The coordinate of texel `index` in the copy of the image where coordinate `near` (texel near_index) lies."""
    mirrored = (mode == "mirror") & (near // size % 2 == 1)
    return np.where(mirrored, near + near_index - index, near - near_index + index)


def brute_force_raster(mesh: Mesh, h: int, w: int, border_width: float = 2.0,
                       wrap: tuple[str, str] = ("clamp", "clamp")) -> dict[str, np.ndarray]:
    """What rasterize_uv computed before it worked in chunks, one triangle at a time over every texel
    centre of its bounding box (in the tiled plane where an axis repeats or mirrors): a texel belongs to
    the first triangle (in face order, then row by row) whose edge functions all reach one of its copies,
    the border ring to the triangle of its nearest covered texel. Arrays as in UVRaster."""
    faces = np.asarray(mesh.faces, np.int64)
    uv = np.asarray(mesh.uvs, np.float64)
    tri = np.stack((uv[:, 0] * w - 0.5, (1.0 - uv[:, 1]) * h - 0.5), axis=1)[faces]
    area2 = (tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1]) \
        - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0])
    owner = np.full(h * w, -1, np.int64)
    at = np.zeros((h * w, 2), np.int64)  # the covering copy's coordinates (x, y)
    for f in np.flatnonzero(np.abs(area2) > 1e-12):
        (x0, y0), (x1, y1) = np.ceil(tri[f].min(axis=0) - 1e-9), np.floor(tri[f].max(axis=0) + 1e-9)
        if wrap[0] == "clamp":
            x0, x1 = max(x0, 0), min(x1, w - 1)
        if wrap[1] == "clamp":
            y0, y1 = max(y0, 0), min(y1, h - 1)
        if x0 > x1 or y0 > y1:
            continue
        py, px = (a.ravel().astype(np.int64) for a in np.mgrid[y0:y1 + 1, x0:x1 + 1])
        weights = _barycentric(np.repeat(tri[f][None], px.size, 0), np.full(px.size, area2[f]), px, py)
        texel = _wrapped(py, h, wrap[1]) * w + _wrapped(px, w, wrap[0])
        hit = np.flatnonzero((weights >= -1e-9).all(axis=1))
        texel, first = np.unique(texel[hit], return_index=True)
        new = owner[texel] < 0
        owner[texel[new]], at[texel[new]] = f, np.stack((px, py), 1)[hit[first[new]]]
    point = np.zeros(len(faces), bool)  # a face holding no texel takes the one sampled at its UV centre, if free
    for f in np.setdiff1d(np.arange(len(faces)), owner[owner >= 0]):
        x, y = np.floor(tri[f].mean(axis=0) + 0.5).astype(np.int64)
        if (wrap[0] == "clamp" and not 0 <= x < w) or (wrap[1] == "clamp" and not 0 <= y < h):
            continue
        texel = _wrapped(y, h, wrap[1]) * w + _wrapped(x, w, wrap[0])
        if owner[texel] < 0:
            owner[texel], at[texel], point[f] = f, (x, y), True
    mask = owner >= 0
    distance, nearest = _nearest_covered(mask.reshape(h, w))
    ring = np.flatnonzero(~mask & (distance.reshape(-1) <= border_width))
    near = nearest[ring]
    owner[ring] = owner[near]
    at[ring, 0] = _same_copy(at[near, 0], near % w, ring % w, w, wrap[0])
    at[ring, 1] = _same_copy(at[near, 1], near // w, ring // w, h, wrap[1])
    border = owner >= 0
    held_as_point = point[owner[border]]
    weights = _barycentric(tri[owner[border]], np.where(held_as_point, 1.0, area2[owner[border]]), at[border, 0],
                           at[border, 1])
    weights[held_as_point] = 1.0 / 3.0
    weights = np.clip(weights, 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    corners = faces[owner[border]]
    out = {"mask": mask, "border": border, "face": owner.astype(np.int32), "barycentric": np.zeros((h * w, 3), np.float32)}
    out["barycentric"][border] = weights
    for name, values in (("position", mesh.positions), ("normal", mesh.normals)):
        point = np.einsum("kc,kcd->kd", weights, np.asarray(values, np.float64)[corners])
        out[name] = np.zeros((h * w, 3), np.float32)
        out[name][border] = point / np.linalg.norm(point, axis=1, keepdims=True) if name == "normal" else point
    out = {name: a.reshape(h, w, *a.shape[1:]) for name, a in out.items()}
    out["fill_index"] = seam_fill_index(out["border"])
    return out


def assert_same_raster(mesh: Mesh, h: int, w: int, wrap: tuple[str, str] = ("clamp", "clamp")) -> None:
    got, want = rasterize_uv(mesh, h, w, wrap=wrap), brute_force_raster(mesh, h, w, wrap=wrap)
    for name, expected in want.items():
        actual = getattr(got, name)
        assert actual.dtype == expected.dtype and np.array_equal(actual, expected), (name, wrap)


def test_in_range_uvs_rasterise_bit_for_bit_as_before():
    """A sphere (a seam down u = 0 = 1, slivers at the poles) and its UVs squeezed into a corner, so the
    border ring and the seam fill have work: every array matches the one-pass rasteriser exactly."""
    sphere = uv_sphere(segments=16, rings=9)
    squeezed = Mesh.from_arrays(sphere.positions, sphere.faces, sphere.uvs * 0.7 + 0.1, sphere.normals)
    for mesh, (h, w) in ((sphere, (40, 56)), (squeezed, (37, 29))):
        for wrap in WRAPS:  # UVs inside the image read it alike under every wrap mode
            assert_same_raster(mesh, h, w, wrap)
        assert_same_raster(mesh, h, w, "repeat")  # the default


def tiled_sphere() -> Mesh:
    """A sphere whose UVs tile: u over [-1.8, 3.6] (SheenChair's TEXCOORD_0 span), v over [-0.5, 1.5]."""
    sphere = uv_sphere(segments=20, rings=10)
    uvs = np.stack((sphere.uvs[:, 0] * 5.4 - 1.8, sphere.uvs[:, 1] * 2.0 - 0.5), axis=1)
    return Mesh.from_arrays(sphere.positions, sphere.faces, uvs, sphere.normals)


@pytest.mark.parametrize("wrap", WRAPS)
def test_tiling_uvs_rasterise_like_every_copy_brute_force(wrap):
    """UVs past [0, 1] cover the texels of their copy of the image: repeated, mirrored in odd copies,
    or (clamp) not at all; the chunked rasteriser agrees with the brute force bit for bit."""
    assert_same_raster(tiled_sphere(), 24, 30, wrap)


def test_tiling_uvs_are_covered_under_repeat_and_refused_in_one_sentence_when_clamped():
    mesh = tiled_sphere()
    assert rasterize_uv(mesh, 32).coverage == 1.0  # wrapped: the whole image is some part of the sphere
    shifted = Mesh.from_arrays(mesh.positions, mesh.faces, mesh.uvs * 0.1 + [3.02, -1.98], mesh.normals)
    moved = rasterize_uv(shifted, 64)  # an island of the tile (3, -2) textures the same texels as in (0, 0)
    home = rasterize_uv(Mesh.from_arrays(mesh.positions, mesh.faces, mesh.uvs * 0.1 + [0.02, 0.02], mesh.normals), 64)
    assert 0 < moved.coverage == home.coverage and np.array_equal(moved.face, home.face)
    np.testing.assert_allclose(moved.position, home.position, atol=1e-6)
    with pytest.raises(InputError, match=r"covers no texel centre at 64x64: .* lie outside \[0, 1\] where the "
                                         r"texture clamps; unwrap it"):
        rasterize_uv(shifted, 64, wrap="clamp")
    with pytest.raises(InputError, match="wrap mode must be one of repeat, mirror, clamp"):
        rasterize_uv(mesh, 8, wrap="MIRRORED_REPEAT")


def test_mirrored_copy_reads_the_image_backwards():
    """Under mirror, an island in the copy (1, 0) textures the texels of its reflection in u = 1."""
    sphere = uv_sphere(segments=12, rings=6)
    island = sphere.uvs * 0.4 + 0.05
    beyond = Mesh.from_arrays(sphere.positions, sphere.faces, island + [1.0, 0.0], sphere.normals)
    reflected = Mesh.from_arrays(sphere.positions, sphere.faces, np.stack((1.0 - island[:, 0], island[:, 1]), 1),
                                 sphere.normals)
    a, b = rasterize_uv(beyond, 40, wrap="mirror"), rasterize_uv(reflected, 40, wrap="mirror")
    assert a.coverage > 0.1 and np.array_equal(a.mask, b.mask) and np.array_equal(a.face, b.face)
    np.testing.assert_allclose(a.position, b.position, atol=1e-6)


@pytest.mark.parametrize("chunk", (3, 50))
def test_any_chunk_size_gives_the_same_raster(monkeypatch, chunk):
    """Spans longer than a chunk, triangles whose rows straddle chunks, texels held by a triangle of an
    earlier chunk: the result does not depend on how the work was cut."""
    import scenefit.core.data.uv_raster as uv_raster

    monkeypatch.setattr(uv_raster, "CHUNK", chunk)
    for wrap in (("clamp", "clamp"), ("mirror", "repeat")):
        assert_same_raster(tiled_sphere(), 18, 22, wrap)
        assert_same_raster(uv_sphere(segments=10, rings=5), 20, 16, wrap)


MEMORY = r"""
import json, resource, tracemalloc
import numpy as np
# A rasteriser that asks for what the UV layout rather than the texture and mesh sizes call for fails
# here at once instead of taking the machine's memory (the one-pass version needed 36 MiB per triangle).
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.uv_raster import rasterize_uv

n = TRIANGLES
rng = np.random.default_rng(0)
uvs = {"half": np.tile([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], (n, 1)),      # the same half, n times
       "quads": np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (n // 2, 1)),
       # the bottom edge and a corner anywhere along the top
       "fans": np.stack([np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n), rng.uniform(0, 1, n), np.ones(n)],
                        1).reshape(-1, 2)}
out = {}
for name, uv in uvs.items():
    mesh = Mesh.from_arrays(rng.normal(size=(3 * n, 3)), np.arange(3 * n).reshape(n, 3), uv)
    tracemalloc.start()
    raster = rasterize_uv(mesh, 512)
    out[name] = {"peak_mib": tracemalloc.get_traced_memory()[1] / 2 ** 20, "coverage": raster.coverage}
    tracemalloc.stop()
print("JSON" + json.dumps(out))
"""


def test_triangles_each_spanning_the_whole_square_stay_within_a_memory_bound(run_py):
    """4000 triangles whose UVs each span the whole square, at 512²: the one-pass rasteriser enumerated
    every texel of every triangle's box (4000 x 512² candidates, about 140 GiB); now the peak stays
    under 160 MiB (measured: about 75), a few times the raster's own arrays."""
    proc = run_py(MEMORY.replace("TRIANGLES", "4000"), timeout=300)
    out = printed_json(proc)
    for name, measured in out.items():
        assert measured["peak_mib"] < 160, (name, measured)
    assert out["half"]["coverage"] == pytest.approx(0.5, abs=0.01) and out["quads"]["coverage"] == 1.0
    assert out["fans"]["coverage"] > 0.9


def test_each_material_of_the_atlas_wraps_in_its_own_cell_as_bake_rasterises_it():
    """convert's atlas raster holds, in each material's cell, exactly what `scenefit bake` rasterises for
    that material in its own UVs (so the two agree), with face numbers of the whole mesh."""
    from scenefit.core.data.materials import atlas_mesh, atlas_raster, atlas_slices, material_submesh

    sphere = tiled_sphere()
    index = (sphere.positions[sphere.faces].mean(axis=1)[:, 2] > 0).astype(np.int32)  # upper half: material 1
    mesh = Mesh.from_arrays(sphere.positions, sphere.faces, sphere.uvs, sphere.normals, "two", index)
    wraps = [("repeat", "repeat"), ("mirror", "clamp")]
    atlas = atlas_raster(atlas_mesh(mesh), mesh, 2 * 20, wraps)
    assert atlas.mask.shape == (40, 40) and not atlas.position.flags.writeable
    for material, (rows, cols) in enumerate(atlas_slices(2, 20)):
        own = rasterize_uv(material_submesh(mesh, material), 20, wrap=wraps[material])
        assert own.coverage > 0.3 and np.array_equal(atlas.mask[rows, cols], own.mask)
        np.testing.assert_array_equal(atlas.position[rows, cols], own.position)
        faces, ids = atlas.face[rows, cols], np.flatnonzero(index == material)  # the submesh's faces in the mesh
        assert np.array_equal(faces[own.border], ids[own.face[own.border]]) and (faces[~own.border] == -1).all()
    assert not atlas.mask[20:].any()  # two materials: the bottom row of the 2x2 atlas is empty
