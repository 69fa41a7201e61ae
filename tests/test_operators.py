"""The Blender operators against calling core directly, in a real bpy session."""
import json

import numpy as np
import pytest

from scenefit.core.imageio import read_image

pytestmark = pytest.mark.blender

SCRIPT = r"""
import json, sys
from pathlib import Path
import numpy as np
import bpy
import scenefit
from scenefit.blender_io import maps_from_material, mesh_from_object
from scenefit.core.presets import stage_config
from scenefit.core.pipeline import convert_and_bake

tmp = Path(sys.argv[1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scenefit.register()

bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
obj = bpy.context.active_object
rng = np.random.default_rng(0)
image = bpy.data.images.new("asset_color", 32, 32, alpha=True)
pixels = np.ones((32, 32, 4), np.float32); pixels[..., :3] = rng.uniform(0.1, 0.9, (32, 32, 3))
image.pixels.foreach_set(pixels.ravel())
mat = bpy.data.materials.new("AssetMaterial")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
tex = nodes.new("ShaderNodeTexImage"); tex.image = image
links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
obj.data.materials.append(mat)
settings = bpy.context.scene.scenefit
settings.preset = "draft"
settings.output_dir = str(tmp / "blender_out") + "/"
pixels_before = list(image.pixels)

out = {}
out["export"] = list(bpy.ops.scenefit.export_mitsuba(directory=str(tmp / "mitsuba")))
out["convert"] = list(bpy.ops.scenefit.convert())
out["active_material"] = obj.active_material.name
out["original_kept"] = "AssetMaterial" in bpy.data.materials and list(image.pixels) == pixels_before
out["new_images"] = sorted(n.image.filepath for n in obj.active_material.node_tree.nodes if n.type == "TEX_IMAGE")

# The same conversion through core directly.
mesh = mesh_from_object(obj, bpy.context.evaluated_depsgraph_get())
_, report = convert_and_bake(mesh, maps_from_material(mat), tmp / "direct", stage_config("convert", "draft"))
out["direct"] = report["outputs"]
scenefit.unregister()
print("JSON" + json.dumps(out))
"""


@pytest.fixture(scope="module")
def operated(run_py, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("operators")
    proc = run_py(SCRIPT.replace("sys.argv[1]", repr(str(tmp))))
    line = next(l for l in proc.stdout.splitlines() if l.startswith("JSON"))
    return tmp, json.loads(line[4:])


def test_export_operator_writes_a_mitsuba_scene(operated):
    tmp, out = operated
    assert out["export"] == ["FINISHED"]
    assert {p.name for p in (tmp / "mitsuba").iterdir()} >= {"scene.xml", "mesh.ply", "base_color.png"}


def test_convert_operator_matches_core_and_keeps_the_original(operated):
    tmp, out = operated
    assert out["convert"] == ["FINISHED"]
    assert out["active_material"] != "AssetMaterial" and out["original_kept"]
    made = sorted((tmp / "blender_out").rglob("base_color.png"))
    assert len(made) == 1 and any(str(made[0]) in path for path in out["new_images"])
    operator_map = read_image(made[0])
    direct_map = read_image(out["direct"]["base_color"])
    assert operator_map.shape == direct_map.shape == (32, 32, 3)
    assert np.abs(operator_map - direct_map).max() <= 1 / 255 + 1e-6
