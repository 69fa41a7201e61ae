"""The convert stage: an asset's own PBR maps -> a neural texture (paper appendix, "Textured Mesh").

run_convert(ConvertInputs, ConvertConfig, progress, cancel) -> ConvertResult; write_convert(result, folder)
bakes it into PBR maps and returns the report; convert_and_bake is both.

Two methods fit the same network:
- "direct": regression in texture space. The asset's maps live in the same UV layout the neural
  texture is baked into, so every covered texel has an exact target. This is the default: it
  reaches the same quality as inverse rendering in a fraction of the time (`make bench`).
- "inverse": the paper's inverse rendering, matching Mitsuba renders of the asset from random views
  (lr 0.02 annealed to 0.001). Kept for assets whose appearance is not a plain UV texture.
"""
from __future__ import annotations

import threading
import time
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ..base.errors import InputError
from ..base.limits import check_texture_size
from ..data.maps import PBRMaps
from ..data.materials import AssetMaterials, atlas_grid, atlas_maps, atlas_mesh, atlas_raster, atlas_slices, mesh_raster
from ..data.mesh import Mesh, NormalizeTransform, normalize_to_unit_sphere
from ..base.progress import ProgressCallback, check_cancel, emit
from ..data.scene_needs import (constant_channels, material_constant_channels, report as needs_report,
                                texture_size_for_screen)
from ..texture.bake import bake_maps
from ..texture.fit_direct import fit_direct, masked_psnr
from ..texture.fit_inverse import fit_inverse_rendering
from ..texture.neural_texture import NeuralTexture
from .convert_config import ConvertConfig
from ..data.uv_raster import UVRaster, rasterize_uv

# Strict JSON has no infinity: an exact start's PSNR (no error at all) is written as this.
EXACT_PSNR_DB = 100.0


@dataclass
class ConvertResult:
    texture: NeuralTexture
    raster: UVRaster
    mesh: Mesh                       # normalised into the radius-0.5 sphere
    transform: NormalizeTransform    # back to the asset's object space
    target: torch.Tensor             # (H, W, 5) the asset's maps at the texture's resolution
    psnr: float                      # on covered texels (sRGB base colour, linear roughness/metallic)
    seconds: float
    method_type: str
    iterations: int
    history: list[float] = field(default_factory=list)
    decisions: dict = field(default_factory=dict)
    config: ConvertConfig | None = None           # set by the stage (core.pipeline.run_convert), for its report
    constants: dict = field(default_factory=dict)  # channels that stay a number: name -> value
    materials_report: dict = field(default_factory=dict)   # an asset's materials and notes, for the report

    def predicted(self) -> torch.Tensor:
        with torch.no_grad():
            return self.texture.texture(self.raster.position, self.raster.border, self.raster.fill_index)


def choose_resolution(maps: PBRMaps, config: ConvertConfig) -> tuple[int, str]:
    """The texture size to fit and bake at, and why (reported to the user)."""
    if config.resolution is not None:
        return config.resolution, "set by the user"
    native = max(maps.resolution)
    if config.screen_px is not None:
        needed = texture_size_for_screen(config.screen_px)
        if needed < min(native, config.max_resolution):
            return needed, (f"the object is {config.screen_px} px tall in the composite, so {needed} texels show "
                            f"every detail it can (the asset has {native})")
    if native <= config.max_resolution:
        return native, f"the asset's own texture size ({native})"
    return config.max_resolution, f"the asset's {native} texels capped at the preset's {config.max_resolution}"


def target_stack(maps: PBRMaps, resolution: int) -> np.ndarray:
    """(R, R, 5) float32 maps at the fitting resolution (area-averaged when shrinking, map by map)."""
    return np.clip(maps.stacked_at(resolution, resolution), 0.0, 1.0).astype(np.float32)


def asset_stack(maps: PBRMaps, what: str = "the asset's maps") -> np.ndarray:
    """(H, W, 5) float32 maps at their own size, the largest height and width among them, for rendering
    the asset as it is. Never squared: a 16384x16 base colour squared to 16384² took 21 GB to render
    16 pixels. Refused in one sentence (`what` names the asset) when it would not fit in memory."""
    arrays = [maps.base_color] + [m for m in (maps.roughness, maps.metallic) if isinstance(m, np.ndarray)]
    height, width = max(a.shape[0] for a in arrays), max(a.shape[1] for a in arrays)
    check_texture_size(height, width, what)
    return np.clip(maps.stacked_at(height, width), 0.0, 1.0).astype(np.float32)


