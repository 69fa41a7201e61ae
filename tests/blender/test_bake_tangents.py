"""A bake of a glTF that carries its own TANGENT, with triangles degenerate in UV and sliver triangles (where
Blender's MikkTSpace writes zero tangents: ACCESSOR_VECTOR3_NON_UNIT without the mend): the output keeps
the input's tangents where its vertices are the input's and writes no zero-length tangent, so an input that
validates clean bakes clean (core.stages.bake.gltf_tangents)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from scenefit.core.data.glb import write_glb
from scenefit.core.stages.bake.gltf_tangents import GltfBuffers, tangents_repaired, usable_tangents

from conftest import scenefit_process

TILTED = np.array([np.cos(np.pi / 6), 0.0, np.sin(np.pi / 6), 1.0])   # not what MikkTSpace gives these UVs


def _png(rgb: tuple[int, int, int], size: int = 8) -> bytes:
    from PIL import Image

    pixels = np.zeros((size, size, 3), np.uint8) + np.array(rgb, np.uint8)
    pixels[: size // 2, : size // 2] = 255 - pixels[: size // 2, : size // 2]   # (some texture to bake)
    out = io.BytesIO()
    Image.fromarray(pixels).save(out, "PNG")
    return out.getvalue()


def tangent_asset(path: Path, degenerate_tangent=(1.0, 0.0, 0.0, 1.0)) -> None:
    """A 3x3 quad plane (+Y up, UVs across it, each vertex's TANGENT tilted 30 degrees from +U), beside it
    a quad whose four UVs are one point (both its triangles degenerate in UV) and a quad whose four corners
    lie on one line (both its triangles slivers: MikkTSpace gives them zero tangents), normal-mapped."""
    grid = [(x, z) for z in range(4) for x in range(4)]
    positions = [(x, 0.0, z) for x, z in grid] + [(4.0, 0.0, 0.0), (5.0, 0.0, 0.0), (5.0, 0.0, 1.0), (4.0, 0.0, 1.0)] \
        + [(4.0, 0.0, 2.0), (5.0, 0.0, 2.0), (6.0, 0.0, 2.0), (7.0, 0.0, 2.0)]
    uvs = [(x / 3, z / 3) for x, z in grid] + [(0.5, 0.5)] * 4 + [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    tangents = [TILTED] * 16 + [degenerate_tangent] * 8
    indices = []
    for z in range(3):
        for x in range(3):
            a, b, c, d = z * 4 + x, z * 4 + x + 1, (z + 1) * 4 + x + 1, (z + 1) * 4 + x
            indices += [a, d, c, a, c, b]   # counter-clockwise seen from +Y
    indices += [16, 19, 18, 16, 18, 17, 20, 23, 22, 20, 22, 21]
    arrays = [np.array(positions, "<f4"), np.array([(0.0, 1.0, 0.0)] * 24, "<f4"), np.array(uvs, "<f4"),
              np.array(tangents, "<f4"), np.array(indices, "<u2")]
    images = [_png((200, 120, 60)), _png((128, 128, 255))]
    blob, views = b"", []
    for data in [a.tobytes() for a in arrays] + images:
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob += data + b"\0" * (-len(data) % 4)
    for view in views[:4]:
        view["target"] = 34962
    views[4]["target"] = 34963
    kinds = [("VEC3", 5126), ("VEC3", 5126), ("VEC2", 5126), ("VEC4", 5126), ("SCALAR", 5123)]
    accessors = [{"bufferView": i, "componentType": c, "count": len(arrays[i]), "type": t}
                 for i, (t, c) in enumerate(kinds)]
    accessors[0].update(min=arrays[0].min(0).tolist(), max=arrays[0].max(0).tolist())
    write_glb(path, {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "plane"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TANGENT": 3},
                                    "indices": 4, "material": 0}]}],
        "materials": [{"name": "painted", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                                   "roughnessFactor": 0.6, "metallicFactor": 0.0},
                       "normalTexture": {"index": 1}}],
        "textures": [{"source": 0}, {"source": 1}],
        "images": [{"bufferView": 5, "mimeType": "image/png"}, {"bufferView": 6, "mimeType": "image/png"}],
        "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}]}, blob)


def _tangents(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    gltf = GltfBuffers(path)
    names = gltf.document["meshes"][0]["primitives"][0]["attributes"]
    return gltf.read(names["POSITION"]), gltf.read(names["NORMAL"]), gltf.read(names["TANGENT"])


def test_usable_tangents_are_unit_orthogonal_and_keep_what_is_usable():
    normals = np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0]], float)
    given = np.array([[0, 0, 0, 0], [2, 0, 0, -1], [0, 3, 0, 1], [np.nan, 0, 0, 1], TILTED], float)
    usable = usable_tangents(given, normals)
    assert np.allclose(np.linalg.norm(usable[:, :3], axis=1), 1) and set(usable[:, 3]) <= {-1.0, 1.0}
    assert np.allclose(np.sum(usable[:, :3] * normals, axis=1), 0)
    assert np.allclose(usable[1], [1, 0, 0, -1]) and np.allclose(usable[4], TILTED)   # usable ones stay
    assert usable[0, 3] == 1.0


def test_a_written_file_is_mended_in_place_and_takes_the_inputs_tangents(tmp_path):
    source, written = tmp_path / "in.glb", tmp_path / "out.glb"
    tangent_asset(source)
    tangent_asset(written, degenerate_tangent=(0.0, 0.0, 0.0, 1.0))   # as Blender's exporter writes them
    counts = tangents_repaired(written, source)
    positions, normals, tangents = _tangents(written)
    assert np.allclose(np.linalg.norm(tangents[:, :3], axis=1), 1)
    assert np.allclose(tangents[:16], TILTED) and counts["input_tangents_kept"] == 24
    other = tmp_path / "other.glb"
    tangent_asset(other, degenerate_tangent=(0.0, 0.0, 0.0, 1.0))
    assert tangents_repaired(other)["tangents_made_usable"] == 8


def test_a_bake_of_an_asset_with_its_own_tangents_and_degenerate_uvs_validates_clean(tmp_path, validator):
    asset = tmp_path / "plane.glb"
    tangent_asset(asset)
    before = validator(str(asset))["issues"]
    assert before["numErrors"] == 0, before["messages"][:5]
    proc = scenefit_process("convert", asset, "--out", tmp_path / "convert", "--preset", "draft",
                            "--resolution", "64", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = tmp_path / "baked.glb"
    proc = scenefit_process("bake", asset, "--texture", tmp_path / "convert" / "maps" / "texture.pt", "--out", out,
                            "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    after = validator(str(out))["issues"]
    codes = {m["code"] for m in after["messages"]}
    assert after["numErrors"] == 0 and "ACCESSOR_VECTOR3_NON_UNIT" not in codes, after["messages"][:5]
    positions, normals, tangents = _tangents(out)
    assert np.allclose(np.linalg.norm(tangents[:, :3], axis=1), 1, atol=1e-5)
    assert np.allclose(np.sum(tangents[:, :3] * normals, axis=1), 0, atol=1e-4)
    on_grid = positions[:, 0] <= 3.0 + 1e-6
    assert on_grid.sum() >= 16 and np.allclose(tangents[on_grid], TILTED, atol=1e-4)   # the input's, kept
