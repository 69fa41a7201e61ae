"""A SceneFit asset folder: the mesh as arrays plus its PBR maps, readable without Blender.

    mesh.npz          positions (V,3), faces (F,3), uvs (V,2) OpenGL v, normals (V,3) optional
    base_color.png    sRGB
    roughness.png     linear, optional (else the constant in material.json)
    metallic.png      linear, optional (else the constant in material.json)
    normal.png        tangent-space normal map, linear, optional
    material.json     {"name": ..., "roughness": float?, "metallic": float?}
"""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from ..base.atomic import write_bytes_atomic, write_json_atomic
from ..base.errors import InputError
from .asset_files import obj_material_libraries
from .imageio import linear_to_srgb, read_color_image, read_image, write_image
from .maps import PBRMaps
from .mesh import Mesh, check_face_indices


def save_asset_folder(mesh: Mesh, maps: PBRMaps, folder: str | Path) -> Path:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {"positions": mesh.positions, "faces": mesh.faces, "uvs": mesh.uvs}
    if mesh.normals is not None:
        arrays["normals"] = mesh.normals
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    write_bytes_atomic(folder / "mesh.npz", buffer.getvalue())
    write_image(folder / "base_color.png", linear_to_srgb(maps.base_color))
    if maps.normal is not None:
        write_image(folder / "normal.png", maps.normal, dtype="uint16")
    material: dict = {"name": mesh.name}
    for name in ("roughness", "metallic"):
        value = getattr(maps, name)
        if isinstance(value, np.ndarray):
            write_image(folder / f"{name}.png", value, dtype="uint16")
        else:
            material[name] = float(value)
    write_json_atomic(folder / "material.json", material)
    return folder


# The files Blender reads as an asset (blender_io.asset_file has an importer for each but .blend).
ASSET_FILE_SUFFIXES = (".blend", ".glb", ".gltf", ".obj", ".fbx", ".ply", ".usd", ".usda", ".usdc", ".usdz")


def is_asset_folder(path: str | Path) -> bool:
    path = Path(path)
    return path.is_dir() and (path / "mesh.npz").is_file()


def resolve_asset_path(path: str | Path) -> Path:
    """`path`, or the one file Blender reads in a folder that is not an asset folder (a downloaded glTF
    beside its .bin and textures); a folder holding several such files is refused, naming them."""
    path = Path(path)
    if not path.is_dir() or is_asset_folder(path):
        return path
    found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in ASSET_FILE_SUFFIXES)
    if len(found) > 1:
        raise InputError(f"'{path}' holds {len(found)} asset files ({', '.join(p.name for p in found[:4])}"
                         f"{', ...' if len(found) > 4 else ''}); give the one to use.")
    return found[0] if found else path


def check_asset_path(path: str | Path) -> None:
    """InputError (one sentence) unless `path` is an asset folder or a non-empty file of a kind Blender
    reads: checked before Blender or torch is loaded, so a mistyped path is refused at once."""
    path = Path(path)
    if path.is_dir():
        if not is_asset_folder(path):
            raise InputError(f"'{path}' is a folder but not a SceneFit asset folder (it has no mesh.npz); give an "
                             "asset folder or a .blend/.glb/.gltf/.obj/.fbx file.")
        return
    if not path.is_file():
        raise InputError(f"Asset file '{path}' does not exist.")
    if path.suffix.lower() not in ASSET_FILE_SUFFIXES:
        raise InputError(f"SceneFit cannot read '{path.suffix.lower()}' files; use one of "
                         f"{', '.join(sorted(ASSET_FILE_SUFFIXES))}, or an asset folder.")
    if path.stat().st_size == 0:
        raise InputError(f"Asset file '{path}' is empty; export it again.")
    if path.suffix.lower() == ".obj":   # Blender reads it without, grey and silent: the maps never arrive

        named, same_name = obj_material_libraries(path)
        missing = [library for library in named if not library.is_file()]
        if missing and (same_name in named or not same_name.is_file()):   # (else Blender reads that one)
            raise InputError(f"'{path.name}' names the material library '{missing[0].name}', which is not in "
                             f"'{missing[0].parent}'; put it there with the maps it names, or export the OBJ "
                             "again with its materials.")


def load_asset_folder(folder: str | Path) -> tuple[Mesh, PBRMaps]:
    folder = Path(folder)
    if not is_asset_folder(folder):
        raise InputError(f"'{folder}' is not a SceneFit asset folder (it has no mesh.npz).")
    material = _read_material(folder / "material.json")
    mesh = _read_mesh(folder / "mesh.npz", str(material.get("name", folder.name)))
    base_path = folder / "base_color.png"
    if not base_path.exists():
        raise InputError(f"Asset folder '{folder}' has no base_color.png.")
    channels = {}
    for name, default in (("roughness", 0.5), ("metallic", 0.0)):
        path = folder / f"{name}.png"
        if path.exists():  # a folder of that name is an error (read_image says so), not "no map"
            channels[name] = read_image(path)[..., 0]
            continue
        value = material.get(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"'{name}' in '{folder / 'material.json'}' must be a number between 0 and 1, "
                             f"got {value!r}.")
        channels[name] = float(value)  # type: ignore[assignment]
    normal_path = folder / "normal.png"
    normal = read_image(normal_path)[..., :3] if normal_path.is_file() else None
    return mesh, PBRMaps(base_color=read_color_image(base_path), normal=normal, **channels)


def _read_material(path: Path) -> dict:
    if not path.exists():
        return {}
    try:
        material = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise InputError(f"'{path}' is not valid JSON ({error}); fix it or delete it to use the defaults.") from None
    if not isinstance(material, dict):
        raise InputError(f"'{path}' must hold a JSON object such as {{\"roughness\": 0.5}}.")
    return material


def _read_mesh(path: Path, name: str) -> Mesh:
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in ("positions", "faces", "uvs") if key not in data.files]
            if missing:
                raise InputError(f"'{path}' has no {' or '.join(missing)} array; SceneFit needs positions, "
                                 "faces and uvs (re-export the asset).")
            arrays = {key: np.asarray(data[key]) for key in ("positions", "faces", "uvs", "normals")
                      if key in data.files}
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise InputError(f"'{path}' cannot be read ({error or 'truncated or not an .npz file'}); "
                         "re-export the asset.") from None
    faces = arrays["faces"]
    if faces.dtype.kind not in "iu":
        raise InputError(f"'{path}' stores its faces as {faces.dtype}; face indices must be integers "
                         "(re-export the asset).")
    positions = arrays["positions"]
    if positions.ndim == 2 and faces.ndim == 2:   # shapes are Mesh's to refuse; this names the file
        check_face_indices(faces, len(positions), f"'{path}'")
    return Mesh.from_arrays(arrays["positions"], faces, arrays["uvs"], arrays.get("normals"), name=name)
