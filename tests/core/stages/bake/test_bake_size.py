"""A game asset out no larger than the one in: materials that share one texture, as a
palette or atlas does (Kenney's diorama: 44 materials, one colour map), bake to one shared image
again, not one copy per material (it grew 2.3x); a material of one plain colour stays a factor."""
from __future__ import annotations

import subprocess
import sys

import pytest

from scenefit.core.data.glb import read_gltf

pytestmark = pytest.mark.blender
from conftest import ROOT  # noqa: E402

BUILD = r"""
import bpy, numpy as np
from pathlib import Path
bpy.ops.wm.read_factory_settings(use_empty=True)
palette = bpy.data.images.new("colormap", 32, 32)
rgba = np.ones((32, 32, 4), np.float32)
rgba[..., :3] = np.random.default_rng(4).uniform(0.05, 0.95, (32, 32, 3)).round(2)
palette.pixels.foreach_set(rgba.ravel())
palette.filepath_raw = str(Path(FOLDER) / "colormap.png")
palette.file_format = "PNG"
palette.save()
for k in range(3):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.5 * k, 0.0, 0.5))
    obj = bpy.context.active_object
    uv = obj.data.uv_layers.active.data
    for loop in uv:                       # each block samples its own quarter of the palette
        loop.uv = (0.05 + 0.4 * (k % 2) + 0.4 * loop.uv[0], 0.05 + 0.4 * (k // 2) + 0.4 * loop.uv[1])
    mat = bpy.data.materials.new(f"block{k}")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = palette
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    obj.data.materials.append(mat)
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 2.0, 0.5))   # a plain colour, no texture
plain = bpy.data.materials.new("plain")
plain.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.2, 0.5, 0.8, 1.0)
bpy.context.active_object.data.materials.append(plain)
bpy.ops.export_scene.gltf(filepath=str(Path(FOLDER) / "with_plain.glb"), export_format="GLB")
"""


def scenefit(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


def test_materials_sharing_a_palette_bake_to_one_shared_image(run_py, tmp_path, validator):
    """One convert and one bake (a process each) of the three blocks with the plain cube beside them: the
    blocks' three materials share the palette, and the plain cube's material is one colour."""
    run_py(BUILD.replace("FOLDER", repr(str(tmp_path))))
    asset = tmp_path / "with_plain.glb"
    source = read_gltf(asset)[0]
    assert len(source["images"]) == 1 and len(source["materials"]) == 4
    proc = scenefit("convert", asset, "--out", tmp_path / "convert", "--preset", "draft", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = tmp_path / "baked.glb"
    proc = scenefit("bake", asset, "--texture", tmp_path / "convert" / "maps" / "texture.pt", "--out", out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    baked = read_gltf(out)[0]
    assert len(baked["materials"]) == 4 and len(baked["textures"]) >= 1
    assert len(baked["images"]) == 1, [image.get("name") for image in baked["images"]]
    assert out.stat().st_size <= 1.2 * asset.stat().st_size, (out.stat().st_size, asset.stat().st_size)
    assert validator(out)["issues"]["numErrors"] == 0

    # A material that gave a plain colour keeps it as a factor (to 8 bits), not an image of that colour.
    materials = {m["name"]: m["pbrMetallicRoughness"] for m in baked["materials"]}
    assert "baseColorTexture" not in materials["plain"]
    assert all("baseColorTexture" in materials[f"block{k}"] for k in range(3))
    assert materials["plain"]["baseColorFactor"] == [pytest.approx(v, abs=0.01) for v in (0.2, 0.5, 0.8, 1.0)]
