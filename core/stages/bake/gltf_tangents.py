"""The TANGENT a bake writes: the input's own where an output vertex is one of the input's (same place,
normal and UV), else the exporter's, and never one a client cannot use: a zero-length, non-unit or
non-finite tangent (Blender's MikkTSpace gives zero where a triangle's UVs are degenerate; the
validator's ACCESSOR_VECTOR3_NON_UNIT) becomes a unit vector orthogonal to the normal, with a handedness
of +1 or -1. Works on a written .glb or .gltf before any mesh compression."""
from __future__ import annotations

import base64
import json
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from ...data.glb import read_gltf, write_glb
from ...data.gltf_meshopt import importable

_DTYPES = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5120: np.int8, 5122: np.int16}
_NORMALIZED = {5121: 255.0, 5123: 65535.0, 5120: 127.0, 5122: 32767.0}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_PLACES = (4, 4)   # decimals a vertex is matched at: place (in its mesh's size), UV


class GltfBuffers:
    """A glTF file's JSON and its buffers as writable bytes (a .glb's BIN chunk, a .gltf's .bin files)."""
    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.document, chunk = read_gltf(self.path)
        self.data: list[bytearray | None] = []
        for index, buffer in enumerate(self.document.get("buffers", [])):
            uri = buffer.get("uri")
            if uri is None:
                self.data.append(bytearray(chunk) if index == 0 and chunk is not None else None)
            elif uri.startswith("data:"):
                self.data.append(bytearray(base64.b64decode(uri.split(",", 1)[1])))
            else:
                file = self.path.parent / unquote(uri)
                self.data.append(bytearray(file.read_bytes()) if file.is_file() else None)

    def _place(self, index: int) -> tuple[np.ndarray, int, int, int, float | None] | None:
        """(the buffer as bytes, byte offset, stride, width, normalizing divisor) of a plain accessor."""
        accessor = self.document["accessors"][index]
        if "bufferView" not in accessor or "sparse" in accessor or accessor["componentType"] not in _DTYPES:
            return None
        view = self.document["bufferViews"][accessor["bufferView"]]
        data = self.data[view["buffer"]]
        if data is None or "extensions" in view:   # (a compressed view: decoded elsewhere or not at all)
            return None
        dtype = np.dtype(_DTYPES[accessor["componentType"]]).newbyteorder("<")
        width = _WIDTH.get(accessor["type"], 0)
        offset = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        divisor = _NORMALIZED.get(accessor["componentType"]) if accessor.get("normalized") else None
        return data, offset, stride, width, divisor

    def read(self, index: int) -> np.ndarray | None:
        """The accessor's values as float64 (count, width), or None where it is not plain data."""
        place = self._place(index)
        if place is None:
            return None
        data, offset, stride, width, divisor = place
        accessor = self.document["accessors"][index]
        dtype = np.dtype(_DTYPES[accessor["componentType"]]).newbyteorder("<")
        values = np.ndarray((accessor["count"], width), dtype, buffer=data, offset=offset,
                            strides=(stride, dtype.itemsize)).astype(np.float64)
        return values / divisor if divisor else values

    def write(self, index: int, values: np.ndarray) -> None:
        """Write float values over a float accessor's own bytes."""
        place = self._place(index)
        assert place is not None   # (written only where the same accessor was read)
        data, offset, stride, width, _ = place
        out: np.ndarray = np.ndarray((len(values), width), np.dtype("<f4"), buffer=data, offset=offset,
                                     strides=(stride, 4))
        out[...] = values

    def save(self) -> None:
        for buffer, data in zip(self.document.get("buffers", []), self.data):
            uri = buffer.get("uri")
            if uri and not uri.startswith("data:") and data is not None:
                (self.path.parent / unquote(uri)).write_bytes(bytes(data))
        if self.path.suffix.lower() == ".glb":
            write_glb(self.path, self.document, bytes(self.data[0]) if self.data and self.data[0] else b"")
        else:
            self.path.write_text(json.dumps(self.document, indent=2))


