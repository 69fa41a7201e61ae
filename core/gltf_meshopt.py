"""EXT_meshopt_compression decoded before import: Blender 5.0's glTF importer has no meshopt
decoder and refuses such files, which the Khronos validator accepts. The file is rewritten as a
plain GLB (every bufferView decoded with meshoptimizer's own decoder, PyPI `meshopt`; external
buffers and images embedded) in a temporary folder, and that copy is imported."""
from __future__ import annotations

import base64
import json
import struct
import tempfile
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from .errors import InputError

EXTENSION = "EXT_meshopt_compression"
_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
         ".ktx2": "image/ktx2"}


def read_gltf(path: Path) -> tuple[dict, bytes | None]:
    """(the JSON, the GLB's BIN chunk or None) of a .glb or .gltf file."""
    data = path.read_bytes()
    if data[:4] != b"glTF":
        return json.loads(data), None
    length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + length])
    rest = data[20 + length:]
    return document, (rest[8:8 + struct.unpack_from("<I", rest, 0)[0]] if len(rest) >= 8 else None)


def uses_meshopt(path: Path) -> bool:
    if path.suffix.lower() not in (".gltf", ".glb"):
        return False
    try:
        document, _ = read_gltf(path)
    except (ValueError, struct.error, UnicodeDecodeError):
        return False  # not readable as glTF: the importer says why
    return EXTENSION in document.get("extensionsUsed", [])


def _uri_bytes(uri: str, folder: Path) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    return (folder / unquote(uri)).read_bytes()


def _buffers(document: dict, chunk: bytes | None, folder: Path) -> list[bytes | None]:
    """Each buffer's bytes; None for a meshopt fallback buffer that holds nothing."""
    found = []
    for index, buffer in enumerate(document.get("buffers", [])):
        if "uri" in buffer:
            found.append(_uri_bytes(buffer["uri"], folder))
        elif index == 0 and chunk is not None:
            found.append(chunk)
        else:
            found.append(None)
    return found


def _decoded_view(view: dict, buffers: list[bytes | None]) -> bytes:
    """The bufferView's plain bytes, decoded where it is compressed."""
    import meshopt

    packed = view.get("extensions", {}).get(EXTENSION)
    if packed is None:
        source = buffers[view["buffer"]]
        if source is None:
            raise InputError(f"A bufferView of the file points into an empty fallback buffer {view['buffer']}; "
                             f"give the file with its {EXTENSION} data.")
        start = view.get("byteOffset", 0)
        return source[start:start + view["byteLength"]]
    source = buffers[packed["buffer"]]
    start = packed.get("byteOffset", 0)
    count, stride, mode = packed["count"], packed["byteStride"], packed.get("mode", "ATTRIBUTES")
    rows = meshopt.decode_gltf_buffer(bytes(source[start:start + packed["byteLength"]]), count, stride, mode,
                                      packed.get("filter", "NONE"))
    rows = np.asarray(rows)
    if mode != "ATTRIBUTES":  # indices come back as integers, stored at the view's stride
        rows = rows.astype(f"<u{stride}")
    return rows.tobytes()


def decoded_glb(path: Path, out: Path) -> Path:
    """`path` (a .glb or .gltf using EXT_meshopt_compression) written to `out` as a plain GLB."""
    document, chunk = read_gltf(path)
    buffers = _buffers(document, chunk, path.parent)
    blob = bytearray()

    def append(data: bytes) -> tuple[int, int]:
        blob.extend(b"\0" * (-len(blob) % 4))  # every accessor's component fits a 4-byte alignment
        blob.extend(data)
        return len(blob) - len(data), len(data)

    for view in document.get("bufferViews", []):
        offset, length = append(_decoded_view(view, buffers))
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


def write_glb(out: Path, document: dict, blob: bytes) -> None:
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + (8 + len(blob) if blob else 0)
    parts = [b"glTF", struct.pack("<II", 2, total), struct.pack("<I", len(text)), b"JSON", text]
    if blob:
        parts += [struct.pack("<I", len(blob)), b"BIN\0", blob]
    out.write_bytes(b"".join(parts))


@contextmanager
def importable(path: Path):
    """`path`, or while the block runs a decoded copy of it when it uses EXT_meshopt_compression."""
    if not uses_meshopt(path):
        yield path
        return
    try:
        import meshopt  # noqa: F401  (meshoptimizer's decoder)
    except ImportError:
        raise InputError(f"'{path.name}' uses {EXTENSION}, whose decoder (PyPI 'meshopt') is not installed; "
                         "run `make setup` or `pip install -r requirements.txt`.") from None
    with tempfile.TemporaryDirectory(prefix="scenefit-meshopt-") as folder:
        try:
            copy = decoded_glb(path, Path(folder) / f"{path.stem}.glb")
        except (KeyError, IndexError, ValueError, RuntimeError, OSError) as error:
            raise InputError(f"The {EXTENSION} data of '{path.name}' does not decode ({error}); check the file "
                             "with the Khronos glTF validator.") from None
        yield copy
