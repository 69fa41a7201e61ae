"""blender_io: Blender data -> core arrays (exact on known data), originals untouched, example asset."""

import numpy as np
import pytest

from scenefit.core.data.asset_io import load_asset_folder

from conftest import printed_json

pytestmark = pytest.mark.blender

EXTRACT = r"""
import json, sys
import numpy as np
import bpy
from scenefit.blender_io import maps_from_material, mesh_from_object, write_result_material
from scenefit.core.base.errors import InputError

bpy.ops.wm.read_factory_settings(use_empty=True)
out = {}

# A 2x2 plane at (1, 2, 3): Blender's primitive has UVs (0,0)..(1,1) matching x, y in [-1, 1].
bpy.ops.mesh.primitive_plane_add(size=2.0, location=(1.0, 2.0, 3.0))
plane = bpy.context.active_object
depsgraph = bpy.context.evaluated_depsgraph_get()
mesh = mesh_from_object(plane, depsgraph)
world = mesh_from_object(plane, depsgraph, space="world")
out["plane"] = {k: getattr(mesh, k).tolist() for k in ("positions", "faces", "uvs", "normals")}
out["plane_world"] = world.positions.tolist()

# 8-bit sRGB base colour with known bytes, Non-Color roughness, constant metallic.
color = bpy.data.images.new("known_color", 2, 2, alpha=True)
color.colorspace_settings.name = "sRGB"
bytes_ = np.array([[[0, 64, 128, 255], [255, 0, 0, 255]], [[0, 255, 0, 255], [10, 20, 30, 255]]], np.float32) / 255
color.pixels.foreach_set(bytes_.ravel())  # Blender rows: first row is the bottom one
rough = bpy.data.images.new("known_rough", 2, 2, alpha=False)
rough.colorspace_settings.name = "Non-Color"
rough.pixels.foreach_set(np.repeat(np.array([0.2, 0.4, 0.6, 0.8], np.float32), 4))
mat = bpy.data.materials.new("Known")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bsdf = nodes["Principled BSDF"]
for image, socket in ((color, "Base Color"), (rough, "Roughness")):
    tex = nodes.new("ShaderNodeTexImage"); tex.image = image
    links.new(tex.outputs["Color"], bsdf.inputs[socket])
bsdf.inputs["Metallic"].default_value = 0.3
plane.data.materials.append(mat)
nodes_before = sorted(n.name for n in nodes)
pixels_before = list(color.pixels)

maps = maps_from_material(mat)
out["base_color"] = maps.base_color.tolist()
out["roughness"] = maps.roughness.tolist()
out["metallic"] = maps.metallic
out["untouched"] = (sorted(n.name for n in nodes) == nodes_before and list(color.pixels) == pixels_before
                    and len(plane.data.vertices) == 4 and len(plane.data.polygons) == 1
                    and len(bpy.data.meshes) == 1 and plane.active_material == mat)

# Default cube: flat faces, one UV island per face -> 24 split vertices, 12 triangles.
bpy.ops.mesh.primitive_cube_add()
cube = mesh_from_object(bpy.context.active_object, bpy.context.evaluated_depsgraph_get())
out["cube"] = [len(cube.positions), len(cube.faces)]

# Bad input gets a sentence, not a traceback.
errors = {}
bpy.ops.mesh.primitive_plane_add()
bare = bpy.context.active_object
bare.data.uv_layers.remove(bare.data.uv_layers[0])
bare.data.update()  # tag it, so the depsgraph re-evaluates
# No UV map at all: read with every corner at (0, 0) (its material's plain colour), the mesh untouched.
no_uv = mesh_from_object(bare, bpy.context.evaluated_depsgraph_get())
out["no_uv"] = [float(abs(no_uv.uvs).max()), len(no_uv.faces), len(bare.data.uv_layers)]
try:
    maps_from_material(None)
except InputError as e:
    errors["no_material"] = str(e)
emit = bpy.data.materials.new("Emission")
emit.node_tree.nodes.remove(emit.node_tree.nodes["Principled BSDF"])
try:
    maps_from_material(emit)
except InputError as e:
    errors["no_bsdf"] = str(e)
out["errors"] = errors

# Results go into a new material; the original survives with a fake user.
new = write_result_material(plane, {"base_color": sys.argv[1], "roughness": 0.7, "metallic": 0.0})
out["result"] = {"new": new.name, "active": plane.active_material.name, "old_kept": mat.name in bpy.data.materials,
                 "old_fake_user": mat.use_fake_user, "rough": new.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value,
                 "images": [n.image.name for n in new.node_tree.nodes if n.type == "TEX_IMAGE"]}
print("JSON" + json.dumps(out))
"""


@pytest.fixture(scope="module")
def extracted(run_py, tmp_path_factory):
    from scenefit.core.data.imageio import write_image

    png = tmp_path_factory.mktemp("result") / "base_color.png"
    write_image(png, np.full((4, 4, 3), 0.5, np.float32))
    proc = run_py(EXTRACT.replace("sys.argv[1]", repr(str(png))))
    return printed_json(proc)


def _srgb_to_linear(x):
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def test_plane_mesh_arrays_are_exact(extracted):
    p = np.array(extracted["plane"]["positions"])
    uv = np.array(extracted["plane"]["uvs"])
    faces = np.array(extracted["plane"]["faces"])
    assert p.shape == (4, 3) and faces.shape == (2, 3) and uv.shape == (4, 2)
    # object space: the corners of the 2x2 square; UVs are (x+1)/2, (y+1)/2
    np.testing.assert_array_equal(np.sort(np.abs(p[:, :2]).ravel()), np.ones(8))
    np.testing.assert_array_equal(p[:, 2], 0.0)
    np.testing.assert_allclose(uv, (p[:, :2] + 1.0) / 2.0, atol=1e-6)
    np.testing.assert_allclose(np.array(extracted["plane"]["normals"]), [[0, 0, 1]] * 4, atol=1e-6)
    # both triangles face +z (counter-clockwise seen from above)
    e1, e2 = p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]]
    assert (np.cross(e1, e2)[:, 2] > 0).all()
    np.testing.assert_allclose(np.array(extracted["plane_world"]), p + [1.0, 2.0, 3.0], atol=1e-6)