def _primitives(gltf: GltfBuffers):
    """(its mesh's size, positions, normals, UVs, tangent accessor index, tangents) of each primitive with
    plain TANGENT, NORMAL and POSITION (TEXCOORD_0 where it has one)."""
    for mesh in gltf.document.get("meshes", []):
        found = []
        for primitive in mesh.get("primitives", []):
            names = primitive.get("attributes", {})
            if not {"TANGENT", "NORMAL", "POSITION"} <= set(names) or "KHR_draco_mesh_compression" in \
                    primitive.get("extensions", {}):
                continue
            position, normal, texcoord, tangent = (gltf.read(names[key]) if key in names else None
                                                   for key in ("POSITION", "NORMAL", "TEXCOORD_0", "TANGENT"))
            if position is None or normal is None or tangent is None or tangent.shape[1] != 4:
                continue
            uv = texcoord if texcoord is not None else np.zeros((len(position), 2))
            found.append((position, normal, uv, names["TANGENT"], tangent))
        if found:
            everything = np.concatenate([f[0] for f in found])
            size = float(np.ptp(everything, axis=0).max()) or 1.0
            yield from ((size, *f) for f in found)


def _keys(size: float, positions: np.ndarray, uvs: np.ndarray) -> list[tuple]:
    rounded = np.concatenate([np.round(positions / size, _PLACES[0]), np.round(uvs, _PLACES[1])], axis=1) + 0.0
    return [tuple(row) for row in rounded]   # (+0.0 above: -0.0 and 0.0 are one key)


def input_tangents(path: Path) -> dict[tuple, list[tuple[np.ndarray, np.ndarray]]]:
    """The input glTF's (normal, tangent) pairs by vertex key (place relative to its mesh's size, UV)."""
    found: dict[tuple, list] = {}
    with importable(Path(path)) as plain:
        for size, positions, normals, uvs, _, tangents in _primitives(GltfBuffers(plain)):
            for key, normal, tangent in zip(_keys(size, positions, uvs), normals, tangents):
                found.setdefault(key, []).append((normal, tangent))
    return found


def _own(candidates: list, normal: np.ndarray) -> np.ndarray | None:
    """The input's tangent of the vertex with this normal (within about 8 degrees), if any."""
    best = max(candidates, key=lambda pair: float(np.dot(pair[0], normal)))
    return best[1] if float(np.dot(best[0], normal)) > 0.99 else None


def usable_tangents(tangents: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Each tangent made unit and orthogonal to its normal, its w +1 or -1; one with no direction left
    (zero, along the normal, not finite) gets a direction orthogonal to the normal."""
    tangents = np.nan_to_num(np.asarray(tangents, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    normals = np.nan_to_num(np.asarray(normals, np.float64))
    n_length = np.linalg.norm(normals, axis=1, keepdims=True)
    n = np.where(n_length > 1e-12, normals / np.maximum(n_length, 1e-12), [0.0, 0.0, 1.0])
    t = tangents[:, :3] - n * np.sum(tangents[:, :3] * n, axis=1, keepdims=True)
    lost = np.linalg.norm(t, axis=1) < 1e-6
    axis = np.where(np.abs(n[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])   # the axis least along n
    fallback = axis - n * np.sum(axis * n, axis=1, keepdims=True)
    t[lost] = fallback[lost]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    w = np.where(tangents[:, 3] < 0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1)


def tangents_repaired(path: Path, source: Path | None = None) -> dict:
    """Rewrite the TANGENT of the .glb/.gltf at `path` in place: the input `source`'s own where a vertex
    matches one of its vertices, every one usable (usable_tangents). Returns counts for the report."""
    gltf = GltfBuffers(path)
    own = input_tangents(source) if source is not None else {}
    kept = fixed = total = 0
    for size, positions, normals, uvs, index, tangents in _primitives(gltf):
        new = tangents.copy()
        if own:
            for row, key in enumerate(_keys(size, positions, uvs)):
                tangent = _own(own[key], normals[row]) if key in own else None
                if tangent is not None:
                    new[row], kept = tangent, kept + 1
        usable = usable_tangents(new, normals)
        fixed += int(np.sum(np.abs(usable - new).max(axis=1) > 1e-4))
        total += len(new)
        gltf.write(index, usable)
    if total:
        gltf.save()
    return {"tangents": total, "input_tangents_kept": kept, "tangents_made_usable": fixed}
