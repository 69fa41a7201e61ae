"""Test assets made by Blender itself and written by its glTF, OBJ and FBX exporters (run inside a
subprocess with bpy). Textures are smooth patterns with known values, small except one 2048²."""
from __future__ import annotations

from pathlib import Path

import numpy as np

SIZE = 64
BIG = 2048


def _pattern(size: int, seed: int) -> np.ndarray:
    """(size, size, 3) smooth values in [0.1, 0.9], different per seed."""
    y, x = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="ij")
    out = []
    for c in range(3):
        f = 1 + (seed + c) % 2
        out.append(0.5 + 0.4 * np.sin(2 * np.pi * f * x + seed + c) * np.cos(np.pi * y + 0.3 * c))
    return np.stack(out, axis=2).astype(np.float32)


def _image(bpy, folder: Path, name: str, rgba: np.ndarray, colorspace: str):
    """An 8-bit image saved as PNG (rows of `rgba` run top to bottom)."""
    h, w = rgba.shape[:2]
    image = bpy.data.images.new(name, w, h, alpha=True)
    image.colorspace_settings.name = colorspace
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], dtype=np.float32).ravel())
    image.filepath_raw = str(folder / f"{name}.png")
    image.file_format = "PNG"
    image.save()
    return image


def _rgba(rgb: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    a = np.ones(rgb.shape[:2], np.float32) if alpha is None else alpha
    return np.concatenate([rgb, a[..., None]], axis=2)


def _sphere(bpy, name: str):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    obj = bpy.context.active_object
    obj.name = name
    bpy.ops.object.shade_smooth()
    return obj


def _material(bpy, name: str):
    mat = bpy.data.materials.new(name)
    return mat, mat.node_tree.nodes, mat.node_tree.links, mat.node_tree.nodes["Principled BSDF"]


def _texture(nodes, image):
    node = nodes.new("ShaderNodeTexImage")
    node.image = image
    return node


def _base_and_packed(bpy, folder: Path, name: str, seed: int, size: int = SIZE, alpha=None):
    """A material with an sRGB base colour and a packed (R occlusion, G roughness, B metallic) image."""
    mat, nodes, links, bsdf = _material(bpy, name)
    base = _texture(nodes, _image(bpy, folder, f"{name}_base", _rgba(_pattern(size, seed), alpha), "sRGB"))
    links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
    orm = _pattern(SIZE, seed + 7)
    packed = _texture(nodes, _image(bpy, folder, f"{name}_orm", _rgba(orm), "Non-Color"))
    separate = nodes.new("ShaderNodeSeparateColor")
    links.new(packed.outputs["Color"], separate.inputs["Color"])
    links.new(separate.outputs["Green"], bsdf.inputs["Roughness"])
    links.new(separate.outputs["Blue"], bsdf.inputs["Metallic"])
    return mat, nodes, links, bsdf, base


def _export_gltf(bpy, path: Path, obj) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", use_selection=True)


def _fresh(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)


def build_assets(folder: str | Path) -> dict[str, str]:
    """Write every test asset into `folder`; returns {name: path}."""
    import bpy
    import addon_utils  # on sys.path once bpy is imported

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out: dict[str, str] = {}

    def gltf(name: str, build) -> None:
        _fresh(bpy)
        addon_utils.enable("io_scene_gltf2", default_set=False)
        obj = build()
        path = folder / f"{name}.glb"
        _export_gltf(bpy, path, obj)
        out[name] = str(path)

    def textured():
        """Packed ORM image (R occlusion, G roughness, B metallic), a normal map and an emissive map."""
        obj = _sphere(bpy, "Textured")
        mat, nodes, links, bsdf, _ = _base_and_packed(bpy, folder, "Textured", 1)
        # Bumps on the left half of the UV square (ripples along u), flat on the right half.
        y, x = np.meshgrid(np.linspace(0, 1, SIZE), np.linspace(0, 1, SIZE), indexing="ij")
        tilt = np.where(x < 0.5, 0.6 * np.sin(2 * np.pi * 8 * x), 0.0)
        n = np.stack([tilt, np.zeros_like(tilt), np.ones_like(tilt)], axis=2)
        n /= np.linalg.norm(n, axis=2, keepdims=True)
        tex = _texture(nodes, _image(bpy, folder, "Textured_normal", _rgba((n * 0.5 + 0.5).astype(np.float32)),
                                     "Non-Color"))
        normal = nodes.new("ShaderNodeNormalMap")
        links.new(tex.outputs["Color"], normal.inputs["Color"])
        links.new(normal.outputs["Normal"], bsdf.inputs["Normal"])
        glow = _texture(nodes, _image(bpy, folder, "Textured_emissive", _rgba(_pattern(SIZE, 9) * 0.5), "sRGB"))
        links.new(glow.outputs["Color"], bsdf.inputs["Emission Color"])
        bsdf.inputs["Emission Strength"].default_value = 1.0
        # Occlusion the way the glTF importer keeps it: a "glTF Material Output" group's Occlusion input.
        group = bpy.data.node_groups.new("glTF Material Output", "ShaderNodeTree")
        group.interface.new_socket(name="Occlusion", in_out="INPUT", socket_type="NodeSocketFloat")
        settings = nodes.new("ShaderNodeGroup")
        settings.node_tree = group
        separate = next(n for n in nodes if n.type == "SEPARATE_COLOR")
        links.new(separate.outputs["Red"], settings.inputs["Occlusion"])
        obj.data.materials.append(mat)
        return obj

    def two_materials():
        """Two materials on one mesh, each in its own (overlapping) UV layout: one blended, one cut out."""
        obj = _sphere(bpy, "TwoMaterials")
        y, x = np.meshgrid(np.linspace(0, 1, SIZE), np.linspace(0, 1, SIZE), indexing="ij")
        alpha = (0.2 + 0.8 * x).astype(np.float32)
        upper, nodes, links, bsdf, base = _base_and_packed(bpy, folder, "Upper", 3, alpha=alpha)
        upper.surface_render_method = "BLENDED"
        links.new(base.outputs["Alpha"], bsdf.inputs["Alpha"])
        lower, nodes, links, bsdf, base = _base_and_packed(bpy, folder, "Lower", 4, alpha=alpha)
        less = nodes.new("ShaderNodeMath")  # cut-out at 0.5, wired as the glTF importer does
        less.operation = "LESS_THAN"
        less.inputs[1].default_value = 0.5
        one_minus = nodes.new("ShaderNodeMath")
        one_minus.operation = "SUBTRACT"
        one_minus.inputs[0].default_value = 1.0
        links.new(base.outputs["Alpha"], less.inputs[0])
        links.new(less.outputs[0], one_minus.inputs[1])
        links.new(one_minus.outputs[0], bsdf.inputs["Alpha"])
        obj.data.materials.append(upper)
        obj.data.materials.append(lower)
        for poly in obj.data.polygons:
            poly.material_index = 0 if poly.center.z > 0 else 1
        return obj

    def big_constants():
        """A 2048² base colour with constant roughness and metallic factors."""
        obj = _sphere(bpy, "Big")
        mat, nodes, links, bsdf = _material(bpy, "Big")
        base = _texture(nodes, _image(bpy, folder, "Big_base", _rgba(_pattern(BIG, 5)), "sRGB"))
        links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
        bsdf.inputs["Roughness"].default_value = 0.35
        bsdf.inputs["Metallic"].default_value = 0.75
        obj.data.materials.append(mat)
        return obj

    for name, build in (("textured", textured), ("two_materials", two_materials), ("big_constants", big_constants)):
        gltf(name, build)

    # OBJ and FBX: a sphere with a base colour image and a roughness image, as other tools write them.
    for fmt in ("obj", "fbx"):
        _fresh(bpy)
        obj = _sphere(bpy, f"From{fmt.upper()}")
        mat, nodes, links, bsdf = _material(bpy, f"{fmt.upper()}Material")
        base = _texture(nodes, _image(bpy, folder, f"{fmt}_base", _rgba(_pattern(SIZE, 10)), "sRGB"))
        links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
        bsdf.inputs["Roughness"].default_value = 0.5
        obj.data.materials.append(mat)
        path = folder / f"model.{fmt}"
        if fmt == "obj":
            bpy.ops.wm.obj_export(filepath=str(path), export_selected_objects=False, path_mode="RELATIVE")
        else:
            addon_utils.enable("io_scene_fbx", default_set=False)
            bpy.ops.export_scene.fbx(filepath=str(path), path_mode="COPY", embed_textures=True)
        out[fmt] = str(path)
    return out


def write_obj(folder, mesh, texture_rgb) -> str:
    """An OBJ + MTL + PNG as a modelling tool writes them (nothing here is SceneFit's own format)."""
    folder.mkdir(parents=True, exist_ok=True)
    from scenefit.core.data.imageio import write_image

    write_image(folder / "albedo.png", texture_rgb)
    (folder / "ball.mtl").write_text("newmtl Ball\nKd 1 1 1\nNs 250\nmap_Kd albedo.png\n")
    lines = ["mtllib ball.mtl", "o Ball"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    lines += ["usemtl Ball"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in mesh.faces]
    (folder / "ball.obj").write_text("\n".join(lines) + "\n")
    return str(folder / "ball.obj")
