"""A mesh whose material is its vertex colours (glTF COLOR_0) and that has no UV map converts: its
temporary copy is unwrapped and its colours are baked through the new UVs, so the base colour holds each
corner's colour as the triangle interpolates it, and the exact start converts at 100 dB."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.data.glb import write_glb
from scenefit.core.data.uv_raster import sample_image

from conftest import scenefit_process

CORNERS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TRIANGLES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
PALETTE = np.array([[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.1, 0.2, 0.9], [0.9, 0.8, 0.1]])


def corner_colour(face: int, corner: int) -> np.ndarray:
    return PALETTE[(face + corner) % 4]   # each face's three corners differ, and so does each face's mix


def vertex_colour_asset(path: Path) -> None:
    """A tetrahedron, flat-shaded, no UV map, its material white with COLOR_0 (linear, as glTF's)."""
    positions, normals, colours = [], [], []
    for face, triangle in enumerate(TRIANGLES):
        a, b, c = CORNERS[list(triangle)]
        normal = np.cross(b - a, c - a)
        for corner, index in enumerate(triangle):
            positions.append(CORNERS[index])
            normals.append(normal / np.linalg.norm(normal))
            colours.append(corner_colour(face, corner))
    arrays = [np.array(positions, "<f4"), np.array(normals, "<f4"), np.array(colours, "<f4"),
              np.arange(12, dtype="<u2")]
    blob, views = b"", []
    for array in arrays:
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes})
        blob += array.tobytes() + b"\0" * (-array.nbytes % 4)
    kinds = [("VEC3", 5126), ("VEC3", 5126), ("VEC3", 5126), ("SCALAR", 5123)]
    accessors = [{"bufferView": i, "componentType": c, "count": len(arrays[i]), "type": t}
                 for i, (t, c) in enumerate(kinds)]
    accessors[0].update(min=arrays[0].min(0).tolist(), max=arrays[0].max(0).tolist())
    write_glb(path, {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
                     "nodes": [{"mesh": 0, "name": "painted"}],
                     "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "COLOR_0": 2},
                                                 "indices": 3, "material": 0}]}],
                     "materials": [{"name": "vertex colours",
                                    "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.7}}],
                     "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}]}, blob)


def test_a_vertex_coloured_mesh_without_uvs_converts_with_each_corners_colour(tmp_path, validator):
    asset = tmp_path / "painted.glb"
    vertex_colour_asset(asset)
    assert validator(str(asset))["issues"]["numErrors"] == 0
    proc = scenefit_process("convert", asset, "--out", tmp_path / "convert", "--preset", "draft",
                            "--resolution", "64")
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads((tmp_path / "convert" / "report.json").read_text())
    assert "100.00 dB" in proc.stdout, proc.stdout[-1000:]
    mesh, maps = load_asset_folder(tmp_path / "convert" / "asset")
    assert np.ptp(mesh.uvs, axis=0).min() > 0.1   # a real layout, not every corner at (0, 0)
    gltf_positions = mesh.positions[:, [0, 2, 1]] * [1, 1, -1]   # Blender's Z up back to glTF's Y up
    weights = np.array([[1 / 3] * 3, [0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.2, 0.2, 0.6]])
    matched = set()
    for face in mesh.faces:
        corners = [int(np.argmin(np.linalg.norm(CORNERS - p, axis=1))) for p in gltf_positions[face]]
        source = next(i for i, t in enumerate(TRIANGLES) if set(t) == set(corners))
        matched.add(source)
        expected_corners = np.array([corner_colour(source, TRIANGLES[source].index(c)) for c in corners])
        seen = sample_image(maps.base_color, weights @ mesh.uvs[face], "clamp")
        assert np.abs(seen - weights @ expected_corners).max() < 0.03, (source, seen, weights @ expected_corners)
    assert matched == {0, 1, 2, 3}
    assert report["stage"] == "convert"
    # The game bake reads it as convert did (the same unwrap) and writes a file that validates clean.
    baked = tmp_path / "baked.glb"
    proc = scenefit_process("bake", asset, "--texture", tmp_path / "convert" / "maps" / "texture.pt", "--out", baked,
                            "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert validator(str(baked))["issues"]["numErrors"] == 0


def test_an_artists_vertex_coloured_mesh_gets_a_uv_map_at_their_word_and_then_converts(tmp_path, run_py):
    """In Blender the artist's mesh is theirs: Convert asks for a UV map rather than making one, Add UV Map
    (their click) makes it without moving a vertex, and Convert then holds each corner's colour."""
    asset = tmp_path / "painted.glb"
    vertex_colour_asset(asset)
    proc = run_py(f"""
        import json
        from pathlib import Path
        import bpy
        import addon_utils

        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        bpy.ops.import_scene.gltf(filepath={str(asset)!r})   # Blender's own importer, as an artist imports it
        obj = next(o for o in bpy.data.objects if o.type == "MESH")
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        bpy.context.scene.scenefit.preset = "draft"
        bpy.context.scene.scenefit.output_dir = {str(tmp_path / "runs")!r}
        shape = [tuple(v.co) for v in obj.data.vertices]
        out = {{"uvs_before": len(obj.data.uv_layers)}}
        try:
            bpy.ops.scenefit.convert()
            out["refused"] = ""
        except RuntimeError as error:
            out["refused"] = str(error).strip().splitlines()[-1]
        out["add"] = sorted(bpy.ops.scenefit.add_uv_map())
        out["uvs_after"] = [layer.name for layer in obj.data.uv_layers]
        out["shape_kept"] = shape == [tuple(v.co) for v in obj.data.vertices]
        out["again"] = bpy.ops.scenefit.add_uv_map.poll()
        out["convert"] = sorted(bpy.ops.scenefit.convert())
        run = obj.scenefit_asset.runs[len(obj.scenefit_asset.runs) - 1]
        report = json.loads((Path(bpy.path.abspath(run.folder)) / "report.json").read_text())   # a run's report
        out["psnr"] = report["stages"]["convert"]["report"]["psnr_covered_texels_db"]
        print("JSON" + json.dumps(out))
    """)
    from conftest import printed_json

    out = printed_json(proc)
    assert out["uvs_before"] == 0 and "no UV map" in out["refused"] and "Add UV Map" in out["refused"], out["refused"]
    assert out["add"] == ["FINISHED"] and out["uvs_after"] == ["SceneFit UV"] and out["shape_kept"]
    assert not out["again"]   # one map is enough: the button greys out
    assert out["convert"] == ["FINISHED"] and out["psnr"] > 40.0, out
