"""`scenefit bake` of a texture adapted per surface on UVs that share texels: the material's
maps go into a new UV map made by Smart UV Project and written as one more TEXCOORD, the asset's own
UVs stay for its other images, the file is valid, and the two mirrored halves now show their own
results (through the asset's own UVs they could only show one)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scenefit.core.data.glb import read_gltf

from conftest import built_and_converted, run_python, scenefit_process

pytestmark = pytest.mark.blender

BUILD = r"""
import bpy, numpy as np
from pathlib import Path
folder = Path(FOLDER)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
obj = bpy.context.active_object
obj.name = "Mirrored"
me = obj.data
uv = np.empty(2 * len(me.loops), np.float32)
me.uv_layers.active.uv.foreach_get("vector", uv)
uv = uv.reshape(-1, 2)
uv[:, 0] = np.abs(uv[:, 0] - 0.5) * 2.0        # the right half laid over the left, as symmetric assets are
me.uv_layers.active.uv.foreach_set("vector", uv.ravel())
mat = bpy.data.materials.new("Painted")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
size = 64
y, x = np.mgrid[0:size, 0:size] / size
rgba = np.stack([0.2 + 0.6 * x, 0.2 + 0.6 * y, np.full_like(x, 0.5), np.ones_like(x)], -1).astype(np.float32)
img = bpy.data.images.new("painted_base", size, size)
img.pixels.foreach_set(rgba[::-1].ravel())
img.filepath_raw = str(folder / "painted_base.png")
img.file_format = "PNG"
img.save()
base = nodes.new("ShaderNodeTexImage")
base.image = img
links.new(base.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
me.materials.append(mat)
bpy.ops.export_scene.gltf(filepath=str(folder / "mirrored.glb"), export_format="GLB")
"""

# An adapted texture stood in for by a residual that varies over the surface (what adaptation learns),
# in the layout adaptation would choose for this asset.
ADAPTED = r"""
import torch
from scenefit.blender_io.asset_file import load_asset_materials
from scenefit.core.texture.surface_layout import adapting_view
from scenefit.core.texture.bake import load_neural_texture, save_neural_texture
texture = load_neural_texture(TEXTURE)
mesh, _ = load_asset_materials(ASSET).fitting_view()
view, layout, report = adapting_view(texture, mesh)
assert layout is not None, report
texture.layout = layout
with torch.no_grad():
    generator = torch.Generator().manual_seed(0)
    texture.encoding.table.normal_(0.0, 1.0, generator=generator)
    texture.mlp[2].weight.normal_(0.0, 1.0, generator=generator)
save_neural_texture(texture, OUT)
"""

# The baked file read back by Blender's importer: each loop's position and both UV maps.
READ_BACK = r"""
import json, bpy, numpy as np
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=BAKED)
obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
me = obj.data
def loops(layer):
    a = np.empty(2 * len(me.loops), np.float32)
    layer.uv.foreach_get("vector", a)
    return a.reshape(-1, 2).tolist()
vertex = np.empty(len(me.loops), np.int32)
me.loops.foreach_get("vertex_index", vertex)
co = np.empty(3 * len(me.vertices), np.float32)
me.vertices.foreach_get("co", co)
print(json.dumps({"layers": [l.name for l in me.uv_layers], "position": co.reshape(-1, 3)[vertex].tolist(),
                  "uv": {l.name: loops(l) for l in me.uv_layers}}))
