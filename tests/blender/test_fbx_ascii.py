"""ASCII FBX files (Asset Forge, older Maya and 3ds Max exports, Kenney's packs) are read: Blender's
importer takes only binary FBX, so the text is written as binary first (blender_io/fbx_ascii.py).

The check: Blender's FBX exporter writes a binary file (a parented, scaled node, two materials, UVs, an
embedded image); this test writes the same tree as FBX text, the way the FBX SDK lays it out; both
files are read by SceneFit and must give the same asset, to the bit."""
from __future__ import annotations


import pytest

from scenefit.blender_io.fbx_ascii import binary_copy, parse_ascii_fbx
from scenefit.core.base.errors import InputError

from conftest import printed_json

SAME_ASSET = r"""
import base64, json, sys
from pathlib import Path
import numpy as np
import bpy, addon_utils
sys.path.insert(0, "tests")
from asset_builder import _image, _pattern, _rgba
from scenefit.blender_io.asset_file import empty_startup_file, load_asset_materials, loaded_asset

folder = Path(FOLDER)
empty_startup_file(bpy)
bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6)
ball = bpy.context.object
ball.name = "Ball"
bpy.ops.object.empty_add(location=(0.5, -1.0, 0.25))
holder = bpy.context.object
holder.name, holder.scale, holder.rotation_euler = "Holder", (2.0, 2.0, 2.0), (0.0, 0.0, 0.7)
ball.parent = holder
for k, colour in enumerate(((0.8, 0.2, 0.1, 1.0), (0.1, 0.5, 0.9, 1.0))):
    material = bpy.data.materials.new(f"Paint{k}")
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = colour
    bsdf.inputs["Roughness"].default_value = 0.3 + 0.4 * k
    if k == 0:
        node = material.node_tree.nodes.new("ShaderNodeTexImage")
        node.image = _image(bpy, folder, "paint", _rgba(_pattern(16, 4)), "sRGB")
        material.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    ball.data.materials.append(material)
for polygon in ball.data.polygons:
    polygon.material_index = int(polygon.center.z > 0)
addon_utils.enable("io_scene_fbx", default_set=False)
binary = folder / "binary" / "ball.fbx"
binary.parent.mkdir()
bpy.ops.export_scene.fbx(filepath=str(binary), path_mode="COPY", embed_textures=True)

from io_scene_fbx import parse_fbx

def text(element, depth=0):
    # One node as the FBX SDK writes text: `Name: v, v {`, arrays `*N { a: ... }`, "Class::Name".
    pad, lines = "\t" * depth, []
    for child in element.elems:
        name, values, array = child.id.decode(), [], None
        for value, kind in zip(child.props, child.props_type):
            kind = chr(kind)
            if kind == "S":
                s = value.decode("utf-8")
                if "\x00\x01" in s:
                    s = "{1}::{0}".format(*s.split("\x00\x01"))
                values.append('"' + s.replace('"', "&quot;") + '"')
            elif kind == "R":
                if name == "Content":
                    values.append('"' + base64.b64encode(value).decode() + '"')
            elif kind in "CB":
                values.append("T" if value not in (b"\x00", False, 0, b"F") else "F")
            elif kind in "fdilbc":
                array = list(value)
            else:
                values.append(repr(value))
        if name in ("FileId", "CreationTime"):   # binary-only stamps
            continue
        head = f"{pad}{name}: " + (f"*{len(array)} {{" if array is not None else ", ".join(values))
        if array is not None:
            lines += [head, f"{pad}\ta: " + ",".join(repr(v) for v in array), pad + "}"]
        elif child.elems:
            lines += [head + " {", *text(child, depth + 1), pad + "}"]
        else:
            lines.append(head)
    return lines

root, version = parse_fbx.parse(str(binary))
ascii_file = folder / "ascii" / "ball.fbx"
ascii_file.parent.mkdir()
ascii_file.write_text(f"; FBX {version // 1000}.{version % 1000 // 100}.0 project file\n" + "\n".join(text(root)) + "\n")

bpy.ops.wm.read_factory_settings(use_empty=True)   # the files' objects are read by their own names


def asset(path):
    materials = load_asset_materials(path)
    with loaded_asset(path) as (meshes, scene):
        objects = sorted((o.name, o.type, o.parent.name if o.parent else None) for o in scene.objects)
    return {"positions": materials.mesh.positions.tolist(), "uvs": materials.mesh.uvs.tolist(),
            "faces": materials.mesh.faces.tolist(), "objects": objects,
            "materials": [json.dumps(m.report(), sort_keys=True, default=str) for m in materials.materials],
            "base": [None if not hasattr(m.maps.base_color, "shape") else np.asarray(m.maps.base_color).tolist()
                     for m in materials.materials]}

print("JSON" + json.dumps({"binary": asset(binary), "ascii": asset(ascii_file), "head": ascii_file.read_text()[:400]}))
"""


