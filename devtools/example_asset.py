"""The demo's example asset, made by Blender itself (development only: it resets Blender's open file): a UV-unwrapped Suzanne with a procedural
material baked by Cycles into image maps, saved as a folder core reads without bpy."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..blender_io.material import image_pixels_linear
from ..blender_io.mesh import mesh_from_object
from ..core.data.asset_io import save_asset_folder
from ..core.data.maps import PBRMaps

EXAMPLE_SIZE = 512


def _procedural_material(bpy):
    """Noise through a two-colour ramp for base colour, Voronoi for roughness, metallic 0."""
    mat = bpy.data.materials.new("SceneFitExample")
    if mat.node_tree is None:  # Blender 4.x
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Metallic"].default_value = 0.0

    coords = nodes.new("ShaderNodeTexCoord")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 4.0
    noise.inputs["Detail"].default_value = 6.0
    links.new(coords.outputs["Object"], noise.inputs["Vector"])
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = 0.35, 0.65
    ramp.color_ramp.elements[0].color = (0.60, 0.16, 0.05, 1.0)  # terracotta
    ramp.color_ramp.elements[1].color = (0.05, 0.35, 0.40, 1.0)  # teal
    links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])

    voronoi = nodes.new("ShaderNodeTexVoronoi")
    voronoi.inputs["Scale"].default_value = 8.0
    links.new(coords.outputs["Object"], voronoi.inputs["Vector"])
    to_rough = nodes.new("ShaderNodeMapRange")
    to_rough.inputs["To Min"].default_value, to_rough.inputs["To Max"].default_value = 0.25, 0.85
    links.new(voronoi.outputs["Distance"], to_rough.inputs["Value"])
    links.new(to_rough.outputs["Result"], bsdf.inputs["Roughness"])
    return mat


def _bake(bpy, obj, mat, bake_type: str, size: int, margin: int) -> np.ndarray:
    image = bpy.data.images.new(f"bake_{bake_type.lower()}", size, size, alpha=False, float_buffer=True)
    target = mat.node_tree.nodes.new("ShaderNodeTexImage")
    target.image = image
    mat.node_tree.nodes.active = target  # Cycles bakes into the active Image Texture node
    kwargs = {"pass_filter": {"COLOR"}} if bake_type == "DIFFUSE" else {}
    bpy.ops.object.bake(type=bake_type, margin=margin, use_clear=True, **kwargs)
    pixels = image_pixels_linear(image)
    mat.node_tree.nodes.remove(target)
    bpy.data.images.remove(image)
    return pixels


def make_example_asset(out_dir: str | Path, size: int = EXAMPLE_SIZE, samples: int = 4) -> dict[str, Path]:
    """Build the example with Blender and write it to `out_dir`; returns the written paths.

    Files: mesh.npz (positions, faces, uvs, normals as core.mesh.Mesh), base_color.png (sRGB),
    roughness.png (linear, 16-bit), material.json (metallic constant). Starts from an empty factory
    file, so it is meant for headless Blender (tests, tools), not for a session with unsaved work.
    """
    import bpy
    import addon_utils  # on sys.path once bpy is imported

    out_dir = Path(out_dir)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon_utils.enable("cycles", default_set=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.bake.margin_type = "EXTEND"

    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.active_object
    obj.name = "Suzanne"
    modifier = obj.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = 1
    bpy.ops.object.modifier_apply(modifier=modifier.name)
    bpy.ops.object.shade_smooth()
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(angle_limit=np.radians(66.0), island_margin=0.02)
    bpy.ops.object.mode_set(mode="OBJECT")

    mat = _procedural_material(bpy)
    obj.data.materials.append(mat)
    margin = max(4, size // 64)
    base_color = _bake(bpy, obj, mat, "DIFFUSE", size, margin)[..., :3]
    roughness = _bake(bpy, obj, mat, "ROUGHNESS", size, margin)[..., 0]

    mesh = mesh_from_object(obj, bpy.context.evaluated_depsgraph_get())
    maps = PBRMaps(base_color=np.clip(base_color, 0.0, 1.0), roughness=np.clip(roughness, 0.0, 1.0), metallic=0.0)
    save_asset_folder(mesh, maps, out_dir)
    return {name: out_dir / name for name in ("mesh.npz", "base_color.png", "roughness.png", "material.json")}
