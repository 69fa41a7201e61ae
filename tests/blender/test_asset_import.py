"""Asset files read by the command line as a new user's would be: a fresh bpy whose file is Blender's
startup scene (Cube, Camera, Light). The assets are written by Blender's own glTF exporter here; the
commands run as processes of their own, exactly as `scenefit convert` and `scenefit bake` run."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenefit.core.data.glb import read_gltf, write_glb

from conftest import printed_json, scenefit_here, scenefit_side_by_side

pytestmark = pytest.mark.blender

from conftest import ROOT  # noqa: E402

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

# UVs that tile: one material repeats its image over u, v in [1.2, 4.2], the other mirrors its own
# over [-1, 1] (glTF samplers REPEAT and MIRRORED_REPEAT; the first lies wholly outside [0, 1]).
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=2.0)
grid = bpy.context.active_object
grid.name = "Tiled"
for name, extension in (("Tiles", "REPEAT"), ("Mirror", "MIRROR")):
    mat = textured(name)
    next(n for n in mat.node_tree.nodes if n.type == "TEX_IMAGE").extension = extension
    grid.data.materials.append(mat)
layer = grid.data.uv_layers.active.data
for poly in grid.data.polygons:
    poly.material_index = int(poly.center.x > 0)
    for loop in poly.loop_indices:
        u, v = layer[loop].uv
        layer[loop].uv = (u * 3 + 1.2, v * 3 + 1.2) if poly.material_index == 0 else (u * 2 - 1, v * 2 - 1)
export(folder / "tiled.glb")

# A palette-textured low-poly prop (as Kenney's and gltf-transform's `palette` write them): every face's
# UVs collapse to the centre of one texel of a 16x16 palette, a different colour for each face.
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1)
gem = bpy.context.active_object
gem.name = "Gem"
palette = np.random.default_rng(5).uniform(0.1, 0.9, (16, 16, 3)).astype(np.float32)
mat = bpy.data.materials.new("Palette")
tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
tex.image = _image(bpy, folder, "palette", _rgba(palette), "sRGB")
mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
gem.data.materials.append(mat)
layer = gem.data.uv_layers.active.data
for poly in gem.data.polygons:
    row, col = divmod(3 * poly.index + 1, 16)
    for loop in poly.loop_indices:
        layer[loop].uv = ((col + 0.5) / 16, 1 - (row + 0.5) / 16)
export(folder / "palette.glb")
np.save(folder / "palette.npy", palette)

# A normal-mapped ball written with Draco (Blender's exporter writes no TANGENT unless asked).
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
ball = bpy.context.active_object
ball.name = "Ball"
mat = textured("Bumpy")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bumps = _pattern(32, 9) * 0.2 + 0.4
bumps[..., 2] = 1.0
normal_image = nodes.new("ShaderNodeTexImage")
normal_image.image = _image(bpy, folder, "bumpy_normal", _rgba(bumps), "Non-Color")
normal_map = nodes.new("ShaderNodeNormalMap")
links.new(normal_image.outputs["Color"], normal_map.inputs["Color"])
links.new(normal_map.outputs["Normal"], nodes["Principled BSDF"].inputs["Normal"])
ball.data.materials.append(mat)
export(folder / "draco.glb", export_draco_mesh_compression_enable=True)

# Vertex colours as the base colour: a grid whose linear colours run with x (red) and y (green).
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8, size=2.0)
painted = bpy.context.active_object
painted.name = "Painted"
colours = painted.data.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
for i, vertex in enumerate(painted.data.vertices):
    colours.data[i].color = (0.2 + 0.3 * (vertex.co.x + 1), 0.1 + 0.4 * (vertex.co.y + 1), 0.5, 1.0)
mat = bpy.data.materials.new("Painted")
attribute = mat.node_tree.nodes.new("ShaderNodeVertexColor")
attribute.layer_name = "Col"
mat.node_tree.links.new(attribute.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
painted.data.materials.append(mat)
export(folder / "painted.glb")
"""


def scenefit(*args: str) -> subprocess.CompletedProcess:
    """The command line in a process of its own (a fresh bpy holding Blender's startup scene)."""
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


