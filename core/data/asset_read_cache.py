"""A run folder's copy of what Blender read from the asset file, so that the next `scenefit run` into
the folder with the same files skips Blender's import: reading SheenChair took 24 of the 26.5 s a run
whose stages are all reused took (now 4.8 s).

The copy is used only when its key matches: the bytes of the asset file and of every file it refers to
(core.asset_files), the object asked for, and the code that reads them (SceneFit's reader modules and
Blender's version), so a changed texture, another --object or an upgrade reads the file again. Only
glTF and OBJ files are copied this way: theirs are the only references core.asset_files can list (an
FBX's or a .blend's external images are not), and a change to an unlisted file must never go unseen.
The copy is plain arrays and JSON (numpy's .npz read without pickle): data, never code.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import zipfile
import zlib
from importlib import metadata
from pathlib import Path
from typing import Annotated

import numpy as np
from annotated_types import Len

from .asset_files import asset_files
from ..base.atomic import write_bytes_atomic
from ..base.errors import InputError
from ..base.untrusted import Record, checked, parse_json
from .maps import PBRMaps
from .mesh import Mesh
from .uv_raster import WrapMode
from ..base.source_graph import reachable_sources

CACHE_FILE = ".asset-read.npz"
CACHEABLE = (".glb", ".gltf", ".obj")
# The code whose output the copy holds: Blender's reader and every module it can reach.
READER = "blender_io.asset_file"


def read_key(path: str | Path, object_name: str | None) -> str | None:
    """The key a copy of this read must carry, or None where the file's kind is not copied."""
    path = Path(path)
    if path.suffix.lower() not in CACHEABLE or not path.is_file():
        return None
    h = hashlib.sha256()
    h.update(json.dumps([object_name, _blender_version()]).encode())
    for source in reachable_sources(READER):
        h.update(source.read_bytes())
    for file in asset_files(path):
        h.update(file.name.encode() + b"\0" + file.read_bytes())
    return h.hexdigest()


def _blender_version() -> str:
    try:
        return metadata.version("bpy")
    except metadata.PackageNotFoundError:   # inside Blender: bpy is not a distribution there
        return "blender"


# What a copy may inflate to: the arrays of an asset with 4096-pixel maps are about 600 MB.
MAX_READ_BYTES = 2**30
# The arrays a copy may hold, and the numbers they may be (never objects: those would need pickle).
_ARRAYS = ("positions", "faces", "uvs", "base_color", "normals", "material_index", "normal", "roughness", "metallic")
_INDEX_ARRAYS = ("faces", "material_index")   # whole numbers, as save_read writes them


class _Meta(Record):
    """The copy's JSON beside its arrays."""

    key: str
    name: str
    wraps: list[Annotated[list[WrapMode], Len(2, 2)]]
    atlas: bool
    roughness: float | None = None
    metallic: float | None = None


def load_read(folder: str | Path, key: str | None) -> tuple[Mesh, PBRMaps] | None:
    """The (Mesh, PBRMaps) a run into `folder` saved under `key`, or None (no copy, another key, or a
    copy that does not read: damaged, of another shape, or inflating past MAX_READ_BYTES)."""
    path = Path(folder) / CACHE_FILE
    if key is None or not path.is_file():
        return None
    try:
        _check_inflated_size(path, MAX_READ_BYTES)
        with np.load(path, allow_pickle=False) as data:
            meta = checked(parse_json(str(data["meta"]), f"the asset-read copy '{path}'"), _Meta,
                           f"the asset-read copy '{path}'")
            if meta.key != key:
                return None
            arrays = {name: data[name] for name in data.files if name in _ARRAYS}
        if any(not np.issubdtype(a.dtype, np.number) or not np.isfinite(a).all() for a in arrays.values()):
            return None
        if any(not np.issubdtype(arrays[name].dtype, np.integer) for name in _INDEX_ARRAYS if name in arrays):
            return None   # (float faces would be cast to indices somewhere down the line: no copy of ours)
        mesh = Mesh(positions=arrays["positions"], faces=arrays["faces"], uvs=arrays["uvs"],
                    normals=arrays.get("normals"), name=meta.name, material_index=arrays.get("material_index"),
                    wraps=tuple((w[0], w[1]) for w in meta.wraps), atlas=meta.atlas)
        roughness, metallic = arrays.get("roughness", meta.roughness), arrays.get("metallic", meta.metallic)
        if roughness is None or metallic is None:   # (a copy without a channel is no copy)
            return None
        maps = PBRMaps(base_color=arrays["base_color"], normal=arrays.get("normal"), roughness=roughness,
                       metallic=metallic)
    # A copy that does not read whole is no copy: the asset is read again (JSONDecodeError is a ValueError).
    except (OSError, ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile, zlib.error, InputError):
        return None
    return mesh, maps


def _check_inflated_size(path: Path, limit: int) -> None:
    """ValueError unless the archive's members inflate to at most `limit` bytes in all and each array's
    header asks for no more than its member holds (numpy allocates what the header says before reading)."""
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        if sum(m.file_size for m in members) > limit:
            raise ValueError(f"{path} inflates past {limit} bytes")
        for member in members:
            with archive.open(member) as stream:
                version = np.lib.format.read_magic(stream)   # (numpy writes 1.0, or 2.0 for huge headers)
                header = {(1, 0): np.lib.format.read_array_header_1_0,
                          (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                if header is None:
                    raise ValueError(f"{member.filename} is .npy version {version}")
                shape, _, dtype = header(stream)
                if dtype.hasobject or math.prod(shape) * dtype.itemsize > member.file_size:
                    raise ValueError(f"{member.filename} asks for more than it holds")


def save_read(folder: str | Path, key: str | None, mesh: Mesh, maps: PBRMaps) -> Path | None:
    """Keep (mesh, maps) in `folder` under `key` (nothing where key is None)."""
    if key is None:
        return None
    arrays = {"positions": mesh.positions, "faces": mesh.faces, "uvs": mesh.uvs, "base_color": maps.base_color}
    for name, value in (("normals", mesh.normals), ("material_index", mesh.material_index), ("normal", maps.normal),
                        ("roughness", maps.roughness), ("metallic", maps.metallic)):
        if isinstance(value, np.ndarray):
            arrays[name] = value
    meta = {"key": key, "name": mesh.name, "wraps": [list(w) for w in mesh.wraps], "atlas": bool(mesh.atlas),
            "roughness": None if isinstance(maps.roughness, np.ndarray) else float(maps.roughness),
            "metallic": None if isinstance(maps.metallic, np.ndarray) else float(maps.metallic)}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, meta=np.array(json.dumps(meta)), **arrays)   # SheenChair: 32 MB, not 135
    return write_bytes_atomic(Path(folder) / CACHE_FILE, buffer.getvalue())
