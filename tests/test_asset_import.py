"""Asset files read by the command line as a new user's would be: a fresh bpy whose file is Blender's
startup scene (Cube, Camera, Light). The assets are written by Blender's own glTF exporter here; the
commands run as processes of their own, exactly as `scenefit convert` and `scenefit bake` run."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.blender

ROOT = Path(__file__).resolve().parent.parent

BUILD = r"""
import sys
from pathlib import Path
import numpy as np
import bpy
import addon_utils
sys.path.insert(0, "tests")
from asset_builder import _image, _pattern, _rgba

folder = Path(FOLDER)
addon_utils.enable("io_scene_gltf2", default_set=False)

def export(path, **options):
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", **options)

def textured(name, mapping=False):
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = _image(bpy, folder, name + "_base", _rgba(_pattern(32, 3)), "sRGB")
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    if mapping:  # written as KHR_texture_transform, read back as a Mapping node: baked by Cycles
        coords, node = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeMapping")
        node.inputs["Scale"].default_value = (0.5, 0.5, 1.0)
        links.new(coords.outputs["UV"], node.inputs["Vector"])
        links.new(node.outputs["Vector"], tex.inputs["Vector"])
    return mat

# A skinned mesh: a two-bone armature bending a cylinder (the importer adds bone shapes for it).
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.object.armature_add(location=(0, 0, 0))
rig = bpy.context.active_object
rig.name = "Rig"
bpy.ops.object.mode_set(mode="EDIT")
first = rig.data.edit_bones[0]
first.head, first.tail = (0, 0, 0), (0, 0, 1)
second = rig.data.edit_bones.new("Upper")
second.head, second.tail, second.parent = (0, 0, 1), (0, 0, 2), first
bpy.ops.object.mode_set(mode="OBJECT")
bpy.ops.mesh.primitive_cylinder_add(vertices=16, depth=2.0, radius=0.3, location=(0, 0, 1))
body = bpy.context.active_object
body.name = "Body"
bpy.ops.object.transform_apply(location=True)
bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.subdivide(number_cuts=4)
bpy.ops.object.mode_set(mode="OBJECT")
body.data.materials.append(textured("Skin"))
body.select_set(True)
rig.select_set(True)
bpy.context.view_layer.objects.active = rig
bpy.ops.object.parent_set(type="ARMATURE_AUTO")
export(folder / "skinned.glb", export_skins=True)

# The startup scene's own names on the asset: a material 'Material', a camera 'Camera', an object 'Cube'.
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
prop = bpy.context.active_object
prop.name = "Cube"
prop.data.materials.append(textured("Material", mapping=True))
camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
camera.location = (0, -4, 0)
bpy.context.scene.collection.objects.link(camera)
export(folder / "names.glb", export_cameras=True)
bpy.ops.wm.save_as_mainfile(filepath=str(folder / "names.blend"))
"""


def gltf_json(path: Path) -> dict:
    data = path.read_bytes()
    length = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + length])


def scenefit(*args: str) -> subprocess.CompletedProcess:
    """The command line in a process of its own (a fresh bpy holding Blender's startup scene)."""
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


@pytest.fixture(scope="module")
def assets(run_py, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("import_assets")
    run_py(BUILD.replace("FOLDER", repr(str(folder))))
    return folder


def convert_and_bake(asset: Path, work: Path) -> tuple[dict, dict]:
    """(convert's report, the baked GLB's JSON) from `scenefit convert` then `scenefit bake` of `asset`."""
    proc = scenefit("convert", str(asset), "--out", str(work / "convert"), "--preset", "draft", "--iterations", "20",
                    "--resolution", "32", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads((work / "convert" / "report.json").read_text())
    baked = work / "baked.glb"
    proc = scenefit("bake", str(asset), "--texture", str(work / "convert/maps/texture.pt"), "--out", str(baked),
                    "--texture-size", "32")
    assert proc.returncode == 0, proc.stderr[-2000:]
    return report, gltf_json(baked)


def test_a_skinned_gltf_converts_and_bakes_with_its_skin(assets, tmp_path):
    """Blender's glTF importer makes bone shapes through the context object; in the startup scene that
    was the Cube of another scene ("Object 'Cube' not in collection 'Scene Collection'")."""
    report, out = convert_and_bake(assets / "skinned.glb", tmp_path)
    assert [m["name"] for m in report["decisions"]["materials"]] == ["Skin"]
    assert len(out["skins"]) == 1 and len(out["skins"][0]["joints"]) == 2
    assert {"Rig", "Body", "Bone", "Upper"} <= {n["name"] for n in out["nodes"]}


def test_bake_keeps_the_names_the_startup_scene_also_uses(assets, tmp_path):
    """A material 'Material' and a camera 'Camera' come back under exactly those names (the startup
    scene's own made them 'Material.001' and 'Camera.001'); the Mapping node's Cycles bake runs in the
    scene it reads (it stopped at "Object "Cube" is not in view layer")."""
    report, out = convert_and_bake(assets / "names.glb", tmp_path)
    assert [m["name"] for m in report["decisions"]["materials"]] == ["Material"]
    source = gltf_json(assets / "names.glb")
    assert [m["name"] for m in out["materials"]] == ["Material"]
    assert sorted(n["name"] for n in out["nodes"]) == sorted(n["name"] for n in source["nodes"]) == ["Camera", "Cube"]
    assert [c["name"] for c in out["cameras"]] == [c["name"] for c in source["cameras"]] == ["Camera"]
    assert [m["name"] for m in out["meshes"]] == [m["name"] for m in source["meshes"]]


IN_SESSION = r"""
import json
import bpy
from scenefit.blender_io.asset_file import load_asset_materials

# An artist's saved file (the startup scene's Cube active and selected): loaded into a temporary scene.
bpy.ops.wm.save_as_mainfile(filepath=BLEND)
counts = lambda: {k: sorted(i.name for i in getattr(bpy.data, k)) for k in
                  ("objects", "meshes", "materials", "images", "scenes", "collections", "armatures", "actions")}
before = counts()
asset = load_asset_materials(ASSET)
print("JSON" + json.dumps({"materials": [m.name for m in asset.materials], "same": counts() == before,
                           "scene": bpy.context.window.scene.name, "active": bpy.context.view_layer.objects.active.name,
                           "file": bpy.data.filepath}))
"""


def test_a_skinned_gltf_loads_into_a_temporary_scene_of_an_open_file(assets, run_py, tmp_path):
    """In a file someone has open nothing is emptied: the import goes into a temporary scene, shown in
    the window while it runs (the importer's bone shapes use the window's active object), and goes."""
    blend = tmp_path / "artist.blend"
    proc = run_py(IN_SESSION.replace("BLEND", repr(str(blend))).replace("ASSET", repr(str(assets / "skinned.glb"))))
    out = json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("JSON"))[4:])
    assert out == {"materials": ["Skin"], "same": True, "scene": "Scene", "active": "Cube", "file": str(blend)}


@pytest.mark.parametrize("suffix", (".blend", ".glb"))
def test_object_naming_a_camera_lists_the_mesh_objects_there_are(assets, suffix, tmp_path):
    """--object naming a non-mesh object says what it is and lists the file's meshes (a .blend, of
    which only the named object is appended, listed "mesh objects: none")."""
    proc = scenefit("convert", str(assets / f"names{suffix}"), "--object", "Camera", "--out", str(tmp_path / "out"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert f"'Camera' in 'names{suffix}' is a camera object, not a mesh; give one of its mesh objects: Cube." \
        in proc.stderr
