"""Stages strung together for the command line and the Blender operators: convert, bake, render, report."""
from __future__ import annotations

import platform
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from .atomic import write_json_atomic
from .backend import init_mitsuba
from .camera import Camera
from .convert import ConvertConfig, ConvertResult, convert_asset, convert_materials
from .errors import InputError
from .imageio import linear_to_srgb, read_color_image
from .maps import PBRMaps
from .materials import AssetMaterials
from .mesh import Mesh
from .progress import ProgressCallback, check_cancel, emit
from .render import AssetRenderer, SceneOptions
from .scene_needs import constant_channels, material_constant_channels, report as needs_report
from .texture.bake import bake_maps
from .texture.neural_texture import split_channels


def constant_environment(color, height: int = 32) -> np.ndarray:
    """A uniform environment of linear RGB `color` (the stand-in until light estimation runs)."""
    color = np.broadcast_to(np.asarray(color, np.float32), (3,))
    return np.broadcast_to(color, (height, 2 * height, 3)).copy()


def sun_environment(direction, sun_radiance: float = 2000.0, sky_radiance: float = 0.3, sun_radius_deg: float = 3.0,
                    height: int = 64) -> np.ndarray:
    """A grey sky with one small disc sun towards world `direction` (Blender's lat-long convention):
    hard-edged shadows with a known direction, for tests and benchmarks."""
    from .scene.frame import equirect_directions

    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    env = np.full((height, 2 * height, 3), sky_radiance, np.float32)
    env[equirect_directions(height, 2 * height) @ d > np.cos(np.radians(sun_radius_deg))] = sun_radiance
    return env


def load_environment(path: str | Path, max_height: int = 256) -> np.ndarray:
    """An equirectangular HDR map (EXR/HDR linear, or an 8-bit image decoded from sRGB), downsized for rendering."""
    import cv2

    env = read_color_image(path)
    h, w = env.shape[:2]
    if w != 2 * h:
        raise InputError(f"Environment map '{path}' is {w}x{h}; a latitude-longitude map is twice as wide as high.")
    check_environment(env, f"Environment map '{path}'")
    if h > max_height:
        env = cv2.resize(env, (2 * max_height, max_height), interpolation=cv2.INTER_AREA)
    return env.astype(np.float32)


def check_environment(env: np.ndarray, what: str = "The environment map") -> None:
    """Radiance is finite and never negative; anything else makes renders (and `mitsuba`) fail later."""
    if not np.isfinite(env).all():
        raise InputError(f"{what} holds NaN or infinite pixels; repair or re-export it.")
    if (env < 0).any():
        raise InputError(f"{what} holds negative pixels (light cannot be negative); clamp them to 0 and re-export.")


