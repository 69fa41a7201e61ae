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
from pathlib import Path

import numpy as np

from .atomic import write_bytes_atomic, write_json_atomic
from .errors import InputError
from .imageio import linear_to_srgb, read_color_image, read_image, write_image
from .maps import PBRMaps
from .mesh import Mesh


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


def is_asset_folder(path: str | Path) -> bool:
    path = Path(path)
    return path.is_dir() and (path / "mesh.npz").is_file()


def load_asset_folder(folder: str | Path) -> tuple[Mesh, PBRMaps]:
    folder = Path(folder)
    if not is_asset_folder(folder):
        raise InputError(f"'{folder}' is not a SceneFit asset folder (it has no mesh.npz).")
    meta_path = folder / "material.json"
    material = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    with np.load(folder / "mesh.npz") as data:
        mesh = Mesh.from_arrays(data["positions"], data["faces"], data["uvs"],
                                data["normals"] if "normals" in data else None,
                                name=material.get("name", folder.name))
    base_path = folder / "base_color.png"
    if not base_path.is_file():
        raise InputError(f"Asset folder '{folder}' has no base_color.png.")
    channels = {}
    for name, default in (("roughness", 0.5), ("metallic", 0.0)):
        path = folder / f"{name}.png"
        channels[name] = read_image(path)[..., 0] if path.is_file() else float(material.get(name, default))
    normal_path = folder / "normal.png"
    normal = read_image(normal_path)[..., :3] if normal_path.is_file() else None
    return mesh, PBRMaps(base_color=read_color_image(base_path), normal=normal, **channels)
