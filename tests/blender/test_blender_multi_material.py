"""Run All and Bake Asset in Blender on an object with three materials and on a selection of two objects:
every slot of every object gets a new SceneFit material with that material's own maps (baked
in its own UVs, not the atlas), the Results switch restores every slot, the artist's materials are kept,
and Bake Asset writes a GLB that validates with every material baked.

One Blender session for the module (conftest.PythonSession), the extension installed from its zip, every
operator through EXEC_DEFAULT. Each material's base colour is one colour of its own, so a result that
took another material's cell of the atlas shows the wrong colour.
"""
import json
from contextlib import closing
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import PythonSession, extension_and_models, fill_in

from scenefit.core.data.imageio import read_image
from scenefit.core.data.glb import read_gltf

pytestmark = pytest.mark.blender

# sRGB colours (as stored in 8-bit images) of the materials, by name.
COLOURS = {"Red": (0.80, 0.10, 0.10), "Green": (0.10, 0.75, 0.15), "Blue": (0.10, 0.20, 0.85),
           "Yellow": (0.90, 0.80, 0.10), "Grey": (0.5, 0.5, 0.5)}

INSTALL = r"""
import json, sys, time
from importlib import import_module
from pathlib import Path
import numpy as np
import bpy

tmp, zip_path = Path(TMP), ZIP
MODULE = "bl_ext.user_default.scenefit"
bpy.ops.extensions.package_install_files(repo="user_default", filepath=zip_path, enable_on_install=True)
prefs = bpy.context.preferences.addons[MODULE].preferences
prefs.offline = True
prefs.base_model, prefs.inpaint_model = str(Path(TINY) / "sd2-base"), str(Path(TINY) / "sd2-inpaint")
imageio = import_module(MODULE + ".core.data.imageio")
imageio.write_image(tmp / "photo.png", np.random.default_rng(1).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32))
COLOURS = COLOURS_HERE

def colour_material(name):
    # A material whose Base Color is a 24x12 image of one colour (with a little noise), roughness 0.6.
    image = bpy.data.images.new(f"{name} image", 24, 12)
    pixels = np.ones((12, 24, 4), np.float32)
    noise = np.random.default_rng(len(name)).uniform(-0.02, 0.02, (12, 24, 3))
    pixels[..., :3] = np.clip(np.array(COLOURS[name], np.float32) + noise, 0, 1)
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.6
    return mat

def new_scene():
    bpy.ops.wm.read_homefile(use_empty=True)  # (factory settings would disable the extension)
    s = bpy.context.scene.scenefit
    s.preset, s.photo_path, s.prompt = "draft", str(tmp / "photo.png"), ""
    s.output_dir = str(tmp / "runs") + "/"

def split_faces(obj, names, by):
    # Material slots `names`, face i using slot by(polygon).
    for name in names:
        obj.data.materials.append(colour_material(name))
    for poly in obj.data.polygons:
        poly.material_index = by(poly)

def base_colour(mat):
    # Median stored (sRGB) colour of the image behind the material's Base Color.
    link = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].links[0]
    image = link.from_node.image
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    return [round(float(v), 4) for v in np.median(px.reshape(-1, image.channels)[:, :3], axis=0)], [w, h]

def artists(names):
    # What the artist's materials are: nodes, links, their image's pixels (must never change).
    out = {}
    for name in names:
        mat = bpy.data.materials[name]
        image = bpy.data.images[f"{name} image"]
        out[name] = [sorted(n.bl_idname for n in mat.node_tree.nodes), len(mat.node_tree.links),
                     round(float(np.sum(np.array(image.pixels[:]))), 3), "scenefit" in mat]
    return out

def box_and_ball():
    # A red box and a sphere (its materials to be added), side by side.
    bpy.ops.mesh.primitive_cube_add(location=(-1.5, 0, 1), scale=(0.8, 0.8, 0.8))
    box = bpy.context.active_object
    box.name = "Box"
    box.data.materials.append(colour_material("Red"))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, location=(1.5, 0, 1))
    ball = bpy.context.active_object
    ball.name = "Ball"
    return box, ball

def slots(objects):
    return {o: [s.material.name for s in bpy.data.objects[o].material_slots] for o in objects}

def results(objects):
    # Per slot: the material, whether SceneFit made it, and its base colour image's median colour and size.
    out = {}
    for o in objects:
        for i, s in enumerate(bpy.data.objects[o].material_slots):
            colour, size = base_colour(s.material)
            out[f"{o}/{i}"] = [s.material.name, s.material.get("scenefit"), colour, size]
    return out

def operate(objects, originals, glb):
    # Run All, the switch both ways, Bake Asset; what each left.
    res, t = {}, time.perf_counter()
    res["run"] = sorted(bpy.ops.scenefit.run(guidance="none"))
    res["seconds_run"] = round(time.perf_counter() - t, 2)
    res["results"] = results(objects)
    res["fake_users"] = {n: bpy.data.materials[n].use_fake_user for n in originals}
    res["revert"] = sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL"))
    res["reverted"] = slots(objects)
    res["again"] = sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="RESULT"))
    res["switched_back"] = slots(objects)
    report = json.loads((Path(bpy.path.abspath(bpy.context.scene.scenefit.composite_path)).parent.parent
                         / "report.json").read_text())
    res["stages"] = {k: v["status"] for k, v in report["stages"].items()}
    res["materials_in_blender"] = [m["name"] for m in report.get("materials_in_blender", [])]
    before = [sorted(x.name for x in getattr(bpy.data, k)) for k in ("objects", "meshes", "materials", "images")]
    t = time.perf_counter()
    res["bake"] = sorted(bpy.ops.scenefit.bake_asset(filepath=str(glb)))
    res["seconds_bake"] = round(time.perf_counter() - t, 2)
    after = [sorted(x.name for x in getattr(bpy.data, k)) for k in ("objects", "meshes", "materials", "images")]
    res["bake_left_session_as_it_was"] = before == after
    res["artists"] = artists(originals)
    return res
"""

