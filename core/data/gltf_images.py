"""glTF images in a format a reader does not take, re-encoded as PNG: WebP (EXT_texture_webp) and AVIF
(EXT_texture_avif) images decoded with Pillow. Used twice: before Blender imports a file (its importer
reads WebP but refuses a file that requires AVIF), and after Blender exports an engine's bake (its
exporter keeps a WebP input's images WebP, which Unity's and Unreal's importers do not read:
core/stages/bake/engine_targets.py). Each texture then reads its PNG as its plain `source`, and an image
extension no texture uses any more leaves `extensionsUsed` and `extensionsRequired`.

KTX2 (KHR_texture_basisu) is GPU block data; decoding it needs Basis Universal's transcoder, which is
not here: such an image is refused in one sentence where it would have to be decoded."""
from __future__ import annotations

import base64
import io
import json
from pathlib import Path
from urllib.parse import unquote

from ..base.errors import InputError
from .glb import gltf_json, read_gltf, write_glb

# Each image extension and the MIME type of the images it points at.
IMAGE_EXTENSIONS = {"EXT_texture_webp": "image/webp", "EXT_texture_avif": "image/avif",
                    "KHR_texture_basisu": "image/ktx2"}
PNG = "image/png"
_MIME_OF_SUFFIX = {".png": PNG, ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
                   ".avif": "image/avif", ".ktx2": "image/ktx2"}
DECODED = ("image/webp", "image/avif")   # what this module turns into PNG
BLENDER_READS = {PNG, "image/jpeg", "image/webp"}   # the image types Blender 5.0's glTF importer reads


def image_mime(image: dict) -> str | None:
    if isinstance(image.get("mimeType"), str):
        return image["mimeType"]
    return _MIME_OF_SUFFIX.get(Path(unquote(str(image.get("uri", "")))).suffix.lower())


def png_bytes(data: bytes, mime: str, name: str) -> bytes:
    """One image's bytes as PNG (its alpha kept); one sentence when they cannot be decoded."""
    if mime not in DECODED:
        raise InputError(f"The {mime} image '{name}' cannot be re-encoded here (only {', '.join(DECODED)} "
                         "images are); give the file with PNG or JPEG images.")
    try:
        from PIL import Image, UnidentifiedImageError  # lazy: Pillow comes with diffusers, not in every install
    except ImportError:
        raise InputError(f"The {mime} image '{name}' needs Pillow to be re-encoded, which is not installed; run "
                         "`pip install -r requirements.txt`, or give the file with PNG or JPEG images.") from None
    try:
        with Image.open(io.BytesIO(data)) as image:
            image.load()
            out = io.BytesIO()
            keep = image.mode if image.mode in ("L", "LA", "RGB", "RGBA") else \
                ("RGBA" if "A" in image.getbands() else "RGB")
            image.convert(keep).save(out, format="PNG")
    except (UnidentifiedImageError, OSError, ValueError) as error:
        raise InputError(f"The {mime} image '{name}' does not decode ({error}); give the file with that image "
                         "in another format.") from None
    return out.getvalue()


def _image_bytes(image: dict, document: dict, chunk: bytes | None, folder: Path) -> bytes:
    if "bufferView" in image:
        view = document["bufferViews"][image["bufferView"]]
        if chunk is None or view.get("buffer", 0) != 0:
            raise InputError("An image of the file lies in a buffer other than the GLB's own; give it as a .glb "
                             "or with its images as files.")
        return chunk[view.get("byteOffset", 0):][:view["byteLength"]]
    uri = str(image.get("uri", ""))
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    return (folder / unquote(uri)).read_bytes()


def _point_textures_at_sources(document: dict) -> None:
    """Each texture whose image extension now points at a PNG reads it as its plain `source`; an image
    extension no texture uses any more leaves the lists of used and required extensions."""
    images = document.get("images", [])
    for texture in document.get("textures", []):
        extensions = texture.get("extensions", {})
        for name, mime in IMAGE_EXTENSIONS.items():
            source = extensions.get(name, {}).get("source") if isinstance(extensions.get(name), dict) else None
            if isinstance(source, int) and 0 <= source < len(images) and image_mime(images[source]) != mime:
                texture["source"] = source
                del extensions[name]
        if "extensions" in texture and not texture["extensions"]:
            del texture["extensions"]
    still = {name for texture in document.get("textures", []) for name in texture.get("extensions", {})}
    for key in ("extensionsUsed", "extensionsRequired"):
        kept = [n for n in document.get(key, []) if n not in IMAGE_EXTENSIONS or n in still]
        document.pop(key, None)
        if kept:
            document[key] = kept


def reencode_images(document: dict, chunk: bytes | None, folder: Path, keep: set[str],
                    out_folder: Path | None = None) -> tuple[bytes | None, list[str]]:
    """Every image of `document` whose MIME type is not in `keep` re-encoded as PNG: in the GLB's BIN chunk
    (returned, rebuilt), or for a .gltf as a file written into `out_folder` (default `folder`). Returns
    (the BIN chunk, the images' names re-encoded); `document` is changed in place."""
    images = document.get("images", [])
    changed: dict[int, bytes] = {}
    names = []
    for index, image in enumerate(images):
        mime = image_mime(image)
        if mime is None or mime in keep:
            continue
        name = str(image.get("name") or image.get("uri") or f"image {index}")
        png = png_bytes(_image_bytes(image, document, chunk, folder), mime, name)
        names.append(name)
        if "bufferView" in image:
            changed[image["bufferView"]] = png
        else:
            uri = f"{Path(unquote(str(image.get('uri') or f'image{index}'))).stem or f'image{index}'}.png"
            if str(image.get("uri", "")).startswith("data:"):
                uri = f"image{index}.png"
            (out_folder or folder).joinpath(uri).write_bytes(png)
            image["uri"] = uri
        image["mimeType"] = PNG
    if changed and chunk is not None:
        blob = bytearray()
        for index, view in enumerate(document.get("bufferViews", [])):
            data = changed.get(index, chunk[view.get("byteOffset", 0):][:view["byteLength"]])
            blob.extend(b"\0" * (-len(blob) % 4))
            view.update(byteOffset=len(blob), byteLength=len(data))
            blob.extend(data)
        chunk = bytes(blob)
        if document.get("buffers"):
            document["buffers"][0]["byteLength"] = len(chunk)
    if names:
        _point_textures_at_sources(document)
    return chunk, names


def images_reencoded(path: Path, keep: set[str]) -> list[str]:
    """reencode_images on the .glb or .gltf at `path` (a file this process wrote: a .gltf's replaced image
    files beside it are deleted), rewritten in place when any image changed."""
    document, chunk = read_gltf(path)
    before = {str(image.get("uri")) for image in document.get("images", []) if "uri" in image}
    chunk, names = reencode_images(document, chunk, path.parent, keep)
    if names and path.suffix.lower() == ".gltf":
        path.write_text(json.dumps(document, indent=2))
        after = {str(image.get("uri")) for image in document.get("images", []) if "uri" in image}
        for uri in before - after:
            if not uri.startswith("data:"):
                path.parent.joinpath(unquote(uri)).unlink(missing_ok=True)
    elif names:
        write_glb(path, document, chunk or b"")
    return names


def needs_decoding(path: Path) -> bool:
    """Whether a glTF's images include a format Blender's importer does not read (AVIF, KTX2)."""
    if path.suffix.lower() not in (".gltf", ".glb"):
        return False
    document = gltf_json(path)
    images = document.get("images", []) if isinstance(document.get("images"), list) else []
    return any(isinstance(image, dict) and image_mime(image) not in BLENDER_READS for image in images)