def test_cube_splits_at_uv_and_normal_seams(extracted):
    assert extracted["cube"] == [24, 12]


def test_material_maps_are_linear_and_top_to_bottom(extracted):
    bc = np.array(extracted["base_color"])
    # Blender's first pixel row is the bottom one; PBRMaps rows run top to bottom.
    stored_top_to_bottom = np.array([[[0, 255, 0], [10, 20, 30]], [[0, 64, 128], [255, 0, 0]]]) / 255
    np.testing.assert_allclose(bc, _srgb_to_linear(stored_top_to_bottom), atol=1e-6)
    np.testing.assert_allclose(np.array(extracted["roughness"]), [[0.6, 0.8], [0.2, 0.4]], atol=1e-6)
    assert extracted["metallic"] == pytest.approx(0.3)


def test_extraction_leaves_blender_data_untouched(extracted):
    assert extracted["untouched"] is True


def test_bad_input_raises_input_error_with_a_fix(extracted):
    errors = extracted["errors"]
    assert extracted["no_uv"] == [0.0, 2, 0]   # a plane without UVs: read at (0, 0), no UV map added
    assert "has no material" in errors["no_material"]
    assert "Principled BSDF" in errors["no_bsdf"]


def test_result_material_is_new_and_original_kept(extracted):
    r = extracted["result"]
    assert r["new"] != "Known" and r["active"] == r["new"]
    assert r["old_kept"] and r["old_fake_user"]
    assert r["rough"] == pytest.approx(0.7) and len(r["images"]) == 1


def test_example_asset_files_and_shapes(example_asset):
    for name in ("mesh.npz", "base_color.png", "roughness.png", "material.json"):
        assert (example_asset / name).is_file(), name
    mesh, maps = load_asset_folder(example_asset)
    assert mesh.positions.shape[1] == 3 and len(mesh.positions) > 2000 and len(mesh.faces) > 3000
    assert mesh.uvs.shape == (len(mesh.positions), 2) and mesh.normals.shape == mesh.positions.shape
    assert 0.0 <= mesh.uvs.min() and mesh.uvs.max() <= 1.0
    assert maps.base_color.shape == (512, 512, 3) and maps.roughness.shape == (512, 512)
    assert maps.metallic == 0.0
    # the procedural material is actually baked: covered texels vary in colour and roughness
    covered = maps.base_color.sum(axis=2) > 0
    assert 0.4 < covered.mean() < 0.95
    assert maps.base_color[covered].std(axis=0).min() > 0.02
    assert 0.25 - 0.02 <= maps.roughness[covered].min() and maps.roughness[covered].max() <= 0.85 + 0.02


def test_operators_take_the_materials_the_faces_use(run_py):
    proc = run_py("""
        import json
        import bpy
        from scenefit.operators.asset import asset_layout

        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.mesh.primitive_cube_add()
        obj = bpy.context.active_object
        unused, used = bpy.data.materials.new("Unused"), bpy.data.materials.new("Painted")
        obj.data.materials.append(unused)
        obj.data.materials.append(used)
        for face in obj.data.polygons:
            face.material_index = 1
        obj.active_material_index = 0                      # the active slot is not the one the faces use
        layout = asset_layout(bpy.context)
        out = {"one": [m.name for m in layout.materials], "slots": layout.slots}
        obj.data.polygons[0].material_index = 0            # now the faces use two materials: both are the asset's
        out["two"] = [m.name for m in asset_layout(bpy.context).materials]
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    assert out["one"] == ["Painted"] and out["slots"] == [[["Cube", 1]]]
    assert out["two"] == ["Unused", "Painted"]


def test_a_bake_limit_shrinks_only_the_procedural_chains_it_caps(run_py):
    """A bake reads a material's procedural chains at no more than its size, and says which channels it
    shrank (those are never written as the material's own nodes): a 64² image material whose roughness is
    a noise chain, read for a 16² bake, then for a 128² one."""
    proc = run_py("""
        import json
        import bpy
        import numpy as np
        from scenefit.blender_io.material import read_material_within

        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.mesh.primitive_plane_add()
        obj = bpy.context.active_object
        material = bpy.data.materials.new("Painted Noise")
        material.use_nodes = True
        nodes, links = material.node_tree.nodes, material.node_tree.links
        bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
        image = bpy.data.images.new("paint", 64, 64)
        image.pixels.foreach_set(np.random.default_rng(0).uniform(0.2, 0.8, 64 * 64 * 4).astype(np.float32))
        texture = nodes.new("ShaderNodeTexImage")
        texture.image = image
        links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
        links.new(nodes.new("ShaderNodeTexNoise").outputs["Fac"], bsdf.inputs["Roughness"])
        obj.data.materials.append(material)
        out = {}
        for limit in (16, 128):
            read, shrunk = read_material_within(material, obj, 0, limit)
            out[limit] = [sorted(shrunk), list(np.shape(read.maps.roughness)), list(np.shape(read.maps.base_color))]
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    assert out["16"] == [["roughness"], [16, 16], [64, 64, 3]]   # the chain at the bake's size, the image as it is
    assert out["128"] == [[], [64, 64], [64, 64, 3]]             # no cap below the image: nothing shrunk