def tonemap_srgb(rgb: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear radiance -> display sRGB in [0, 1] (exposure, clip, sRGB curve)."""
    return linear_to_srgb(np.clip(np.asarray(rgb) * exposure, 0.0, 1.0))


def render_views(normalized_mesh: Mesh, stacks: dict[str, torch.Tensor], envmap: np.ndarray,
                 cameras: list[Camera], spp: int, progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None,
                 normal_map: np.ndarray | None = None) -> dict[str, list[np.ndarray]]:
    """Render every (H, W, 5) map stack from every camera with one scene; linear RGB images.

    normal_map: the asset's tangent-space normal map (PBRMaps.normal), used by every render: it is
    not fitted, so the original and the neural texture are shown on the same bumps."""
    shapes = {tuple(s.shape[:2]) for s in stacks.values()}
    images: dict[str, list[np.ndarray]] = {name: [] for name in stacks}
    env_t = torch.from_numpy(envmap)
    renderers = {shape: AssetRenderer(normalized_mesh, shape, envmap, SceneOptions(integrator_type="path"),
                                      normal_map=normal_map)
                 for shape in shapes}
    total, done = len(stacks) * len(cameras), 0
    with torch.no_grad():
        for name, stack in stacks.items():
            renderer = renderers[tuple(stack.shape[:2])]
            for i, camera in enumerate(cameras):
                check_cancel(cancel)
                out = renderer.render(camera, *split_channels(stack), env_t, spp=spp, seed=i)
                images[name].append(out.rgb.numpy())
                done += 1
                emit(progress, "render", done, total, f"{name} view {i + 1}")
    return images


def image_psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB between two display images in [0, 1]."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def contact_sheet(rows: dict[str, list[np.ndarray]], label_height: int = 22) -> np.ndarray:
    """A grid image (one labelled row per entry) of sRGB [0, 1] images."""
    import cv2

    strips = []
    for label, images in rows.items():
        strip = np.concatenate(images, axis=1)
        band = np.full((label_height, strip.shape[1], 3), 0.12, np.float32)
        cv2.putText(band, label, (6, label_height - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0.95, 0.95, 0.95), 1,
                    cv2.LINE_AA)
        strips.append(np.concatenate([band, strip], axis=0))
    return np.concatenate(strips, axis=0)


def environment_info() -> dict:
    backend = init_mitsuba()
    return {
        "mitsuba_variant": backend.variant, "variant_reason": backend.reason,
        "llvm_library": backend.llvm_library, "torch": torch.__version__,
        "machine": f"{platform.machine()}, {torch.get_num_threads()} torch threads, {platform.platform()}",
    }


@dataclass(frozen=True)
class ConvertInputs:
    """What the convert stage reads: a mesh with its maps, or every material of an asset (maps None:
    the maps are then fitted as the atlas, core.materials, and `scenefit bake` writes them per material
    in the asset's own UV layout). keep_constants: a roughness/metallic that holds one value stays that
    number (reported in decisions > channels, written in outputs as a float) instead of a baked 16-bit
    map; on by default, so no entry point can forget it (batch's convert-only jobs once did)."""

    asset: Mesh | AssetMaterials
    maps: PBRMaps | None = None
    keep_constants: bool = True


def run_convert(inputs: ConvertInputs, config: ConvertConfig = ConvertConfig(),
                progress: ProgressCallback | None = None, cancel: threading.Event | None = None) -> ConvertResult:
    """The convert stage: the asset's maps as a neural texture (which channels stay numbers decided here)."""
    asset, maps = inputs.asset, inputs.maps
    if isinstance(asset, AssetMaterials):
        result = convert_materials(asset, config, progress=progress, cancel=cancel)
    else:
        result = convert_asset(asset, maps, config, progress=progress, cancel=cancel)
    result.config = config
    if inputs.keep_constants:
        channels = (material_constant_channels([m.maps for m in asset.materials], [m.name for m in asset.materials])
                    if isinstance(asset, AssetMaterials) else constant_channels(maps))
        result.constants = {name: d.choice for name, d in channels.items() if d.choice != "map"}
        result.decisions["channels"] = {name: needs_report(d) for name, d in channels.items()}
    if isinstance(asset, AssetMaterials):
        result.materials_report = {
            "materials": [dict(m.report(), psnr_db=d["psnr_db"], uv_coverage=d["uv_coverage"])
                          for m, d in zip(asset.materials, result.decisions["materials"])],
            "notes": list(asset.notes)}
    return result


def write_convert(result: ConvertResult, folder: str | Path) -> dict:
    """The texture baked into `folder` (core.texture.bake); returns the stage's report."""
    paths = bake_maps(result.texture, result.raster.position, result.raster.border, result.raster.fill_index,
                      Path(folder), constants=result.constants)
    return {
        "stage": "convert",
        "config": asdict(result.config),
        "decisions": result.decisions,
        "psnr_covered_texels_db": round(result.psnr, 3),
        "seconds": round(result.seconds, 3),
        "iterations": result.iterations,
        "outputs": {k: v if isinstance(v, float) else str(v) for k, v in paths.items()},
        **result.materials_report,
    }


def convert_and_bake(mesh: Mesh | AssetMaterials, maps: PBRMaps | None, out_dir: str | Path,
                     config: ConvertConfig = ConvertConfig(), progress: ProgressCallback | None = None,
                     cancel: threading.Event | None = None, keep_constants: bool = True) -> tuple[ConvertResult, dict]:
    """run_convert then write_convert into `out_dir` (ConvertInputs says what mesh, maps and
    keep_constants mean); returns the result and the report."""
    result = run_convert(ConvertInputs(mesh, maps, keep_constants), config, progress, cancel)
    check_cancel(cancel)
    return result, write_convert(result, out_dir)


def write_report(path: str | Path, report: dict) -> Path:
    """report.json in strict JSON; paths inside the report's folder are written relative to it, so
    they stay right when the run's folder is swapped into place or moved."""
    path = Path(path)
    report = dict(report)
    report.setdefault("written_at", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    return write_json_atomic(path, relative_paths(report, path.parent.absolute()))


def relative_paths(value, folder: Path):
    if isinstance(value, dict):
        return {k: relative_paths(v, folder) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [relative_paths(v, folder) for v in value]
    if isinstance(value, (str, Path)) and str(value):
        candidate = Path(value)
        if candidate.is_absolute() or isinstance(value, Path):
            try:
                return candidate.absolute().relative_to(folder).as_posix()
            except ValueError:
                return str(value) if isinstance(value, Path) else value
    return value