@pytest.fixture(scope="module")
def assets(run_py, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("import_assets")
    run_py(BUILD.replace("FOLDER", repr(str(folder))))
    return folder


# Each convert runs in one bpy process for the module (bpy costs seconds to start), as the command runs:
# scenefit.cli.main, after Blender's startup scene (Cube, Camera, Light) is read again, so each convert
# meets what a fresh process meets. Each bake is a process of its own, as `scenefit bake` is (bpy cannot
# import a glTF after its exporter ran); the bakes run side by side.
CONVERTS = r"""
import contextlib, io, json
import bpy
from scenefit.cli import main

results = {}
for name, args in json.loads(JOBS):
    bpy.ops.wm.read_factory_settings()
    assert {o.name for o in bpy.data.objects} == {"Cube", "Camera", "Light"}
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(args)
    results[name] = {"code": code, "stderr": err.getvalue()}
print("JSON" + json.dumps(results))
"""

DEFAULT_FIT = ("--preset", "draft", "--iterations", "20", "--resolution", "32", "--quiet")
PALETTE_FIT = ("--preset", "draft", "--iterations", "300", "--resolution", "16", "--quiet")


def _derived_assets(assets: Path, folder: Path) -> dict[str, Path]:
    """The inputs made from the built ones by editing their glTF (no Blender needed)."""
    from scenefit.core.data.gltf_meshopt import encoded_glb

    document, chunk = read_gltf(assets / "skinned.glb")   # the skinned mesh moved to the scene's root
    nodes = document["nodes"]
    body = next(i for i, n in enumerate(nodes) if n.get("name") == "Body")
    next(n for n in nodes if body in n.get("children", []))["children"].remove(body)
    document["scenes"][0]["nodes"].append(body)
    write_glb(folder / "rooted.glb", document, chunk)
    rewrite_glb_json(assets / "palette.glb", folder / "palette.glb", _texcoord_only_transform)
    rewrite_glb_json(assets / "palette.glb", folder / "unlit.glb",
                     lambda data: (_unlit(data), _texcoord_only_transform(data)))
    return {"skinned": assets / "skinned.glb", "rooted": folder / "rooted.glb", "names": assets / "names.glb",
            "tiled": assets / "tiled.glb", "palette": folder / "palette.glb", "unlit": folder / "unlit.glb",
            "meshopt": encoded_glb(assets / "palette.glb", folder / "meshopt.glb"), "draco": assets / "draco.glb",
            "painted": assets / "painted.glb"}


@pytest.fixture(scope="module")
def runs(assets, run_py, tmp_path_factory) -> dict[str, dict]:
    """name -> {"asset", "work", "convert": (code, stderr), "bake": (code, stderr)} for every input here,
    plus the two refusals of --object Camera ("camera.blend", "camera.glb": convert only)."""
    folder = tmp_path_factory.mktemp("import_runs")
    inputs = _derived_assets(assets, folder)
    jobs = []
    for name, asset in inputs.items():
        fit = PALETTE_FIT if name == "palette" else DEFAULT_FIT
        jobs.append((name, ["convert", str(asset), "--out", str(folder / name / "convert"), *fit]))
    for suffix in (".blend", ".glb"):
        jobs.append((f"camera{suffix}", ["convert", str(assets / f"names{suffix}"), "--object", "Camera", "--out",
                                         str(folder / f"camera{suffix}")]))
    proc = run_py(CONVERTS.replace("JOBS", repr(json.dumps(jobs))), timeout=900)
    converted = printed_json(proc)
    out = {name: {"convert": (c["code"], c["stderr"])} for name, c in converted.items()}
    for name, asset in inputs.items():
        out[name].update(asset=asset, work=folder / name)
    baked = [name for name in inputs if out[name]["convert"][0] == 0]
    commands = [("bake", inputs[name], "--texture", folder / name / "convert/maps/texture.pt", "--out",
                 folder / name / "baked.glb", "--texture-size", "16" if name == "palette" else "32", "--report",
                 folder / name / "bake.json") for name in baked]
    for name, result in zip(baked, scenefit_side_by_side(*commands)):
        out[name]["bake"] = result
    return out


def convert_and_bake(runs: dict, name: str) -> tuple[dict, dict]:
    """(convert's report, the baked GLB's JSON) of `scenefit convert` then `scenefit bake` of input `name`."""
    run = runs[name]
    assert run["convert"][0] == 0, run["convert"][1][-2000:]
    assert run["bake"][0] == 0, run["bake"][1][-2000:]
    return json.loads((run["work"] / "convert" / "report.json").read_text()), read_gltf(run["work"] / "baked.glb")[0]


def test_a_skinned_gltf_converts_and_bakes_with_its_skin(runs):
    """Blender's glTF importer makes bone shapes through the context object; in the startup scene that
    was the Cube of another scene ("Object 'Cube' not in collection 'Scene Collection'")."""
    report, out = convert_and_bake(runs, "skinned")
    assert [m["name"] for m in report["decisions"]["materials"]] == ["Skin"]
    assert len(out["skins"]) == 1 and len(out["skins"][0]["joints"]) == 2
    assert {"Rig", "Body", "Bone", "Upper"} <= {n["name"] for n in out["nodes"]}


def test_a_skinned_mesh_at_the_root_stays_at_the_root(runs, validator):
    """Blender parents a skinned mesh to its armature; glTF ignores a skinned mesh node's transform, so
    under a parent it only draws NODE_SKINNED_MESH_NON_ROOT. An input whose skinned mesh is a root node
    (the Khronos Fox) gets it back as a root node, and the validator no warning the input did not have;
    an input that parented it (Blender's own export) keeps it parented, as it came."""
    rooted = runs["rooted"]["asset"]   # the built file with Body moved to the scene's root
    assert "NODE_SKINNED_MESH_NON_ROOT" not in {m["code"] for m in validator(str(rooted))["issues"]["messages"]}

    _, out = convert_and_bake(runs, "rooted")
    body = next(i for i, n in enumerate(out["nodes"]) if n["name"] == "Body")
    assert "skin" in out["nodes"][body] and body in out["scenes"][0]["nodes"]
    assert not any(body in n.get("children", []) for n in out["nodes"])
    report = validator(str(runs["rooted"]["work"] / "baked.glb"))["issues"]
    assert report["numErrors"] == 0 and "NODE_SKINNED_MESH_NON_ROOT" not in {m["code"] for m in report["messages"]}

    _, out = convert_and_bake(runs, "skinned")
    body = next(i for i, n in enumerate(out["nodes"]) if n["name"] == "Body")
    assert any(body in n.get("children", []) for n in out["nodes"])


def test_bake_keeps_the_names_the_startup_scene_also_uses(assets, runs):
    """A material 'Material' and a camera 'Camera' come back under exactly those names (the startup
    scene's own made them 'Material.001' and 'Camera.001'); the Mapping node's Cycles bake runs in the
    scene it reads (it stopped at "Object "Cube" is not in view layer")."""
    report, out = convert_and_bake(runs, "names")
    assert [m["name"] for m in report["decisions"]["materials"]] == ["Material"]
    source = read_gltf(assets / "names.glb")[0]
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
    out = printed_json(proc)
    assert out == {"materials": ["Skin"], "same": True, "scene": "Scene", "active": "Cube", "file": str(blend)}


@pytest.mark.parametrize("suffix", (".blend", ".glb"))
def test_object_naming_a_camera_lists_the_mesh_objects_there_are(runs, suffix):
    """--object naming a non-mesh object with no mesh under it says what it is and lists what can be
    taken (a .blend once listed "mesh objects: none": only the named object was appended)."""
    code, stderr = runs[f"camera{suffix}"]["convert"]
    assert code == 2 and "Traceback" not in stderr, stderr[-2000:]
    assert (f"'Camera' in 'names{suffix}' is a camera object with no mesh under it; give one of its mesh objects "
            "or a node above them: Cube.") in stderr, stderr


def test_tiling_uvs_convert_and_bake_alike_and_keep_their_samplers(runs):
    """Convert fitted the atlas (UVs past a cell reached into the next one) while bake refused the
    material whose UVs all lie outside [0, 1] ("covers no texel centre"); now both wrap each
    material as its sampler says, cover the same texels, and the baked file keeps the samplers."""
    report, out = convert_and_bake(runs, "tiled")
    converted = {m["name"]: m for m in report["decisions"]["materials"]}
    baked = {m["name"]: m for m in json.loads((runs["tiled"]["work"] / "bake.json").read_text())["materials"]}
    for name in ("Tiles", "Mirror"):
        assert converted[name]["uv_coverage"] == baked[name]["uv_coverage"] == 1.0, (converted, baked)
    assert {m["name"]: m["wrap"] for m in report["materials"]} == {"Tiles": ["repeat", "repeat"],
                                                                   "Mirror": ["mirror", "mirror"]}
    samplers = {}
    for material in out["materials"]:
        texture = out["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
        sampler = out["samplers"][texture["sampler"]] if "sampler" in texture else {}
        samplers[material["name"]] = (sampler.get("wrapS", 10497), sampler.get("wrapT", 10497))
    assert samplers == {"Tiles": (10497, 10497), "Mirror": (33648, 33648)}  # REPEAT, MIRRORED_REPEAT


def glb_image(path: Path, data: dict, texture: int) -> np.ndarray:
    """(H, W, 3) float sRGB values of texture `texture` of the GLB at `path` (its JSON `data`)."""
    import cv2

    _, blob = read_gltf(path)
    view = data["bufferViews"][data["images"][data["textures"][texture]["source"]]["bufferView"]]
    encoded = np.frombuffer(blob[view.get("byteOffset", 0):][:view["byteLength"]], np.uint8)
    return cv2.imdecode(encoded, cv2.IMREAD_COLOR)[..., ::-1] / 255.0


def rewrite_glb_json(path: Path, out: Path, edit) -> None:
    """`path` with its JSON chunk changed by edit(data) in place, written to `out`."""
    data, blob = read_gltf(path)
    edit(data)
    write_glb(out, data, blob or b"")


def _texcoord_only_transform(data: dict) -> None:
    """A KHR_texture_transform naming only the UV set, as UnityGLTF writes on every texture (Kenney's GLBs)."""
    data["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
        "KHR_texture_transform": {"texCoord": 0}}
    data["extensionsUsed"] = sorted(set(data.get("extensionsUsed", [])) | {"KHR_texture_transform"})


def test_palette_textures_convert_and_bake_each_face_as_the_texel_it_samples(assets, runs):
    """UVs collapsed to points were refused ("has no UV area ... Unwrap it again"), which would lose
    the palette's colours. Each face now samples its texel in convert and bake alike, and the baked
    palette gives every face the colour it had. The importer's Mapping node for a texture transform
    that moves nothing is read through (it sent the image to a Cycles bake, which saw no UV area:
    Kenney's palettes came back black)."""
    report, out = convert_and_bake(runs, "palette")   # its texture transform names only the UV set
    assert report["psnr_covered_texels_db"] > 30, report["psnr_covered_texels_db"]
    assert not any("Cycles" in line for line in report["materials"][0]["read"]), report["materials"][0]["read"]
    converted = report["decisions"]["materials"][0]["uv_coverage"]
    work = runs["palette"]["work"]
    baked_coverage = json.loads((work / "bake.json").read_text())["materials"][0]["uv_coverage"]
    assert converted == baked_coverage == round(20 / 256, 4)
    image = glb_image(work / "baked.glb", out, out["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"])
    palette = np.load(assets / "palette.npy")
    rows, cols = np.divmod(3 * np.arange(20) + 1, 16)
    error = np.abs(image[rows, cols] - np.round(palette[rows, cols] * 255) / 255)  # the image's sRGB bytes
    assert error.mean() < 0.03 and error.max() < 0.1, error


def _unlit(data: dict) -> None:
    """The material made KHR_materials_unlit, as Kenney's characters are."""
    data["materials"][0].setdefault("extensions", {})["KHR_materials_unlit"] = {}
    data["extensionsUsed"] = sorted(set(data.get("extensionsUsed", [])) | {"KHR_materials_unlit"})


def test_an_unlit_material_reads_its_colour_as_base_colour_and_stays_unlit(runs):
    """KHR_materials_unlit comes in as an Emission shader mixed by Light Path, no Principled BSDF:
    it was refused ("has no Principled BSDF node"). Its colour is the base colour now, and the
    baked file is unlit again, with the baked image as its colour."""
    report, out = convert_and_bake(runs, "unlit")
    material = report["materials"][0]
    assert any(line.startswith("unlit (KHR_materials_unlit)") for line in material["kept"]), material
    assert any(line.startswith("Base Color <- image 'palette'") for line in material["read"]), material["read"]
    assert "KHR_materials_unlit" in out["extensionsUsed"]
    assert out["materials"][0]["extensions"] == {"KHR_materials_unlit": {}}
    assert "baseColorTexture" in out["materials"][0]["pbrMetallicRoughness"]


def test_a_meshopt_compressed_file_converts_and_bakes(runs):
    """Blender 5.0's importer has no EXT_meshopt_compression decoder: such a file (valid per the
    validator) was refused "check that it is a valid '.glb' file, or export it again"."""
    report, out = convert_and_bake(runs, "meshopt")
    assert report["decisions"]["materials"][0]["uv_coverage"] == round(20 / 32 ** 2, 4)  # each face its texel
    assert [m["name"] for m in out["materials"]] == ["Palette"] and len(out["meshes"]) == 1
    assert "EXT_meshopt_compression" in out["extensionsUsed"]   # compressed as the input was
    # A .gltf cannot hold meshopt (its encoder works on a .glb's binary chunk): written plain, and said so.
    # It was refused for "--compress meshopt", which the user never gave.
    work = runs["meshopt"]["work"]
    proc = scenefit("bake", str(runs["meshopt"]["asset"]), "--texture", str(work / "convert/maps/texture.pt"),
                    "--out", str(work / "baked.gltf"), "--texture-size", "32")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "the input's meshopt compression is written into .glb files only: none in this .gltf" in proc.stdout
    assert "EXT_meshopt_compression" not in read_gltf(work / "baked.gltf")[0].get("extensionsUsed", [])


def test_bake_compresses_like_the_input_follows_its_tangents_and_writes_the_chosen_textures(runs, tmp_path,
                                                                                             validator):
    """The bake of a Draco file came back uncompressed. It is compressed as the input by default, its
    TANGENT is the input's (this normal-mapped ball has none: glTF's clients generate MikkTSpace ones, and
    the validator says nothing of the bake it did not say of the input), and --compress / --textures /
    --max-texture choose otherwise."""
    asset, texture = runs["draco"]["asset"], runs["draco"]["work"] / "convert/maps/texture.pt"
    _, out = convert_and_bake(runs, "draco")
    assert "KHR_draco_mesh_compression" in out["extensionsUsed"] and "normalTexture" in out["materials"][0]
    assert not any("TANGENT" in p["attributes"] for mesh in out["meshes"] for p in mesh["primitives"])
    warnings = [{m["code"] for m in validator(str(path))["issues"]["messages"] if m["severity"] <= 1}
                for path in (asset, runs["draco"]["work"] / "baked.glb")]
    assert warnings[1] <= warnings[0], warnings
    baked = tmp_path / "meshopt.glb"
    proc = scenefit("bake", str(asset), "--texture", str(texture), "--out", str(baked),
                    "--texture-size", "32", "--compress", "meshopt", "--textures", "jpeg", "--max-texture", "16",
                    "--report", str(tmp_path / "meshopt.json"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    out, report = read_gltf(baked)[0], json.loads((tmp_path / "meshopt.json").read_text())
    assert "EXT_meshopt_compression" in out["extensionsRequired"] and "KHR_draco_mesh_compression" not in \
        out.get("extensionsUsed", [])
    base = out["textures"][out["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    assert out["images"][base["source"]]["mimeType"] == "image/jpeg"
    assert report["texture_size"] == 16 and report["output"]["compress"] == "meshopt"
    assert validator(str(baked))["issues"]["numErrors"] == 0   # the conftest's validator (tools/gltf_validate.js)
    proc = scenefit_here("bake", str(asset), "--texture", str(texture), "--out",
                         str(tmp_path / "x.glb"), "--max-texture", "100")   # refused before Blender is needed
    assert proc.returncode == 2 and "--max-texture must be a power of two between 4 and 8192, got 100." in proc.stderr


def test_vertex_colours_are_baked_into_the_base_colour_and_not_multiplied_in_again(runs):
    """Vertex colours are read as base colour (Blender's bake of the Color Attribute chain); the
    exporter then still wrote COLOR_0 (and a second, made-up COLOR_1), which glTF multiplies into
    the baked base colour that already holds them: the colours came out squared."""
    assert any("COLOR_0" in p["attributes"] for m in read_gltf(runs["painted"]["asset"])[0]["meshes"]
               for p in m["primitives"])
    report, out = convert_and_bake(runs, "painted")
    assert any("Color Attribute" in line for line in report["materials"][0]["read"]), report["materials"][0]["read"]
    assert not any(name.startswith("COLOR_") for m in out["meshes"] for p in m["primitives"] for name in p["attributes"])
    image = glb_image(runs["painted"]["work"] / "baked.glb", out, out["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
                      ["index"])
    size = image.shape[0]
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, 1 - (np.arange(size) + 0.5) / size)
    linear = np.stack([0.2 + 0.6 * u, 0.1 + 0.8 * v, np.full_like(u, 0.5)], axis=-1)  # the grid's UVs: u = (x + 1) / 2
    srgb = np.where(linear <= 0.0031308, linear * 12.92, 1.055 * linear ** (1 / 2.4) - 0.055)
    # (20 draft iterations fit the gradients loosely: the colours on average)
    assert np.abs(image.mean(axis=(0, 1)) - srgb.mean(axis=(0, 1))).max() < 0.05, (image.mean((0, 1)), srgb.mean((0, 1)))


PROCEDURAL_TILES = r"""
import json
import numpy as np
import bpy
from scenefit.blender_io.material import read_material

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_plane_add(size=2.0)
plane = bpy.context.active_object
for loop in plane.data.uv_layers.active.data:
    loop.uv = (loop.uv[0] + 1.0, loop.uv[1] * 2.0 - 0.5)  # u in [1, 2], v in [-0.5, 1.5]
mat = bpy.data.materials.new("Procedural")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bsdf = nodes["Principled BSDF"]
rgb = nodes.new("ShaderNodeRGB")
rgb.outputs[0].default_value = (0.2, 0.5, 0.8, 1.0)
links.new(rgb.outputs[0], bsdf.inputs["Base Color"])
coords, xyz, minus = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeSeparateXYZ"), nodes.new("ShaderNodeMath")
minus.operation, minus.inputs[1].default_value = "SUBTRACT", 1.0  # roughness = u - 1, read from the mesh's UVs
links.new(coords.outputs["UV"], xyz.inputs[0])
links.new(xyz.outputs["X"], minus.inputs[0])
links.new(minus.outputs[0], bsdf.inputs["Roughness"])
plane.data.materials.append(mat)
material = read_material(mat, plane, 0)
print("JSON" + json.dumps({"base": material.maps.base_color.tolist(), "rough": np.asarray(material.maps.roughness).tolist(),
                           "uv_maps": [layer.name for layer in plane.data.uv_layers]}))
"""


def test_procedural_inputs_are_baked_over_uvs_that_tile(run_py):
    """Blender bakes only UVs inside [0, 1]: a chain over u in [1, 2] came back all black. Each copy of
    the image the faces reach is baked through a moved UV map, the chain reading the mesh's own UVs."""
    proc = run_py(PROCEDURAL_TILES)
    out = printed_json(proc)
    base, rough = np.array(out["base"]), np.array(out["rough"])
    assert np.abs(base - [0.2, 0.5, 0.8]).max() < 1e-3
    u = (np.arange(rough.shape[1]) + 0.5) / rough.shape[1]  # texel centres: the chain's u - 1 there
    assert np.abs(rough - u).max() < 2.0 / rough.shape[1], np.abs(rough - u).max()
    assert out["uv_maps"] == ["UVMap"]  # the bake's own UV map went with its temporary mesh
