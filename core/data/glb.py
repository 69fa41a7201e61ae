"""The glTF container: a .gltf's JSON, or a .glb's JSON and BIN chunks (glTF 2.0 spec, "GLB File
Format"). Read and written here only; the importer and exporter are Blender's.

A glTF from elsewhere is data: its JSON is parsed with the untrusted reader's limits (nesting, finite
numbers) and the parts SceneFit walks (its lists of buffers, images, meshes and their primitives, nodes,
scenes, the extensions used) are checked for their glTF types before any code reads them, so a file
whose `images` is an object or whose primitives is a number is one sentence, not a traceback."""
from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field

from ..base.untrusted import Record, checked, parse_json, read_bytes

_JSON_CHUNK = 0x4E4F534A
# A glTF's JSON is at most megabytes (its data lives in buffers); a file 64 levels deep is no glTF.
MAX_GLTF_JSON_BYTES = 256 * 2**20
MAX_GLTF_FILE_BYTES = 4 * 2**30
Index = Annotated[int, Field(ge=0)]


class _Primitive(Record):
    attributes: dict[str, Index] = {}
    indices: Index | None = None
    material: Index | None = None
    extensions: dict[str, Any] = {}


class _Mesh(Record):
    primitives: list[_Primitive] = []


class _Node(Record):
    children: list[Index] = []
    mesh: Index | None = None
    skin: Index | None = None


class _Scene(Record):
    nodes: list[Index] = []


class _Uri(Record):
    uri: str | None = None
    mimeType: str | None = None
    bufferView: Index | None = None


class GltfDocument(Record):
    """The parts of a glTF document SceneFit's code walks, typed as the glTF 2.0 schema types them."""

    asset: dict[str, Any] = {}
    extensionsUsed: list[str] = []
    extensionsRequired: list[str] = []
    buffers: list[_Uri] = []
    bufferViews: list[dict[str, Any]] = []
    accessors: list[dict[str, Any]] = []
    images: list[_Uri] = []
    textures: list[dict[str, Any]] = []
    samplers: list[dict[str, Any]] = []
    materials: list[dict[str, Any]] = []
    meshes: list[_Mesh] = []
    nodes: list[_Node] = []
    scenes: list[_Scene] = []
    skins: list[dict[str, Any]] = []
    extensions: dict[str, Any] = {}


def read_gltf(path: Path) -> tuple[dict, bytes | None]:
    """(the JSON, the GLB's BIN chunk or None) of a .glb or .gltf file; ValueError (or struct.error) when it is
    neither, InputError (one sentence naming the file and field) when its JSON is not a glTF document's."""
    data = read_bytes(path, MAX_GLTF_FILE_BYTES, "glTF file")
    where = f"the glTF file '{path}'"
    if data[:4] != b"glTF":
        return _document(data, where), None
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != _JSON_CHUNK:
        raise ValueError(f"'{path}' is a GLB whose first chunk is not its JSON")
    document = _document(data[20:20 + length], where)
    rest = data[20 + length:]
    return document, (rest[8:8 + struct.unpack_from("<I", rest, 0)[0]] if len(rest) >= 8 else None)


def _document(text: bytes, where: str) -> dict:
    value = parse_json(text, where, MAX_GLTF_JSON_BYTES)
    if not isinstance(value, dict):   # ([] or null parse, but are no glTF: the importer says why)
        raise ValueError(f"{where} holds no glTF document")
    checked(value, GltfDocument, where)
    return value


def gltf_json(path: Path) -> dict:
    """A .glb's or .gltf's JSON, or {} when the file cannot be read as glTF at all (the importer says why);
    one sentence (InputError) when it is JSON whose parts are not of glTF's types."""
    try:
        document = read_gltf(path)[0]
    except (OSError, ValueError, struct.error):
        return {}
    return document


def write_glb(out: Path, document: dict, blob: bytes) -> None:
    """`document` and `blob` as a .glb (each chunk padded to 4 bytes: JSON with spaces, BIN with zeros)."""
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + (8 + len(blob) if blob else 0)
    parts = [b"glTF", struct.pack("<II", 2, total), struct.pack("<I", len(text)), b"JSON", text]
    if blob:
        parts += [struct.pack("<I", len(blob)), b"BIN\0", blob]
    Path(out).write_bytes(b"".join(parts))