# An object with three materials: a cube whose faces use Red, Green and Blue, two faces each.
THREE = r"""
new_scene()
bpy.ops.mesh.primitive_cube_add()
cube = bpy.context.active_object
split_faces(cube, ["Red", "Green", "Blue"], lambda poly: poly.index % 3)
originals = ["Red", "Green", "Blue"]
before = artists(originals)
out.update(operate(["Cube"], originals, tmp / "three.glb"))
out["artists_before"] = before
# Run All again with nothing changed: a new run folder, its stages copied from the last run, not redone
first_run = Path(bpy.path.abspath(bpy.context.scene.scenefit.composite_path)).parent.parent
listing = lambda folder: sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))
first_files = listing(first_run)
out["run_again"] = sorted(bpy.ops.scenefit.run(guidance="none"))
second_run = Path(bpy.path.abspath(bpy.context.scene.scenefit.composite_path)).parent.parent
report = json.loads((second_run / "report.json").read_text())
out["again_stages"] = {k: v["status"] for k, v in report["stages"].items()}
out["again_folders"] = [first_run.name != second_run.name, first_files == listing(first_run)]
"""

# A selection of two objects (one with one material, one with two) and an object left out of it.
SELECTION = r"""
new_scene()
bpy.ops.mesh.primitive_plane_add(location=(0, 4, 0))
bystander = bpy.context.active_object
bystander.name = "Bystander"
bystander.data.materials.append(colour_material("Grey"))
box, ball = box_and_ball()
split_faces(ball, ["Blue", "Yellow"], lambda poly: int(poly.center.z > 0))
bystander.select_set(False)
box.select_set(True)
ball.select_set(True)
bpy.context.view_layer.objects.active = ball
originals = ["Red", "Blue", "Yellow"]
before = artists(originals + ["Grey"])
out.update(operate(["Box", "Ball"], originals, tmp / "selection.glb"))
# Compose (set up only) takes the selection as Run All did: the camera Run All placed around both stays put
camera = bpy.data.objects["SceneFit Camera"]
placed = [round(v, 5) for v in camera.location]
box.select_set(True); ball.select_set(True); bpy.context.view_layer.objects.active = ball
out["compose"] = sorted(bpy.ops.scenefit.compose(render=False))
out["camera_moved"] = [placed, [round(v, 5) for v in camera.location]]
out["artists"] = artists(originals + ["Grey"])
out["artists_before"] = before
out["bystander"] = [s.material.name for s in bystander.material_slots]
"""

