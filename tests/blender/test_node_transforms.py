"""An asset file's node transforms are part of the asset: a node that stands a mesh upright,
or mirrors it, places the mesh so in convert, compose and bake alike (the baked file keeps the
transforms, so reading the mesh in object space composited a rotated painting lying flat)."""
from __future__ import annotations


import numpy as np
import pytest

from conftest import printed_json

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
print("JSON" + json.dumps(out))
"""


def _extent(points: np.ndarray) -> np.ndarray:
    return points.max(axis=0) - points.min(axis=0)


def test_a_rotated_and_a_mirrored_node_are_read_as_the_file_places_them(tmp_path, run_py):
    proc = run_py(CHECK.replace("FOLDER", repr(str(tmp_path))), timeout=600)
    out = printed_json(proc)
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


COMPOSE_CHECK = r"""
import json
from pathlib import Path
import numpy as np
import bpy, addon_utils, mathutils
from scenefit.blender_io.asset_file import load_asset_file
from scenefit.blender_io.compose import transparent_cycles
from scenefit.blender_io.cycles_crosscheck import photo_camera_object
from scenefit.core.stages.compose import ComposeConfig, ComposeInputs, build_compose
from scenefit.core.data.mesh import normalize_to_unit_sphere
from scenefit.core.render.environment import sun_environment
from scenefit.core.scene.asset_pose import placement_transform
from scenefit.core.scene.camera import PhotoCamera

folder = Path(FOLDER)
camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-15.0, fov_deg=50.0, width=160, height=120)
env = sun_environment([0.4, -0.5, 0.8], sun_radiance=200.0, sky_radiance=0.5)
out = {}
for name in ("upright", "mirrored"):
    glb = str(folder / f"{name}.glb")
    # The pipeline's composite of the file, as `scenefit run FILE` makes it (the mesh in world space).
    mesh, _ = load_asset_file(glb)
    maps = np.full((8, 8, 5), 0.5, np.float32)
    job = build_compose(ComposeInputs(mesh, maps, np.full((120, 160, 3), 0.5, np.float32), (80.0, 100.0), env,
                                      camera), ComposeConfig(size=0.5, spp=8, shadow_type="none", denoiser_type="none"))
    while not job.done:
        job.step()
    alpha = job.finish().alpha
    # Cycles renders the file as Blender imports it, moved by the same similarity the pipeline applied.
    normalized, norm = normalize_to_unit_sphere(mesh)
    rotation, scale, offset = placement_transform(normalized, job.placement)
    linear = rotation * scale / norm.scale
    similarity = np.eye(4)
    similarity[:3, :3], similarity[:3, 3] = linear, offset - linear @ norm.center
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon_utils.enable("io_scene_gltf2", default_set=False)
    bpy.ops.import_scene.gltf(filepath=glb)
    holder = bpy.data.objects.new("Placed", None)
    bpy.context.scene.collection.objects.link(holder)
    for obj in [o for o in bpy.context.scene.objects if o.parent is None and o is not holder]:
        obj.parent = holder
    holder.matrix_world = mathutils.Matrix(similarity.tolist())
    scene = bpy.context.scene
    transparent_cycles(scene)
    scene.cycles.samples = 4
    photo_camera_object(camera)
    scene.render.image_settings.file_format, scene.render.image_settings.color_mode = "PNG", "RGBA"
    scene.render.filepath = str(folder / f"{name}_cycles.png")
    bpy.ops.render.render(write_still=True)
    np.save(folder / f"{name}_mitsuba.npy", alpha)
print("DONE")
"""


def test_a_rotated_and_a_mirrored_node_composite_as_cycles_renders_the_imported_file(tmp_path, run_py):
    """The pipeline's composite of a file with a rotated and a mirrored node shows the asset
    where and as Cycles shows Blender's own import of that file (silhouette IoU >= 0.95)."""
    from scenefit.core.data.imageio import read_image

    run_py(CHECK.replace("FOLDER", repr(str(tmp_path))), timeout=600)   # writes upright.glb and mirrored.glb
    run_py(COMPOSE_CHECK.replace("FOLDER", repr(str(tmp_path))), timeout=600)
    for name in ("upright", "mirrored"):
        mitsuba = np.load(tmp_path / f"{name}_mitsuba.npy") > 0.5
        cycles = read_image(tmp_path / f"{name}_cycles.png")[..., 3] > 0.5
        assert cycles.sum() > 300, name
        iou = (mitsuba & cycles).sum() / (mitsuba | cycles).sum()
        assert iou >= 0.95, (name, iou)   # measured 0.998 upright, 0.995 mirrored; 0.80 with the mirror dropped
