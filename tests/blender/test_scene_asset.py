"""A multi-object asset file is one asset: every mesh object with its world transform and
its own materials, in convert and bake alike; `--object` takes one object, or a node with the meshes
under it, never the object with the most faces alone (a bike's chain rather than the bike), and bake
never exports the whole scene with only that object re-textured."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from scenefit.core.data.glb import read_gltf

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
# Frame and wheel under one node (an empty, raised by 0.5), and a sign beside them that is not the bike.
bpy.ops.object.empty_add(location=(0, 0, 0.5))
node = bpy.context.active_object
node.name = "Bike"
frame.parent = wheel.parent = node
bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 3.0, 0))
sign = bpy.context.active_object
sign.name = "Sign"
sign.data.materials.append(textured("Board", 3))
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
assert main(["convert", bike, "--object", "Bike", "--out", str(folder / "bike"), "--preset", "draft",
             "--iterations", "5", "--resolution", "16", "--quiet"]) == 0
assert main(["convert", bike, "--object", "Bicycle", "--out", str(folder / "none"), "--quiet"]) == 2
"""


def scenefit(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True, timeout=900)


def test_a_multi_object_file_is_one_asset_in_convert_and_bake(tmp_path, run_py):
    said = run_py(BUILD.replace("FOLDER", repr(str(tmp_path))), timeout=600).stderr
    bike = tmp_path / "bike.glb"
    report = json.loads((tmp_path / "convert" / "report.json").read_text())
    assert any("the whole scene: 3 mesh object(s)" in note and "Frame" in note and "Wheel" in note
               for note in report["notes"]), report.get("notes")
    assert [m["name"] for m in report["materials"]] == ["Paint", "Board", "Rubber"]
    # The whole file, and the node "Bike" (frame and wheel, not the sign), baked side by side.
    bakes = {name: subprocess.Popen([sys.executable, "-m", "scenefit.cli", "bake", str(bike), "--texture",
                                     str(tmp_path / folder / "maps" / "texture.pt"), "--out",
                                     str(tmp_path / f"baked_{folder}.glb"), "--report", str(tmp_path / f"{folder}.json"),
                                     "--quiet", *extra], stderr=subprocess.PIPE, text=True)
             for name, folder, extra in (("whole", "convert", ()), ("node", "bike", ("--object", "Bike")))}
    for name, process in bakes.items():
        assert process.wait(timeout=600) == 0, process.stderr.read()
    bake = json.loads((tmp_path / "convert.json").read_text())
    assert bake["objects"] == ["Frame", "Sign", "Wheel"]
    assert [m["name"] for m in bake["materials"]] == ["Paint", "Board", "Rubber"]
    document = read_gltf(tmp_path / "baked_convert.glb")[0]
    names = {n.get("name") for n in document["nodes"]}
    assert {"Bike", "Frame", "Wheel", "Sign"} <= names
    # Every material carries a newly baked base colour image.
    images = {document["images"][document["textures"][m["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
              ["source"]]["name"] for m in document["materials"]}
    assert all(name.startswith(("Paint", "Rubber", "Board")) and "base_color" in name for name in images), images
    # --object takes one object ...
    assert [m["name"] for m in json.loads((tmp_path / "wheel" / "report.json").read_text())["materials"]] == ["Rubber"]
    # ... or a node with the meshes under it, in convert and bake alike; the rest of the file is kept as it was
    node = json.loads((tmp_path / "bike" / "report.json").read_text())
    assert [m["name"] for m in node["materials"]] == ["Paint", "Rubber"]
    assert any("'Bike': 2 mesh object(s)" in note for note in node["notes"]), node["notes"]
    node_bake = json.loads((tmp_path / "bike.json").read_text())
    assert node_bake["objects"] == ["Frame", "Wheel"] and [m["name"] for m in node_bake["materials"]] == ["Paint",
                                                                                                          "Rubber"]
    document = read_gltf(tmp_path / "baked_bike.glb")[0]
    assert {"Bike", "Frame", "Wheel", "Sign"} <= {n.get("name") for n in document["nodes"]}
    board = next(m for m in document["materials"] if m["name"] == "Board")
    source = document["images"][document["textures"][board["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
                                ["source"]]["name"]
    assert "base_color" not in source, source   # the sign's own image, not a bake
    # A name that is not in the file: one sentence naming what can be taken.
    assert "No object 'Bicycle' in 'bike.glb'; give one of its mesh objects or a node above them: Bike, Frame, " \
           "Sign, Wheel." in said, said