# A texture adapted per surface (stood in for by a residual that varies over the surface) on a selection
# whose sphere has mirrored UVs: Bake Asset bakes the sphere's materials into a new UV map, on copies.
MIRRORED = r"""
new_scene()
box, ball = box_and_ball()
uv = np.empty(2 * len(ball.data.loops), np.float32)
ball.data.uv_layers.active.uv.foreach_get("vector", uv)
uv = uv.reshape(-1, 2)
uv[:, 0] = np.abs(uv[:, 0] - 0.5) * 2.0
ball.data.uv_layers.active.uv.foreach_set("vector", uv.ravel())
split_faces(ball, ["Blue", "Yellow"], lambda poly: int(poly.center.z > 0))
box.select_set(True)
ball.select_set(True)
bpy.context.view_layer.objects.active = ball
import torch
asset_ops = import_module(MODULE + ".operators.asset")
convert = import_module(MODULE + ".core.stages.convert")
layouts = import_module(MODULE + ".core.texture.surface_layout")
saving = import_module(MODULE + ".core.texture.bake")
asset = asset_ops.asset_layout(bpy.context).read(bpy.context)
texture = convert.convert_materials(asset, convert.ConvertConfig(texture=import_module(MODULE + ".core.pipeline.presets").stage_config("texture", "draft"), resolution=32)).texture
view, layout, why = layouts.adapting_view(texture, asset.fitting_view()[0])
out["layout"] = why
texture.layout = layout
with torch.no_grad():
    generator = torch.Generator().manual_seed(0)
    texture.encoding.table.normal_(0.0, 1.0, generator=generator)
    texture.mlp[2].weight.normal_(0.0, 1.0, generator=generator)
bpy.context.scene.scenefit.texture_path = str(saving.save_neural_texture(texture, tmp / "mirrored.pt"))
layers = lambda: {o.name: [l.name for l in o.data.uv_layers] for o in (box, ball)}
out["uv_layers_before"] = layers()
before = [sorted(x.name for x in getattr(bpy.data, k)) for k in ("objects", "meshes", "materials", "images")]
out["bake"] = sorted(bpy.ops.scenefit.bake_asset(filepath=str(tmp / "mirrored.glb")))
after = [sorted(x.name for x in getattr(bpy.data, k)) for k in ("objects", "meshes", "materials", "images")]
out["bake_left_session_as_it_was"] = before == after
out["uv_layers_after"] = layers()
"""

# Convert on the same object, twice: the second reads the first's results and keeps the artist's as originals.
CONVERT = r"""
new_scene()
bpy.ops.mesh.primitive_cube_add()
split_faces(bpy.context.active_object, ["Red", "Green", "Blue"], lambda poly: poly.index % 3)
out["convert"] = [sorted(bpy.ops.scenefit.convert())]
# The first results repainted magenta (as an adapted texture differs from the asset): converting again
# restyles the artist's materials, not SceneFit's last result in the slots
for s in bpy.data.objects["Cube"].material_slots:
    image = s.material.node_tree.nodes["SceneFit Base Color"].image
    image.pixels.foreach_set(np.tile(np.array([1.0, 0.0, 1.0, 1.0], np.float32), len(image.pixels) // 4))
out["convert"].append(sorted(bpy.ops.scenefit.convert()))
out["results"] = results(["Cube"])
out["revert"] = sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL"))
out["reverted"] = slots(["Cube"])
"""

