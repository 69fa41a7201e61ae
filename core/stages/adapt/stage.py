"""The adapt stage's run: adapt_texture (AdaptSystem built, stepped until done or cancelled, finished),
write_adapt (the texture baked in the asset's own UVs, and the report), and adapt_and_bake (both, the
asset's UVs checked first)."""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from ...base.decision import decisions_to_dict
from ...base.errors import Cancelled
from ...base.progress import ProgressCallback, check_cancel, emit
from ...data.materials import mesh_raster
from ...data.mesh import Mesh, normalize_to_unit_sphere
from ...guidance.models import GuidanceModels, load_guidance_models
from ...scene.camera import PhotoCamera
from ...scene.placement import Placement
from ...texture.bake import bake_maps
from ...texture.neural_texture import NeuralTexture
from ...texture.surface_layout import adapting_view
from .config import AdaptConfig
from .distributed import join_process_group, rank_world
from .stage_data import AdaptInputs, AdaptResult
from .system import AdaptSystem


def adapt_texture(inputs: AdaptInputs, config: AdaptConfig, progress: ProgressCallback | None = None,
                  cancel: threading.Event | None = None, checkpoint_dir: str | Path | None = None,
                  models: GuidanceModels | None = None, cache_constants: bool = True) -> AdaptResult:
    """Run the adapt stage; returns a new NeuralTexture (the input texture is left as it was).

    Models are located (and a missing one reported) before any work. With `checkpoint_dir`, a
    checkpoint is written every `checkpoint_every` iterations and a run with the same settings
    resumes from it.
    """
    system = AdaptSystem.build(inputs, config, models, checkpoint_dir, cache_constants)
    done = saved = system.start
    try:
        for iteration in range(system.start, config.iterations):
            check_cancel(cancel)
            metrics = system.step(iteration, cancel)
            done = iteration + 1
            system.after_step(iteration, metrics, progress)
            saved = done if system.checkpointed(done) else saved
    except Cancelled:
        system.keep(done, saved)   # the steps made so far, for a resume
        raise
    return system.finish()


def adapt_and_bake(mesh: Mesh, texture: NeuralTexture | None, config: AdaptConfig, out_dir: str | Path,
                   photo: np.ndarray | None = None, placement: Placement | None = None,
                   envmap: np.ndarray | None = None, resolution: int | None = None,
                   photo_camera: PhotoCamera | None = None, progress: ProgressCallback | None = None, cancel: threading.Event | None = None,
                   models: GuidanceModels | None = None) -> tuple[AdaptResult, dict]:
    """Adapt (or, for "generate", make) the asset's texture and bake it into out_dir/maps.

    mesh is the asset as given (normalised here); photo_camera: the light stage's camera for the photo
    (None: its default for the photo); checkpoints go to out_dir/checkpoint so that
    running the same command again resumes. Returns the result and a report dict (on ranks other
    than 0 of a distributed run nothing is written and the report's outputs are empty).
    """
    out_dir = Path(out_dir)
    join_process_group()  # under torchrun: this rank's GPU is chosen before the models load
    if models is None:  # missing weights stop the run here, before any work
        models = load_guidance_models(config.models, config.views_type == "local+global")
    normalized, _ = normalize_to_unit_sphere(mesh)
    res = texture.config.resolution if texture is not None else int(resolution or config.texture.resolution)
    raster = mesh_raster(normalized, res)   # each material's own cell and wrap mode, as the renderer reads them
    # Where the asset's UVs share texels the result could not differ per surface: a new layout.
    emit(progress, "adapt", 0, config.iterations, "checking whether the UVs give every surface its own texels")
    view, layout, uv_report = adapting_view(texture, normalized)
    inputs = AdaptInputs(mesh=view.mesh if view else normalized, raster=view.raster if view else raster,
                         texture=texture, photo=photo, placement=placement, envmap=envmap,
                         photo_camera=photo_camera, base_logit=view.base_logit if view else None, layout=layout)
    result = adapt_texture(inputs, config, progress=progress, cancel=cancel, checkpoint_dir=out_dir / "checkpoint",
                           models=models)
    check_cancel(cancel)
    result.config, result.bake_raster, result.uv_report = config, raster, uv_report
    return result, write_adapt(result, out_dir)


def write_adapt(result: AdaptResult, folder: str | Path) -> dict:
    """The adapted texture baked into folder/maps in the asset's own UVs (on rank 0 only of a distributed
    run: one writer); returns the stage's report (its outputs empty on the other ranks)."""
    raster, config, paths = result.bake_raster, result.config, {}
    assert raster is not None and config is not None   # (adapt_and_bake sets both)
    if rank_world()[0] == 0:
        paths = bake_maps(result.texture, raster.position, raster.border, raster.fill_index, Path(folder) / "maps")
    per_it = result.seconds_per_iteration()
    return {
        "stage": "adapt", "config": config.to_dict(), "schedule": config.schedule(),
        "decisions": decisions_to_dict(result.decisions), "uv_layout": result.uv_report,
        "iterations": result.iterations, "resumed_from": result.resumed_from, "seconds": round(result.seconds, 3),
        "seconds_per_iteration": {k: round(v, 4) for k, v in per_it.items()},
        "peak_memory_mb": None if result.peak_memory_mb is None else round(result.peak_memory_mb, 1),
        "last_metrics": result.history[-1] if result.history else {},
        "outputs": {k: str(v) for k, v in paths.items()},
    }
