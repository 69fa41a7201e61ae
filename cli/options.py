"""What several commands share: loading an asset, the progress display, the lighting options, the
model options. Declared once so an option means the same thing in every command."""
from __future__ import annotations

import argparse

PRESETS = ("draft", "balanced", "final")


def load_asset(path: str, object_name: str | None = None):
    """(Mesh, PBRMaps) from an asset folder, or from a file Blender reads (needs bpy)."""
    from ..core.asset_io import is_asset_folder, load_asset_folder

    if is_asset_folder(path):
        return load_asset_folder(path)
    from ..blender_io.asset_file import load_asset_file

    return load_asset_file(path, object_name)


def load_asset_materials(path: str, object_name: str | None = None):
    """core.materials.AssetMaterials: every material of the asset, with what was read and dropped."""
    from ..core.asset_io import is_asset_folder, load_asset_folder
    from ..core.materials import AssetMaterials, Material

    if is_asset_folder(path):
        mesh, maps = load_asset_folder(path)
        return AssetMaterials(mesh=mesh, materials=(Material(name=mesh.name, maps=maps,
                                                             read=(f"asset folder '{path}'",)),))
    from ..blender_io.asset_file import load_asset_materials as load_file

    return load_file(path, object_name)


def progress(args):
    from ..core.progress import TerminalProgress

    return None if getattr(args, "quiet", False) else TerminalProgress()


def environment(args):
    """(environment map, label) from --envmap, --studiolight or --ambient."""
    from ..core.photo import studiolight_path
    from ..core.pipeline import constant_environment, load_environment

    if getattr(args, "envmap", None):
        return load_environment(args.envmap), f"environment map {args.envmap}"
    if getattr(args, "studiolight", None):
        return load_environment(studiolight_path(args.studiolight)), f"Blender studio light '{args.studiolight}'"
    value = float(getattr(args, "ambient", 1.0))
    return constant_environment([value] * 3), f"constant environment of radiance {value}"


def add_asset_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("asset", help="a SceneFit asset folder (mesh.npz + maps) or a .blend/.glb/.gltf/.obj/.fbx file")
    p.add_argument("--object", help="mesh object to use from a Blender file (default: the largest)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_lighting_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--envmap", help="equirectangular HDR map (EXR/HDR) to light the asset")
    p.add_argument("--studiolight", help="one of Blender's bundled HDR maps (studio, interior, city, forest, ...)")
    p.add_argument("--ambient", type=float, default=1.0, help="constant environment radiance when no map is given")


def add_model_args(p: argparse.ArgumentParser) -> None:
    """Where the diffusion models come from (adapt, light, ...)."""
    p.add_argument("--base-model", help="hub id or folder (default stabilityai/stable-diffusion-2-base)")
    p.add_argument("--inpaint-model", help="hub id or folder (default stabilityai/stable-diffusion-2-inpainting)")
    p.add_argument("--cache-dir", help="Hugging Face cache folder to look in")
    p.add_argument("--offline", action="store_true", help="never download (also HF_HUB_OFFLINE=1)")


def model_config(args):
    from ..core.guidance import ModelConfig

    return ModelConfig(**{k: v for k, v in (("base_model", args.base_model), ("inpaint_model", args.inpaint_model),
                                            ("cache_dir", args.cache_dir)) if v}, local_files_only=args.offline)