# Adapt after Convert on three materials: the atlas Convert fitted is adapted and every slot gets its material's
# maps (it once adapted the active object's own mesh and put one result in slot 0 only).
ADAPT = r"""
new_scene()
bpy.ops.mesh.primitive_cube_add()
split_faces(bpy.context.active_object, ["Red", "Green", "Blue"], lambda poly: poly.index % 3)
s = bpy.context.scene.scenefit
s.preset, s.photo_path, s.prompt, s.placement = "draft", str(tmp / "photo.png"), "a mossy cube", (0.5, 0.8)
out["convert"] = sorted(bpy.ops.scenefit.convert(iterations=5))
out["adapt"] = sorted(bpy.ops.scenefit.adapt(iterations=2, model_resolution=32, render_size=16))
out["results"] = results(["Cube"])
# One used material behind an unused active slot: Adapt's result goes where the faces are, as Convert's does
bpy.ops.mesh.primitive_cube_add(location=(4, 0, 0))
lone = bpy.context.active_object
lone.name = "Lone"
lone.data.materials.append(colour_material("Grey"))
lone.data.materials.append(colour_material("Yellow"))
for poly in lone.data.polygons:
    poly.material_index = 1
lone.active_material_index = 0
s.prompt = "a mossy cube"   # each asset has its own prompt (Lone is another asset than Cube)
out["lone"] = [sorted(bpy.ops.scenefit.convert(iterations=5)),
               sorted(bpy.ops.scenefit.adapt(iterations=2, model_resolution=32, render_size=16))]
out["lone_slots"] = [[sl.material.name, sl.material.get("scenefit")] for sl in lone.material_slots]
# Export to Mitsuba takes the three materials too (their atlas, one shape, as `scenefit export` writes them)
out["export"] = sorted(bpy.ops.scenefit.export_mitsuba(directory=str(tmp / "mitsuba")))
out["exported"] = sorted(p.name for p in (tmp / "mitsuba").iterdir())
ply = next((tmp / "mitsuba").glob("*.ply")).read_bytes()
out["ply_faces"] = next(int(l.split()[2]) for l in ply[:ply.index(b"end_header")].decode().splitlines()
                        if l.startswith("element face"))
"""

# Convert on A, then on B, then A's result repainted and A converted again: A's artist's material is still
# what is read (it was found only through the last job's record, which B's result replaced).
ONE_THEN_ANOTHER = r"""
new_scene()
bpy.ops.mesh.primitive_cube_add(location=(-2, 0, 0))
a = bpy.context.active_object
a.name = "A"
a.data.materials.append(colour_material("Red"))
bpy.ops.mesh.primitive_cube_add(location=(2, 0, 0))
b = bpy.context.active_object
b.name = "B"
b.data.materials.append(colour_material("Blue"))
def convert(obj):
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return sorted(bpy.ops.scenefit.convert())
out["converts"] = [convert(a), convert(b)]
image = a.material_slots[0].material.node_tree.nodes["SceneFit Base Color"].image
image.pixels.foreach_set(np.tile(np.array([1.0, 0.0, 1.0, 1.0], np.float32), len(image.pixels) // 4))
out["converts"].append(convert(a))
out["a"] = results(["A"])["A/0"]
out["a_behind"] = import_module(MODULE + ".operators.asset").asset_layout(bpy.context).artists[0].name
# The Results switch on B alone, though A's result came last: B's original back, A's result stays
bpy.ops.object.select_all(action="DESELECT")
b.select_set(True)
bpy.context.view_layer.objects.active = b
out["switch_b"] = [sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL")),
                   [o.material_slots[0].material.name for o in (a, b)]]
out["switch_b"].append(sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="RESULT")))
out["switch_b"].append([o.material_slots[0].material.name for o in (a, b)])
# Nothing selected: the last result's asset (A)
bpy.ops.object.select_all(action="DESELECT")
bpy.context.view_layer.objects.active = None
out["switch_last"] = [sorted(bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL")),
                      [o.material_slots[0].material.name for o in (a, b)]]
"""

