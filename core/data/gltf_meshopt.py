"""EXT_meshopt_compression decoded before import: Blender 5.0's glTF importer has no meshopt
decoder and refuses such files, which the Khronos validator accepts. The file is rewritten as a
plain GLB (every bufferView decoded with meshoptimizer's own decoder, PyPI `meshopt`; external
buffers and images embedded) in a temporary folder, and that copy is imported."""
from __future__ import annotations

import base64
import struct
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import unquote

import numpy as np
from pydantic import Field

from ..base.errors import InputError
from ..base.untrusted import Record, checked
from .glb import read_gltf, write_glb
from .gltf_images import BLENDER_READS, images_reencoded, needs_decoding

EXTENSION = "EXT_meshopt_compression"
_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
         ".ktx2": "image/ktx2"}


class BufferView(Record):
    buffer: Annotated[int, Field(ge=0)]
    byteOffset: Annotated[int, Field(ge=0)] = 0
    byteLength: Annotated[int, Field(ge=0)]
    extensions: dict[str, Any] = {}


class Buffer(Record):
    uri: str = ""


class Image(Record):
    uri: str = ""
    bufferView: Annotated[int, Field(ge=0)] | None = None


class GltfParts(Record):
    """The parts of a glTF document the decoder walks, typed (the meshopt objects: MeshoptView)."""

    extensionsUsed: list[str] = []
    extensionsRequired: list[str] = []
    buffers: list[Buffer] = []
    bufferViews: list[BufferView] = []
    images: list[Image] = []


def uses_meshopt(path: Path) -> bool:
    if path.suffix.lower() not in (".gltf", ".glb"):
        return False
    try:
        document, _ = read_gltf(path)
    except (ValueError, struct.error, UnicodeDecodeError, RecursionError):
        return False  # not readable as glTF: the importer says why
    used = document.get("extensionsUsed") if isinstance(document, dict) else None
    return isinstance(used, list) and EXTENSION in used


def _uri_bytes(uri: str, folder: Path) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    return (folder / unquote(uri)).read_bytes()


def _buffers(document: dict, chunk: bytes | None, folder: Path) -> list[bytes | None]:
    """Each buffer's bytes; None for a meshopt fallback buffer that holds nothing."""
    found: list[bytes | None] = []
    for index, buffer in enumerate(document.get("buffers", [])):
        if "uri" in buffer:
            found.append(_uri_bytes(buffer["uri"], folder))
        elif index == 0 and chunk is not None:
            found.append(chunk)
        else:
            found.append(None)
    return found


# What a file may decode to in all: a game asset's geometry is megabytes, a scanned one a few hundred.
MAX_DECODED_BYTES = 2**31


class MeshoptView(Record):
    """A bufferView's EXT_meshopt_compression object, as the extension's schema types it."""

    buffer: Annotated[int, Field(ge=0)]
    byteOffset: Annotated[int, Field(ge=0)] = 0
    byteLength: Annotated[int, Field(ge=0)]
    byteStride: Annotated[int, Field(ge=1, le=256)]
    count: Annotated[int, Field(ge=0)]
    mode: Literal["ATTRIBUTES", "TRIANGLES", "INDICES"] = "ATTRIBUTES"
    filter: Literal["NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL"] = "NONE"


def _checked_packing(view: dict, index: int, source: bytes | None, room: int) -> MeshoptView:
    """The view's extension object with its counts checked against the view and its buffer: what the
    decoder allocates (count x byteStride) is what the view says it holds and fits in `room` bytes (what
    is left of MAX_DECODED_BYTES), and the bytes lie in the buffer."""
    where = f"bufferView {index}'s {EXTENSION}"
    packed = checked(view["extensions"][EXTENSION], MeshoptView, where)
    rows = "attribute rows" if packed.mode == "ATTRIBUTES" else "indices"
    if packed.mode == "ATTRIBUTES" and packed.byteStride % 4 or packed.mode != "ATTRIBUTES" and \
            packed.byteStride not in (2, 4) or packed.mode == "TRIANGLES" and packed.count % 3:
        raise InputError(f"{where} has {packed.count} {rows} of {packed.byteStride} bytes, which mode "
                         f"{packed.mode} cannot hold.")
    if packed.count * packed.byteStride != view.get("byteLength"):
        raise InputError(f"{where} decodes to {packed.count} x {packed.byteStride} bytes, but the view holds "
                         f"{view.get('byteLength')!r}.")
    if packed.count * packed.byteStride > room:
        raise InputError(f"{where} would decode past {MAX_DECODED_BYTES // 2**30} GiB for the file; it is not "
                         "decoded.")
    if source is None or packed.byteOffset + packed.byteLength > len(source):
        raise InputError(f"{where} reads bytes {packed.byteOffset} to {packed.byteOffset + packed.byteLength} of "
                         f"buffer {packed.buffer}, which holds {0 if source is None else len(source)}.")
    return packed