@pytest.mark.blender
def test_an_ascii_fbx_reads_as_the_same_binary_fbx_does(run_py, tmp_path):
    proc = run_py(SAME_ASSET.replace("FOLDER", repr(str(tmp_path))))
    got = printed_json(proc)
    binary, text = got["binary"], got["ascii"]
    assert got["head"].startswith("; FBX 7.") and "Objects:  {" not in got["head"]
    assert ["Ball", "MESH", "Holder"] in binary["objects"]
    assert len(binary["materials"]) == 2 and len(binary["faces"]) > 100
    for key in ("objects", "positions", "uvs", "faces", "materials", "base"):
        assert text[key] == binary[key], key


def test_the_text_is_typed_as_the_importer_reads_it():
    nodes = parse_ascii_fbx("""; FBX 7.3.0 project file
FBXHeaderExtension:  {
\tFBXVersion: 7300
}
Objects:  {
\tGeometry: 4455667788990, "Geometry::Sofa", "Mesh" {
\t\tVertices: *6 {
\t\t\ta: 0,0,0,
1.5,-2e-3,3,
\t\t}
\t\tShading: T
\t\tProperties70:  {
\t\t\tP: "Lcl Scaling", "Lcl Scaling", "", "A",1,1,1
\t\t}
\t}
}
Connections:  {
\tC: "OO",4455667788990,0
}
""")
    assert [n[0] for n in nodes] == ["FBXHeaderExtension", "Objects", "Connections"]
    geometry = nodes[1][2][0]
    assert geometry[1] == [("number", "4455667788990"), ("string", "Geometry::Sofa"), ("string", "Mesh")]
    vertices, shading, props = geometry[2]
    assert vertices == ("Vertices", [("array", ["0", "0", "0", "1.5", "-2e-3", "3"])], [])
    assert shading == ("Shading", [("word", "T")], [])
    assert props[2][0][1][4:] == [("number", "1")] * 3
    assert nodes[2][2][0][1][0] == ("string", "OO")


@pytest.mark.parametrize("text, words", [
    ("; FBX 6.1.0 project file\nFBXHeaderExtension:  {\n\tFBXVersion: 6100\n}\n", "FBX 6.1 text file"),
    ("Objects:  {\n\tModel: 1, \"Model::A\" {\n", "cannot be read"),
    ("Geometry: 1 {\n\tVertices: *4 {\n\t\ta: 0,1\n\t}\n}\n", "cannot be read (an array of 4 values holds 2)"),
])
def test_a_text_fbx_blender_cannot_read_is_one_sentence(tmp_path, text, words):
    source = tmp_path / "old.fbx"
    source.write_text(text)
    with pytest.raises(InputError) as caught:
        binary_copy(source, tmp_path / "out.fbx")
    message = str(caught.value)
    assert words in message and message.count(". ") == 0 and "\n" not in message
    assert not (tmp_path / "out.fbx").exists()