def convert_asset(mesh: Mesh, maps: PBRMaps, config: ConvertConfig = ConvertConfig(),
                  progress: ProgressCallback | None = None, cancel: threading.Event | None = None,
                  rasterize: Callable[[Mesh, int], UVRaster] = mesh_raster) -> ConvertResult:
    """Fit a neural texture to the asset's maps. Nothing given is modified.

    rasterize(normalised mesh, resolution): its UV raster; by default as the renderer reads it
    (core.materials.mesh_raster: an atlas mesh's materials in their own cells, each wrapped as its
    sampler says; the mesh's wrap mode, else repeat)."""
    started = time.perf_counter()
    normalized, transform = normalize_to_unit_sphere(mesh)
    resolution, why = choose_resolution(maps, config)
    emit(progress, "convert", 0, config.iterations, f"rasterising UVs at {resolution}²")
    raster = rasterize(normalized, resolution)
    if raster.coverage == 0:
        raise InputError(f"Mesh '{mesh.name}' covers no texel of its UV map at {resolution}².")
    target = torch.from_numpy(target_stack(maps, resolution))
    texture = NeuralTexture(config.texture_config(resolution), seed=config.seed)

    if config.init_type == "exact":   # the asset's own maps are the texture: nothing to fit
        texture.set_base(target)
        history, iterations = [], 0
        emit(progress, "convert", config.iterations, config.iterations, "exact start: the asset's own maps")
    elif config.method_type == "direct":
        def report(it: int, loss: float, psnr: float) -> None:
            emit(progress, "convert", it + 1, config.iterations, "direct fit", {"psnr": psnr})

        fit = fit_direct(texture, raster.position, raster.mask, target, iterations=config.iterations,
                         lr_start=config.lr_start, lr_end=config.lr_end, batch_texels=config.batch_texels,
                         seed=config.seed, progress=report, cancel=cancel)
        history, iterations = fit.psnr_history, fit.iterations
    else:
        plan = texture.plan(raster.position, raster.border, raster.fill_index)
        fit = fit_inverse_rendering(lambda: texture.texture_from_plan(plan), texture.parameters(), normalized,  # type: ignore[assignment]
                                    target, iterations=config.iterations, lr_start=config.lr_start,
                                    lr_end=config.lr_end, render_size=config.render_size, spp=config.spp,
                                    seed=config.seed, progress=progress, cancel=cancel)
        history, iterations = fit.loss_history, fit.iterations

    result = ConvertResult(texture=texture, raster=raster, mesh=normalized, transform=transform, target=target,
                           psnr=0.0, seconds=0.0, method_type=config.method_type, iterations=iterations,
                           history=history)
    result.psnr = min(masked_psnr(result.predicted(), target, raster.mask), EXACT_PSNR_DB)
    result.seconds = time.perf_counter() - started
    result.decisions = {
        "start": config.init_type, "start_reason": "the asset's own maps and a zero residual (--init exact)"
        if config.init_type == "exact" else "the paper's fit of the network to the maps (--init fit)",
        "resolution": resolution, "resolution_reason": why,
        "method": config.method_type if config.init_type == "fit" else "none (nothing fitted)",
        "hash_grid": {"levels": config.texture.n_levels, "log2_table": config.texture.log2_table,
                      "finest_resolution": config.texture.finest_resolution}, "uv_coverage": round(raster.coverage, 4),
    }
    return result


def convert_materials(asset: AssetMaterials, config: ConvertConfig = ConvertConfig(),
                      progress: ProgressCallback | None = None,
                      cancel: threading.Event | None = None) -> ConvertResult:
    """Fit one neural texture to every material of the asset (see core.materials for the atlas).

    The preset's size cap (or --resolution) applies to each material's cell, so a two-material
    asset is not fitted at half the detail of a one-material one. Reports each material's PSNR.
    """
    maps = [m.maps for m in asset.materials]
    if len(maps) == 1:
        result = convert_asset(asset.mesh, maps[0], config, progress=progress, cancel=cancel,
                               rasterize=partial(rasterize_uv, wrap=asset.materials[0].wrap))
        cell = result.raster.resolution[0]
    else:
        largest = max(maps, key=lambda m: max(m.resolution))
        cell, why = choose_resolution(largest, config)
        size = atlas_grid(len(maps)) * cell
        # Each material wraps in its own cell, as `scenefit bake` rasterises it in its own UV square.
        result = convert_asset(atlas_mesh(asset.mesh), atlas_maps(maps, cell), replace(config, resolution=size),
                               progress=progress, cancel=cancel,
                               rasterize=lambda normalized, size: atlas_raster(normalized, asset.mesh, size, asset.wraps))
        result.decisions["resolution"] = cell
        result.decisions["resolution_reason"] = f"per material: {why}; {len(maps)} materials in a {size}² atlas"
    predicted = result.predicted()
    per_material = []
    for material, (rows, cols) in zip(asset.materials, atlas_slices(len(maps), cell)):
        mask = result.raster.mask[rows, cols]
        psnr = min(masked_psnr(predicted[rows, cols], result.target[rows, cols], mask), EXACT_PSNR_DB) \
            if mask.any() else float("nan")
        per_material.append({"name": material.name, "psnr_db": round(psnr, 3),
                             "uv_coverage": round(float(mask.mean()), 4)})
    result.decisions["materials"] = per_material
    return result


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
        result = convert_asset(asset, maps, config, progress=progress, cancel=cancel)  # type: ignore[arg-type]
    result.config = config
    if inputs.keep_constants:
        channels = (material_constant_channels([m.maps for m in asset.materials], [m.name for m in asset.materials])
                    if isinstance(asset, AssetMaterials) else constant_channels(maps))  # type: ignore[arg-type]
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
        "config": asdict(result.config),  # type: ignore[arg-type]
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