def _decoded_view(view: dict, index: int, buffers: list[bytes | None], room: int) -> bytes:
    """The bufferView's plain bytes, decoded where it is compressed."""
    import meshopt  # lazy: its wheel is not on every platform

    if EXTENSION not in view.get("extensions", {}):
        source = buffers[view["buffer"]]
        if source is None:
            raise InputError(f"A bufferView of the file points into an empty fallback buffer {view['buffer']}; "
                             f"give the file with its {EXTENSION} data.")
        start = view.get("byteOffset", 0)
        return source[start:start + view["byteLength"]]
    packed = view["extensions"][EXTENSION]
    source = buffers[packed["buffer"]] if isinstance(packed, dict) and isinstance(packed.get("buffer"), int) \
        and 0 <= packed["buffer"] < len(buffers) else None
    packed = _checked_packing(view, index, source, room)
    assert source is not None   # (_checked_packing refuses a view outside its buffer)
    start = packed.byteOffset
    rows = meshopt.decode_gltf_buffer(bytes(source[start:start + packed.byteLength]), packed.count,
                                      packed.byteStride, packed.mode, packed.filter)
    rows = np.asarray(rows)
    if packed.mode != "ATTRIBUTES":  # indices come back as integers, stored at the view's stride
        rows = rows.astype(f"<u{packed.byteStride}")
    return rows.tobytes()


def decoded_glb(path: Path, out: Path) -> Path:
    """`path` (a .glb or .gltf using EXT_meshopt_compression) written to `out` as a plain GLB."""
    document, chunk = read_gltf(path)
    checked(document, GltfParts, f"'{path.name}'")
    buffers = _buffers(document, chunk, path.parent)
    blob = bytearray()

    def append(data: bytes) -> tuple[int, int]:
        blob.extend(b"\0" * (-len(blob) % 4))  # every accessor's component fits a 4-byte alignment
        blob.extend(data)
        return len(blob) - len(data), len(data)

    for index, view in enumerate(document.get("bufferViews", [])):
        offset, length = append(_decoded_view(view, index, buffers, MAX_DECODED_BYTES - len(blob)))
        extensions = {k: v for k, v in view.pop("extensions", {}).items() if k != EXTENSION}
        view.update({"buffer": 0, "byteOffset": offset, "byteLength": length}, **({"extensions": extensions}
                                                                               if extensions else {}))
    for image in document.get("images", []):
        if "uri" in image:  # embedded, so the copy needs no files beside it
            uri = image.pop("uri")
            document.setdefault("bufferViews", []).append(dict(zip(("buffer", "byteOffset", "byteLength"),
                                                                   (0, *append(_uri_bytes(uri, path.parent))))))
            image["bufferView"] = len(document["bufferViews"]) - 1
            image.setdefault("mimeType", _MIME.get(Path(unquote(uri)).suffix.lower(), "image/png"))
    document["buffers"] = [{"byteLength": len(blob)}]
    for key in ("extensionsUsed", "extensionsRequired"):
        kept = [name for name in document.get(key, []) if name != EXTENSION]
        document.pop(key, None)
        if kept:
            document[key] = kept
    write_glb(out, document, bytes(blob))
    return out


