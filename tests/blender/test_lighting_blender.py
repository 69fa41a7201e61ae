"""The estimated map lights a sphere in Blender (Cycles, World nodes) from the same side as in Mitsuba."""
from __future__ import annotations


import numpy as np
import torch

from scenefit.core.render.orbit_camera import Camera
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.renderer import AssetRenderer
from scenefit.core.scene.frame import equirect_directions

from conftest import printed_json

SIZE = 32
LIGHT = np.array([1.0, -1.0, 1.0]) / np.sqrt(3.0)   # right of, towards and above the camera at azimuth 0


def lit_centroid(image: np.ndarray) -> np.ndarray:
    """(x, y) of the luminance-weighted centroid of the pixels brighter than the background, from the centre."""
    lum = image[..., :3].mean(-1)
    weight = np.maximum(lum - np.quantile(lum, 0.5), 0.0)
    ys, xs = np.mgrid[0:lum.shape[0], 0:lum.shape[1]]
    c = np.array([(weight * (xs + 0.5)).sum(), (weight * (ys + 0.5)).sum()]) / weight.sum()
    return c - np.array(lum.shape[::-1]) / 2


def test_estimated_map_lights_a_sphere_from_the_same_side_in_blender_and_mitsuba(tmp_path, run_py):
    env = np.full((32, 64, 3), 0.02, np.float32)
    env[equirect_directions(32, 64) @ LIGHT > np.cos(np.radians(15))] = 100.0
    write_image(tmp_path / "light.exr", env, dtype="float")
    camera = Camera(width=SIZE, height=SIZE)

    # Mitsuba: a grey rough sphere of radius 0.5 at the origin.
    tex = (4, 4)
    renderer = AssetRenderer(uv_sphere(), tex, env)
    mitsuba = renderer.render(camera, torch.full((*tex, 3), 0.8), torch.ones(*tex, 1), torch.zeros(*tex, 1),
                              torch.from_numpy(env), spp=32, seed=0).rgb.numpy()

    # Blender: the same sphere and camera, lit by a World made by blender_io.world from the EXR.
    proc = run_py(f"""
        import json, math
        import bpy, addon_utils, mathutils
        addon_utils.enable('cycles')
        bpy.ops.wm.read_factory_settings(use_empty=True)
        from scenefit.blender_io.world import assign_world, world_from_hdr
        scene = bpy.context.scene
        mine = bpy.data.worlds.new("User World")
        mine.use_nodes = True
        scene.world = mine
        before = (mine.name, len(mine.node_tree.nodes))
        world = world_from_hdr({str(tmp_path / 'light.exr')!r})
        assign_world(scene, world)
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        mat = bpy.data.materials.new("grey")
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
        bsdf.inputs["Roughness"].default_value = 1.0
        bpy.context.object.data.materials.append(mat)
        cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
        scene.collection.objects.link(cam)
        scene.camera = cam
        cam.location = {camera.origin.tolist()}
        cam.rotation_euler = mathutils.Vector({camera.forward.tolist()}).to_track_quat('-Z', 'Y').to_euler()
        cam.data.sensor_fit = 'HORIZONTAL'
        cam.data.angle = math.radians({camera.fov_deg})
        scene.render.engine = 'CYCLES'
        scene.cycles.device = 'CPU'
        scene.cycles.samples = 16
        scene.cycles.use_denoising = False
        scene.render.resolution_x = scene.render.resolution_y = {SIZE}
        scene.render.resolution_percentage = 100
        scene.render.image_settings.file_format = 'OPEN_EXR'
        scene.render.filepath = {str(tmp_path / 'cycles.exr')!r}
        bpy.ops.render.render(write_still=True)
        print("JSON" + json.dumps({{"before": before, "after": (mine.name, len(mine.node_tree.nodes)),
                                    "fake_user": mine.use_fake_user, "world": scene.world.name,
                                    "nodes": sorted(n.bl_idname for n in world.node_tree.nodes)}}))
    """)
    info = printed_json(proc)
    assert info["before"] == info["after"] and info["fake_user"]     # the user's world is untouched and kept
    assert info["world"] == "SceneFit Light"
    assert info["nodes"] == ["ShaderNodeBackground", "ShaderNodeMapping", "ShaderNodeOutputWorld",
                             "ShaderNodeTexCoord", "ShaderNodeTexEnvironment"]
    cycles = read_image(tmp_path / "cycles.exr")[..., :3]

    a, b = lit_centroid(mitsuba), lit_centroid(cycles)
    # Lit from the upper right in both (image x right, y down) ...
    assert a[0] > 2 and a[1] < -2, a
    assert b[0] > 2 and b[1] < -2, b
    # ... and at the same place within a couple of pixels of a 32-pixel render.
    assert np.linalg.norm(a - b) < 2.5, (a, b)