# What cannot work is one sentence: faces on an empty slot, in an object and in a selection.
REFUSALS = r"""
new_scene()
bpy.ops.mesh.primitive_cube_add()
cube = bpy.context.active_object
cube.data.materials.append(colour_material("Red"))
cube.data.materials.append(None)
cube.data.polygons[0].material_index = 1
said = {}
for what in ("object", "selection"):
    if what == "selection":
        cube.location.x = 3
        bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4)
        bpy.context.active_object.data.materials.append(colour_material("Blue"))
        cube.select_set(True)
    try:
        bpy.ops.scenefit.run(guidance="none")
        said[what] = "finished"
    except RuntimeError as error:
        said[what] = str(error)
out["said"] = said
out["materials"] = sorted(m.name for m in bpy.data.materials)
"""


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("multi_material")
    zip_path, tiny, user = extension_and_models(tmp)
    with closing(PythonSession(env={"BLENDER_USER_RESOURCES": str(user)})) as session:
        session.run(fill_in(INSTALL, tmp, zip_path, tiny).replace("COLOURS_HERE", repr(COLOURS)))
        yield SimpleNamespace(run=session.run, tmp=tmp)


def step(blender, code: str) -> dict:
    out = blender.run(code)
    (blender.tmp / "out.json").write_text(json.dumps(out, default=str))  # for a look after a failure
    print({k: v for k, v in out.items() if k.startswith("seconds")})
    return out


def glb_materials(path: Path, tmp: Path) -> dict[str, list[float]]:
    """Each material of a .glb with the median stored colour of its base colour image ("_sizes": each
    image's height and width)."""
    assert path.read_bytes()[:4] == b"glTF"
    doc, binary = read_gltf(path)
    out, sizes = {}, {}
    for index, material in enumerate(doc["materials"]):
        texture = material["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        image = doc["images"][doc["textures"][texture]["source"]]
        view = doc["bufferViews"][image["bufferView"]]
        file = tmp / f"{path.stem}_{index}.png"
        file.write_bytes(binary[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]])
        pixels = read_image(file)
        out[material["name"]] = np.median(pixels[..., :3].reshape(-1, 3), axis=0).tolist()
        sizes[material["name"]] = list(pixels.shape[:2])
    out["_sizes"] = sizes
    out["_meshes"] = len(doc["meshes"])
    out["_nodes"] = sorted(n.get("name", "") for n in doc["nodes"] if "mesh" in n)
    return out


def check_slots(out: dict, expected: dict[str, str]) -> None:
    """Every slot ('Object/slot' -> the artist's material there) got a new SceneFit material of that colour."""
    got = out["results"]
    assert sorted(got) == sorted(expected)
    for key, original in expected.items():
        name, tag, colour, size = got[key]
        assert tag == "convert" and name == f"{original} SceneFit convert", got[key]   # the last stage that ran
        assert np.allclose(colour, COLOURS[original], atol=0.03), (key, original, colour)
        assert size[0] == size[1] and size[0] >= 4
    assert len({got[k][0] for k in expected}) == len(set(expected.values()))   # one result per material
    assert all(out["fake_users"].values()), out["fake_users"]


def check_switch(out: dict, expected: dict[str, str]) -> None:
    """Original restores every slot; SceneFit puts every result back."""
    for switch in ("revert", "again", "bake"):
        assert out[switch] == ["FINISHED"], out
    restored = {f"{o}/{i}": name for o, names in out["reverted"].items() for i, name in enumerate(names)}
    assert restored == expected
    back = {f"{o}/{i}": name for o, names in out["switched_back"].items() for i, name in enumerate(names)}
    assert back == {k: v[0] for k, v in out["results"].items()}