"""


def python(code: str) -> str:
    """What `code` printed, run in a fresh interpreter (a fresh bpy)."""
    return run_python(code).stdout


scenefit = scenefit_process


@pytest.fixture(scope="module")
def adapted(tmp_path_factory) -> tuple[Path, Path]:
    """(the mirrored sphere's GLB, a texture adapted per surface in a new layout for it)."""
    folder = tmp_path_factory.mktemp("mirrored")
    asset, converted = built_and_converted(BUILD, folder, "mirrored.glb")
    texture = folder / "adapted.pt"
    python(ADAPTED.replace("TEXTURE", repr(str(converted)))
           .replace("ASSET", repr(str(asset))).replace("OUT", repr(str(texture))))
    return asset, texture


# Smart UV Project failing (as an operator can on a broken mesh): the bake goes on in the asset's own UVs.
UNWRAP_FAILS = r"""
import json
import scenefit.blender_io.uv_unwrap as uv_unwrap
from scenefit.blender_io.gltf_export import bake_asset_file
from contextlib import contextmanager

@contextmanager
def failing(objects, materials):
    raise RuntimeError("Error: smart_project found no faces")
    yield

uv_unwrap.new_uv_map_active = failing
report = bake_asset_file(ASSET, TEXTURE, OUT)
print(json.dumps(report))
"""


def test_a_failed_unwrap_bakes_in_the_asset_uvs_and_says_so(adapted, tmp_path, validator):
    asset, texture = adapted
    out = tmp_path / "own_uvs.glb"
    report = json.loads(python(UNWRAP_FAILS.replace("ASSET", repr(str(asset))).replace("TEXTURE", repr(str(texture)))
                               .replace("OUT", repr(str(out)))).strip().splitlines()[-1])
    assert "no new UV map could be made (Error: smart_project found no faces)" in report["uv_map"]
    assert "uv_map" not in report["materials"][0]
    assert validator(str(out))["issues"]["numErrors"] == 0
    document, _ = read_gltf(out)
    assert "TEXCOORD_1" not in document["meshes"][0]["primitives"][0]["attributes"]


def test_an_adapted_texture_on_mirrored_uvs_bakes_into_a_new_uv_map(adapted, tmp_path, validator):
    import cv2

    asset, adapted = adapted
    baked = tmp_path / "baked.glb"
    proc = scenefit("bake", asset, "--texture", adapted, "--out", baked, "--report", tmp_path / "bake.json")
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads((tmp_path / "bake.json").read_text())
    (material,) = report["materials"]
    assert material["uv_map"] == "SceneFit UV" and any("new UV map" in line for line in material["done"])
    assert validator(str(baked))["issues"]["numErrors"] == 0

    document, chunk = read_gltf(baked)
    info = document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    primitive = document["meshes"][0]["primitives"][0]
    assert info.get("texCoord") == 1 and {"TEXCOORD_0", "TEXCOORD_1"} <= set(primitive["attributes"])
    image = document["images"][document["textures"][info["index"]]["source"]]
    view = document["bufferViews"][image["bufferView"]]
    pixels = cv2.imdecode(np.frombuffer(chunk[view.get("byteOffset", 0):][:view["byteLength"]], np.uint8),
                          cv2.IMREAD_UNCHANGED)[..., :3][..., ::-1].astype(np.float64) / 255.0

    back = json.loads(python(READ_BACK.replace("BAKED", repr(str(baked)))).strip().splitlines()[-1])
    own_name, new_name = back["layers"][0], back["layers"][1]
    position = np.array(back["position"])
    own_uv, new_uv = np.array(back["uv"][own_name]), np.array(back["uv"][new_name])
    # The own UVs still mirror the halves; the new map gives each half its own texels.
    half = np.flatnonzero(position[:, 1] < -0.2)
    mirror = position[half] * [1.0, -1.0, 1.0]
    partner = np.argmin(((position[None, :, :] - mirror[:, None, :]) ** 2).sum(axis=2), axis=1)
    close = np.linalg.norm(position[partner] - mirror, axis=1) < 1e-4
    half, partner = half[close], partner[close]
    assert len(half) > 50
    assert np.abs(own_uv[half] - own_uv[partner]).max() < 1e-4
    assert np.abs(new_uv[half] - new_uv[partner]).max(axis=1).min() > 1e-3

    def read(uv: np.ndarray) -> np.ndarray:
        h, w = pixels.shape[:2]
        col = np.clip((uv[:, 0] * w).astype(int), 0, w - 1)
        row = np.clip(((1.0 - uv[:, 1]) * h).astype(int), 0, h - 1)
        return pixels[row, col]

    assert np.abs(read(new_uv[half]) - read(new_uv[partner])).mean() > 0.05


def uv_less_ball(folder: Path) -> Path:
    """An OBJ sphere with no texture coordinates at all and two plain-colour materials (top, bottom)."""
    (folder / "ball.mtl").write_text("newmtl Red\nKd 0.8 0.1 0.1\nnewmtl Blue\nKd 0.1 0.2 0.85\n")
    rings, segments = 8, 16
    verts = [(0.0, 0.0, 1.0)] + [(np.sin(np.pi * i / rings) * np.cos(2 * np.pi * j / segments),
                                  np.sin(np.pi * i / rings) * np.sin(2 * np.pi * j / segments), np.cos(np.pi * i / rings))
                                 for i in range(1, rings) for j in range(segments)] + [(0.0, 0.0, -1.0)]
    ring = lambda i, j: 1 + i * segments + j % segments   # noqa: E731
    faces = [(0, ring(0, j), ring(0, j + 1)) for j in range(segments)]
    faces += [f for i in range(rings - 2) for j in range(segments)
              for f in ((ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)), (ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)))]
    faces += [(ring(rings - 2, j), len(verts) - 1, ring(rings - 2, j + 1)) for j in range(segments)]
    up = [f for f in faces if np.mean([verts[k][2] for k in f]) > 0]
    lines = ["mtllib ball.mtl", *(f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in verts), "usemtl Red",
             *(f"f {a + 1} {b + 1} {c + 1}" for a, b, c in up), "usemtl Blue",
             *(f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces if (a, b, c) not in up)]
    (folder / "ball.obj").write_text("\n".join(lines) + "\n")
    return folder / "ball.obj"


def test_an_asset_with_no_uv_map_converts_exactly_and_an_adapted_texture_bakes_into_a_new_one(tmp_path, validator):
    """No UV map at all (an OBJ without texture coordinates): it was refused ("unwrap it first"). Each
    material reads as its plain colour (every corner at UV 0, 0, as Blender renders it); adaptation
    finds every face collapsed and works in a new layout, and the bake writes it as the file's UV map."""
    asset = uv_less_ball(tmp_path)
    proc = scenefit("convert", asset, "--out", tmp_path / "convert", "--preset", "draft", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads((tmp_path / "convert" / "report.json").read_text())
    assert [(m["name"], m["psnr_db"]) for m in report["decisions"]["materials"]] == [("Red", 100.0), ("Blue", 100.0)]
    adapted = tmp_path / "adapted.pt"
    python(ADAPTED.replace("TEXTURE", repr(str(tmp_path / "convert/maps/texture.pt")))
           .replace("ASSET", repr(str(asset))).replace("OUT", repr(str(adapted))))
    baked = tmp_path / "ball.glb"
    proc = scenefit("bake", asset, "--texture", adapted, "--out", baked, "--report", tmp_path / "bake.json")
    assert proc.returncode == 0, proc.stderr[-2000:]
    materials = json.loads((tmp_path / "bake.json").read_text())["materials"]
    assert [(m["name"], m.get("uv_map")) for m in materials] == [("Red", "SceneFit UV"), ("Blue", "SceneFit UV")]
    assert validator(str(baked))["issues"]["numErrors"] == 0
    document, _ = read_gltf(baked)
    assert all("TEXCOORD_0" in p["attributes"] for m in document["meshes"] for p in m["primitives"])