@contextmanager
def importable(path: Path):
    """`path`, or while the block runs a copy of it Blender's importer reads: its EXT_meshopt_compression
    data decoded, and images of a type the importer does not read (AVIF) as PNG (core/data/gltf_images.py)."""
    meshopt_used, images = uses_meshopt(path), needs_decoding(path)
    if not meshopt_used and not images:
        yield path
        return
    if meshopt_used:
        try:
            import meshopt  # noqa: F401  (meshoptimizer's decoder)
        except ImportError:
            raise InputError(f"'{path.name}' uses {EXTENSION}, whose decoder (PyPI 'meshopt') is not installed; "
                             "run `make setup` or `pip install -r requirements.txt`.") from None
    with tempfile.TemporaryDirectory(prefix="scenefit-meshopt-") as folder:
        try:
            copy = decoded_glb(path, Path(folder) / f"{path.stem}.glb")
        except (KeyError, IndexError, ValueError, RuntimeError, OSError, InputError) as error:
            why = _lower_first(str(error).rstrip("."))
            raise InputError(f"The {EXTENSION} data of '{path.name}' does not decode ({why}); check the file "
                             "with the Khronos glTF validator.") from None
        if images:
            images_reencoded(copy, BLENDER_READS)
        yield copy


def _lower_first(text: str) -> str:
    return text[:1].lower() + text[1:]


_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_COUNT = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_ELEMENT_ARRAY_BUFFER = 34963


def _element_sizes(document: dict) -> dict[int, int]:
    """bufferView -> the bytes of one element of the accessors reading it (views no accessor reads,
    images, are left out)."""
    sizes = {}
    for accessor in document.get("accessors", []):
        if "bufferView" in accessor:
            sizes[accessor["bufferView"]] = _COMPONENT_BYTES[accessor["componentType"]] * \
                _TYPE_COUNT[accessor["type"]]
    return sizes


def _packed(data: bytes, view: dict, size: int) -> tuple[bytes, dict] | None:
    """The view's bytes as EXT_meshopt_compression stores them and the extension's fields, or None
    where the codec cannot take it (a stride not a multiple of 4, a partial row)."""
    import meshopt  # lazy: its wheel is not on every platform

    stride = view.get("byteStride", size)
    rows: np.ndarray
    if view.get("target") == _ELEMENT_ARRAY_BUFFER and stride in (2, 4) and len(data) % (3 * stride) == 0:
        mode, rows = "TRIANGLES", np.frombuffer(data, f"<u{stride}").astype(np.uint32)
    elif stride % 4 == 0 and stride <= 256 and len(data) % stride == 0 and view.get("target") != _ELEMENT_ARRAY_BUFFER:
        mode, rows = "ATTRIBUTES", np.frombuffer(data, np.uint8).reshape(-1, stride)
    else:
        return None
    return meshopt.encode_gltf_buffer(rows, mode), {"byteStride": stride, "count": len(data) // stride, "mode": mode}


def encoded_glb(source: Path, out: Path) -> Path:
    """A plain GLB `source` written to `out` with its vertex and index data EXT_meshopt_compression-
    compressed, in gltfpack's layout: the compressed bytes in the BIN chunk, and a fallback buffer
    holding nothing (so the extension is required). Images stay as they are."""
    document, chunk = read_gltf(source)
    if chunk is None:   # (the exporter's GLB holds its buffer in the BIN chunk)
        raise InputError(f"'{source}' has no BIN chunk; only a self-contained GLB is meshopt-compressed.")
    sizes = _element_sizes(document)
    blob, fallback = bytearray(), 0
    for index, view in enumerate(document.get("bufferViews", [])):
        data = chunk[view.get("byteOffset", 0):][:view["byteLength"]]
        blob.extend(b"\0" * (-len(blob) % 4))
        packed = _packed(data, view, sizes[index]) if index in sizes else None
        if packed is None:
            view.update(buffer=0, byteOffset=len(blob))
            blob.extend(data)
            continue
        view["extensions"] = {**view.get("extensions", {}), EXTENSION: {
            "buffer": 0, "byteOffset": len(blob), "byteLength": len(packed[0]), **packed[1]}}
        fallback += -fallback % 4
        view.update(buffer=1, byteOffset=fallback)
        fallback += view["byteLength"]
        blob.extend(packed[0])
    document["buffers"] = [{"byteLength": len(blob)},
                           {"byteLength": max(fallback, 1), "extensions": {EXTENSION: {"fallback": True}}}]
    for key in ("extensionsUsed", "extensionsRequired"):
        document[key] = sorted(set(document.get(key, [])) | {EXTENSION})
    write_glb(out, document, bytes(blob))
    return out