def check_glb(path: Path, tmp: Path, validator, expected: dict[str, str]) -> dict:
    report = validator(str(path))
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    found = glb_materials(path, tmp)
    # The artist's materials (the slots hold SceneFit's previews of the texture), by their names, with the
    # baked maps: their normal maps, alpha and extensions come along, as `scenefit bake` keeps a file's
    names = set(expected.values())
    assert set(found) - {"_meshes", "_nodes", "_sizes"} == names, found
    for original in names:
        assert np.allclose(found[original], COLOURS[original], atol=0.03), (original, found)
    # Each is the artist's own 24x12 image: its baked map is what the material already gave (one colour,
    # reproduced), so the artist's nodes and image are kept (BakedMaterial.unchanged), as `scenefit bake`
    # keeps a file's; it was once the texture's square atlas cell, then a resampled 32x16 copy
    assert set(map(tuple, found["_sizes"].values())) == {(12, 24)}, found["_sizes"]
    return found


def test_an_object_with_three_materials_through_run_all_and_bake_asset(blender, validator):
    out = step(blender, THREE)
    assert out["run"] == ["FINISHED"]
    assert out["stages"]["convert"] == "ran" and out["stages"]["compose"] == "ran"
    assert out["materials_in_blender"] == ["Red", "Green", "Blue"]
    expected = {"Cube/0": "Red", "Cube/1": "Green", "Cube/2": "Blue"}
    check_slots(out, expected)
    check_switch(out, expected)
    assert out["artists"] == out["artists_before"] and not any(v[3] for v in out["artists"].values())
    assert out["bake_left_session_as_it_was"]
    found = check_glb(blender.tmp / "three.glb", blender.tmp, validator, expected)
    assert found["_meshes"] == 1 and found["_nodes"] == ["Cube"]
    # Run All again: a new folder whose stages are the last run's, copied (each run redid everything before)
    assert out["run_again"] == ["FINISHED"]
    assert out["again_stages"] == {"convert": "reused", "light": "reused", "adapt": "skipped", "compose": "reused",
                                   "bake": "skipped"}, out["again_stages"]
    assert out["again_folders"] == [True, True]   # a folder of its own; the last run's left as it was


def test_a_selection_of_two_objects_through_run_all_and_bake_asset(blender, validator):
    out = step(blender, SELECTION)
    assert out["run"] == ["FINISHED"]
    assert out["materials_in_blender"] == ["Blue", "Yellow", "Red"]   # objects by name, then their slots
    expected = {"Box/0": "Red", "Ball/0": "Blue", "Ball/1": "Yellow"}
    check_slots(out, expected)
    check_switch(out, expected)
    assert out["bystander"] == ["Grey"]   # not selected: not part of the asset
    assert out["compose"] == ["FINISHED"] and out["camera_moved"][0] == out["camera_moved"][1]
    assert out["artists"] == out["artists_before"]
    assert out["bake_left_session_as_it_was"]
    found = check_glb(blender.tmp / "selection.glb", blender.tmp, validator, expected)
    assert found["_nodes"] == ["Ball", "Box"]   # the selection, not the bystander


def test_convert_takes_every_material_too(blender):
    out = step(blender, CONVERT)
    assert out["convert"] == [["FINISHED"], ["FINISHED"]] and out["revert"] == ["FINISHED"]
    for key, original in {"Cube/0": "Red", "Cube/1": "Green", "Cube/2": "Blue"}.items():
        name, tag, colour, _ = out["results"][key]
        # (the second convert's material, named after the artist's one as the first's was)
        assert tag == "convert" and name == f"{original} SceneFit convert.001", out["results"][key]
        assert np.allclose(colour, COLOURS[original], atol=0.03), (key, colour)
    assert out["reverted"] == {"Cube": ["Red", "Green", "Blue"]}


