"""The glTF container: a .gltf's JSON, or a .glb's JSON and BIN chunks (glTF 2.0 spec, "GLB File
Format"). Read and written here only; the importer and exporter are Blender's."""
from __future__ import annotations

import json
import struct
from pathlib import Path

_JSON_CHUNK = 0x4E4F534A


def read_gltf(path: Path) -> tuple[dict, bytes | None]:
    """(the JSON, the GLB's BIN chunk or None) of a .glb or .gltf file; ValueError (or struct.error,
    UnicodeDecodeError) when it is neither."""
    data = Path(path).read_bytes()
    if data[:4] != b"glTF":
        return json.loads(data), None
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != _JSON_CHUNK:
        raise ValueError(f"'{path}' is a GLB whose first chunk is not its JSON")
    document = json.loads(data[20:20 + length])
    rest = data[20 + length:]
    return document, (rest[8:8 + struct.unpack_from("<I", rest, 0)[0]] if len(rest) >= 8 else None)


def gltf_json(path: Path) -> dict:
    """A .glb's or .gltf's JSON, or {} when the file cannot be read as glTF (the importer says why)."""
    try:
        document = read_gltf(path)[0]
    except (OSError, ValueError, struct.error, UnicodeDecodeError):
        return {}
    return document if isinstance(document, dict) else {}   # ([] or null parse, but are no glTF)


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
