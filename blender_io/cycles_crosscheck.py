"""core/stages/compose.py's scene rebuilt in Blender for Cycles, to cross-check the Mitsuba composite: the
photo camera, the light map as a new World, the placed asset, a floor and a transparent film
(tests/blender/test_compose_cycles.py compares the two). The artist-facing set-up (camera around the
asset, photo behind, shadow catcher) is blender_io/compose.py.

Cycles renders three passes: the asset alone (floor hidden) over nothing, and the floor with and
without the asset's shadow: the asset stays in the scene but invisible to camera rays
(`visible_camera = False`), so it blocks light and shows nowhere. Their ratio is the shadow matte,
what a shadow catcher computes. (`is_shadow_catcher` with a transparent film wrote neither a shadow
into the alpha nor a Shadow Catcher pass in the bpy 5.0 module we tried, so the matte is taken
from the two floor renders instead.) The photo goes behind in numpy, as Blender's Alpha Over does.

Geometry is core's: the camera stands CAMERA_HEIGHT above the floor z = 0 looking along the
PhotoCamera's forward with its up (horizontal field of view), and the asset is the mesh
core.scene.asset_pose.placed_mesh returns (already in world space).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core.data.mesh import Mesh
from ..core.scene.camera import CAMERA_HEIGHT, PhotoCamera
from .compose import camera_rotation, new_plane, transparent_cycles
from .material import write_result_material
from .world import assign_world, world_from_hdr


def object_from_mesh(mesh: Mesh, name: str = "SceneFit Asset"):
    """A NEW object with the mesh's triangles, UVs and smooth shading, linked to the scene."""
    import bpy

    data = bpy.data.meshes.new(name)
    data.from_pydata(mesh.positions.tolist(), [], mesh.faces.tolist())
    uv = data.uv_layers.new(name="UVMap")
    loops = mesh.faces.reshape(-1)
    uv.data.foreach_set("uv", mesh.uvs[loops].astype(np.float32).ravel())
    data.shade_smooth()
    data.update()
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def photo_camera_object(camera: PhotoCamera, name: str = "SceneFit Photo Camera"):
    """A NEW camera object matching the photo camera (and made the scene's camera)."""
    import bpy
    import mathutils

    forward, _, up, _, _ = camera.basis()
    cam = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (0.0, 0.0, CAMERA_HEIGHT)
    cam.matrix_world = mathutils.Matrix.Translation(cam.location) @ camera_rotation(forward, up).to_4x4()
    cam.data.sensor_fit = "HORIZONTAL"
    cam.data.angle = math.radians(camera.fov_deg)
    scene = bpy.context.scene
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = camera.width, camera.height
    scene.render.resolution_percentage = 100
    return cam


def floor_plane(size: float = 2000.0, name: str = "SceneFit Floor"):
    """A NEW white diffuse plane on z = 0 (its albedo cancels in the shadow ratio)."""
    import bpy

    obj = new_plane(name, size / 2)
    data = obj.data
    bpy.context.scene.collection.objects.link(obj)
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    data.materials.append(mat)
    return obj


def composite_scene(mesh: Mesh, maps_paths: dict, light_exr: str | Path, camera: PhotoCamera, samples: int = 64):
    """Set up the current scene for the composite render (Cycles, transparent film); returns the objects."""
    import bpy

    scene = bpy.context.scene
    transparent_cycles(scene)   # linear radiance out, as Mitsuba's
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    assign_world(scene, world_from_hdr(light_exr))
    asset = object_from_mesh(mesh)
    write_result_material(asset, maps_paths, name="SceneFit Asset Material")
    floor = floor_plane()
    cam = photo_camera_object(camera)
    return {"asset": asset, "floor": floor, "camera": cam}


def render_passes(objects: dict, out_dir: str | Path) -> dict[str, str]:
    """object.exr (asset over nothing), floor_with.exr and floor_without.exr (the floor with and without
    the asset's shadow, asset invisible to the camera); returns their paths."""
    import bpy

    scene = bpy.context.scene
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    asset, floor = objects["asset"], objects["floor"]
    paths = {}
    for name, floor_on, asset_on, asset_seen in (("object", False, True, True), ("floor_with", True, True, False),
                                                 ("floor_without", True, False, False)):
        floor.hide_render = not floor_on
        asset.hide_render = not asset_on
        asset.visible_camera = asset_seen
        scene.render.filepath = str(Path(out_dir) / f"{name}.exr")
        bpy.ops.render.render(write_still=True)
        paths[name] = scene.render.filepath
    return paths
