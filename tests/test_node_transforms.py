"""An asset file's node transforms are part of the asset (issue 23): a node that stands a mesh upright,
or mirrors it, places the mesh so in convert, compose and bake alike (the baked file keeps the
transforms, so reading the mesh in object space composited a rotated painting lying flat)."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytestmark = pytest.mark.blender

CHECK = r"""
import json, sys
from pathlib import Path
import numpy as np
import bpy, addon_utils

folder = Path(FOLDER)
addon_utils.enable("io_scene_gltf2", default_set=False)
bpy.ops.wm.read_factory_settings(use_empty=True)

# An asymmetric shape: a long thin slab along +X with a bump on its +Y side (its handedness shows).
bpy.ops.mesh.primitive_cube_add(size=1.0)
slab = bpy.context.active_object
slab.scale = (2.0, 0.5, 0.1)
bpy.ops.object.transform_apply(scale=True)
bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0.7, 0.4, 0.0))
bump = bpy.context.active_object
slab.select_set(True)
bpy.context.view_layer.objects.active = slab
bpy.ops.object.join()
slab.name = "Painting"
bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.select_all(action="SELECT")
bpy.ops.uv.smart_project()
bpy.ops.object.mode_set(mode="OBJECT")
slab.data.materials.append(bpy.data.materials.new("Canvas"))
raw = np.array([v.co[:] for v in slab.data.vertices])

out = {}
for name, rotation, scale in (("upright", (np.pi / 2, 0.0, 0.0), (1, 1, 1)), ("mirrored", (0, 0, 0), (-1, 1, 1))):
    slab.rotation_euler, slab.scale = rotation, scale
    bpy.context.view_layer.update()
    world = np.array(slab.matrix_world)
    bpy.ops.export_scene.gltf(filepath=str(folder / f"{name}.glb"), export_format="GLB")
    out[name] = {"expected": (raw @ world[:3, :3].T + world[:3, 3]).tolist()}

from scenefit.blender_io.asset_file import load_asset_file
for name in out:
    mesh, _ = load_asset_file(str(folder / f"{name}.glb"))
    out[name]["positions"] = np.asarray(mesh.positions).tolist()
    tri = np.asarray(mesh.positions)[np.asarray(mesh.faces)]
    geometric = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    shading = np.asarray(mesh.normals)[np.asarray(mesh.faces)].mean(axis=1)
    out[name]["outward"] = float(np.mean(np.sum(geometric * shading, axis=1) > 0))
print(json.dumps(out))
"""


def _extent(points: np.ndarray) -> np.ndarray:
    return points.max(axis=0) - points.min(axis=0)


def test_a_rotated_and_a_mirrored_node_are_read_as_the_file_places_them(tmp_path, run_py):
    proc = run_py(CHECK.replace("FOLDER", repr(str(tmp_path))), timeout=600)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    upright = out["upright"]
    got, want = np.array(upright["positions"]), np.array(upright["expected"])
    # glTF is Y-up and Blender Z-up; the importer converts, so Blender's world frame is what counts.
    np.testing.assert_allclose(np.sort(_extent(got)), np.sort(_extent(want)), atol=1e-4)
    # Stood upright: 0.8 tall in Z (the slab's width with its bump), 0.3 thin in Y (its thickness);
    # read in object space it lay flat, 0.3 in Z.
    np.testing.assert_allclose(_extent(got), _extent(want), atol=1e-4)
    np.testing.assert_allclose(_extent(got)[1:], [0.3, 0.8], atol=1e-4)
    mirrored = out["mirrored"]
    got, want = np.array(mirrored["positions"]), np.array(mirrored["expected"])
    # The bump lies on the mirrored side (-X), as the file shows it, not un-mirrored at +X.
    bump = got[np.abs(got[:, 1]) > 0.3]
    assert bump[:, 0].mean() < 0 and want[np.abs(want[:, 1]) > 0.3][:, 0].mean() < 0
    # Mirroring turns triangles inside out unless they are wound back: faces still face outwards.
    assert mirrored["outward"] == 1.0 and upright["outward"] == 1.0