def test_adapt_and_export_take_every_material_of_the_asset(blender):
    out = step(blender, ADAPT)
    assert out["convert"] == out["adapt"] == ["FINISHED"]
    got = out["results"]
    for key, original in {"Cube/0": "Red", "Cube/1": "Green", "Cube/2": "Blue"}.items():
        name, tag, _, _ = got[key]
        assert tag == "adapt" and name.startswith(f"{original} SceneFit adapt"), got[key]
    assert len({got[k][0] for k in got}) == 3   # one result per material, each with its own maps
    assert out["lone"] == [["FINISHED"], ["FINISHED"]]
    (unused, unused_tag), (used, used_tag) = out["lone_slots"]
    assert unused.startswith("Grey") and unused_tag is None and used_tag == "adapt", out["lone_slots"]
    assert out["export"] == ["FINISHED"] and any(n.endswith(".xml") for n in out["exported"]), out["exported"]
    assert out["ply_faces"] == 12   # the cube's 12 triangles, all three materials' faces in one shape


def test_the_artists_material_is_found_after_results_on_other_objects(blender):
    out = step(blender, ONE_THEN_ANOTHER)
    assert out["converts"] == [["FINISHED"]] * 3
    name, tag, colour, _ = out["a"]
    assert tag == "convert" and name.startswith("A SceneFit convert"), out["a"]
    assert np.allclose(colour, COLOURS["Red"], atol=0.03), colour   # not the magenta of its last result
    assert out["a_behind"] == "Red"
    # The switch acts on the selected object's slots, though another object's result came last (it once
    # acted on the last job's slots only), and on the last result's asset when nothing is selected
    (done, (a_slot, b_slot)), again, (a_back, b_back) = out["switch_b"][:2], out["switch_b"][2], out["switch_b"][3]
    assert done == ["FINISHED"] and a_slot.startswith("A SceneFit convert") and b_slot == "Blue", out["switch_b"]
    assert again == ["FINISHED"] and a_back == a_slot and b_back.startswith("B SceneFit convert"), out["switch_b"]
    assert out["switch_last"] == [["FINISHED"], ["Red", b_back]], out["switch_last"]


def test_what_cannot_be_textured_is_one_sentence(blender):
    out = step(blender, REFUSALS)
    said = out["said"]
    assert "Faces of 'Cube' use material slot 2, which holds no material." in said["object"], said
    assert "The selection cannot be textured as one asset: Faces of 'Cube' use material slot 2" in said["selection"]
    assert all("Traceback" not in s and s.count(". ") == 0 for s in said.values()), said
    assert not any("SceneFit" in m for m in out["materials"])   # nothing was made


def test_bake_asset_bakes_a_texture_adapted_per_surface_into_a_new_uv_map(blender, validator):
    """Mirrored UVs (the sphere's two materials) get the new UV map on the exported copies; the cube's own
    UVs hold its result and are kept; the artist's meshes keep their UV maps."""
    out = step(blender, MIRRORED)
    assert out["layout"]["uv_layout"] == "new (xatlas)", out["layout"]
    assert out["bake"] == ["FINISHED"] and out["bake_left_session_as_it_was"]
    assert out["uv_layers_after"] == out["uv_layers_before"]
    path = blender.tmp / "mirrored.glb"
    assert validator(str(path))["issues"]["numErrors"] == 0
    doc = read_gltf(path)[0]
    coords = {m["name"]: m["pbrMetallicRoughness"]["baseColorTexture"].get("texCoord", 0) for m in doc["materials"]}
    assert coords == {"Red": 0, "Blue": 1, "Yellow": 1}, coords
    ball = next(m for m in doc["meshes"] if any(doc["materials"][p["material"]]["name"] == "Blue"
                                                 for p in m["primitives"]))
    assert all("TEXCOORD_1" in p["attributes"] for p in ball["primitives"])
