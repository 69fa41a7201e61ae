"""A multi-object asset file is one asset (issue 23): every mesh object with its world transform and
its own materials, in convert and bake alike; `--object` still takes one. Before, the object with
the most faces was taken silently (a bike's chain rather than the bike), and bake exported the whole
scene with only that object re-textured."""
from __future__ import annotations

import json
import struct
import subprocess
import sys

import pytest

pytestmark = pytest.mark.blender

BUILD = r"""
from pathlib import Path
import bpy, addon_utils
import sys
sys.path.insert(0, "tests")
from asset_builder import _image, _pattern, _rgba

folder = Path(FOLDER)
addon_utils.enable("io_scene_gltf2", default_set=False)
bpy.ops.wm.read_factory_settings(use_empty=True)

def textured(name, seed):
    mat = bpy.data.materials.new(name)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = _image(bpy, folder, name + "_base", _rgba(_pattern(32, seed)), "sRGB")
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    return mat

# A frame (many faces) and a wheel (few faces, turned upright by its node), each its own material.
bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.0)
frame = bpy.context.active_object
frame.name = "Frame"
frame.data.materials.append(textured("Paint", 1))
bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.6, depth=0.2, location=(2.0, 0, 0))
wheel = bpy.context.active_object
wheel.name = "Wheel"
wheel.rotation_euler = (1.5708, 0, 0)
bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.select_all(action="SELECT")
bpy.ops.uv.smart_project()
bpy.ops.object.mode_set(mode="OBJECT")
wheel.data.materials.append(textured("Rubber", 2))
bpy.ops.export_scene.gltf(filepath=str(folder / "bike.glb"), export_format="GLB")

# Convert the whole file, then --object one, in this process (as the game-asset tests do); bake
# runs as a process of its own (see blender_io.gltf_export.bake_asset_file).
from scenefit.cli import main
bpy.ops.wm.read_factory_settings(use_empty=True)   # the built materials gone: the file's own names come back
bike = str(folder / "bike.glb")
assert main(["convert", bike, "--out", str(folder / "convert"), "--preset", "draft", "--iterations", "20",
             "--resolution", "32", "--quiet"]) == 0
assert main(["convert", bike, "--object", "Wheel", "--out", str(folder / "wheel"), "--preset", "draft",
             "--iterations", "5", "--resolution", "16", "--quiet"]) == 0
"""


def glb_json(path) -> dict:
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    return json.loads(data[20:20 + length])


def scenefit(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True, timeout=900)


def test_a_multi_object_file_is_one_asset_in_convert_and_bake(tmp_path, run_py):
    run_py(BUILD.replace("FOLDER", repr(str(tmp_path))), timeout=600)
    bike = tmp_path / "bike.glb"
    report = json.loads((tmp_path / "convert" / "report.json").read_text())
    assert any("the whole scene: 2 mesh object(s)" in note and "Frame" in note and "Wheel" in note
               for note in report["notes"]), report.get("notes")
    assert [m["name"] for m in report["materials"]] == ["Paint", "Rubber"]
    baked = tmp_path / "baked.glb"
    done = scenefit("bake", str(bike), "--texture", str(tmp_path / "convert" / "maps" / "texture.pt"), "--out",
                    str(baked), "--report", str(tmp_path / "bake.json"), "--quiet")
    assert done.returncode == 0, done.stderr
    bake = json.loads((tmp_path / "bake.json").read_text())
    assert bake["objects"] == ["Frame", "Wheel"] and [m["name"] for m in bake["materials"]] == ["Paint", "Rubber"]
    document = glb_json(baked)
    names = {n.get("name") for n in document["nodes"]}
    assert {"Frame", "Wheel"} <= names
    # Both materials carry a newly baked base colour image (the wheel's was left as it was before).
    images = {document["images"][document["textures"][m["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
              ["source"]]["name"] for m in document["materials"]}
    assert all(name.startswith(("Paint", "Rubber")) and "base_color" in name for name in images), images
    # --object still takes one object.
    assert [m["name"] for m in json.loads((tmp_path / "wheel" / "report.json").read_text())["materials"]] == ["Rubber"]
