"""The bundled example, end to end: what `make demo` runs (`scenefit run` on it, and a sheet).

Inputs are made here, never downloaded: Suzanne with a procedural material baked by Blender's
Cycles into image maps, and a photo cut from one of the CC0 HDR maps inside the bpy wheel,
exposed and clipped to 8 bits as a camera would.
"""
from __future__ import annotations

from .core.base.names import GUIDANCE_TYPES

import shutil
import subprocess
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from .core.data.asset_io import is_asset_folder, load_asset_folder
from .core.pipeline.layout import RunLayout, camera_of
from .core.stages.compose import ComposeInputs, compose_to_folder
from .core.data.imageio import read_image, write_image
from .core.data.photo import load_photo
from .core.render.photo import develop_photo, perspective_view, studiolight_path
from .core.base.report import write_report
from .core.render.backend import environment_info
from .core.render.environment import constant_environment, load_environment
from .core.texture.views import contact_sheet
from .core.pipeline.presets import stage_config
from .core.base.progress import ProgressCallback, emit
from .core.pipeline.run import RunConfig, run_pipeline
from .core.scene.camera import PhotoCamera
from .core.scene.placement import Placement
from .core.texture.surface_layout import texture_view
from .core.texture.bake import load_neural_texture

DEMO_STUDIOLIGHT = "interior"
DEMO_PHOTO_CAMERA = PhotoCamera(yaw_deg=60.0, pitch_deg=-12.0, fov_deg=60.0, width=768, height=512)
DEMO_PLACEMENT = (0.5, 0.75)  # where the asset stands, as a fraction of the photo's width and height
DEMO_SIZE = 0.3               # the fraction of the photo's height it spans


def make_example(folder: Path) -> str:
    """Make the example asset with Blender in a child process (it resets Blender's file); reuse it if present."""
    if is_asset_folder(folder):
        return "reused"
    code = f"from scenefit.devtools.example_asset import make_example_asset; make_example_asset({str(folder)!r})"
    subprocess.run([sys.executable, "-c", code], check=True)
    return "made by Blender (Suzanne, Smart UV Project, procedural material baked by Cycles)"


def make_photo(path: Path) -> dict:
    hdr = read_image(studiolight_path(DEMO_STUDIOLIGHT))[..., :3]
    photo = develop_photo(perspective_view(hdr, DEMO_PHOTO_CAMERA))
    write_image(path, photo.astype(np.float32) / 255.0)
    return {"source": f"bpy studiolights/world/{DEMO_STUDIOLIGHT}.exr (CC0)",
            "camera": asdict(DEMO_PHOTO_CAMERA)}


def run_demo(out: Path, preset: str = "balanced", progress: ProgressCallback | None = None,
             refresh: bool = False, guidance: str = "auto") -> dict:
    """`scenefit run` on the bundled example, plus the same composite under a constant light, and a sheet:
    photo | composite under a constant light | composite under the estimated light."""
    started = time.perf_counter()
    out = Path(out)
    # Texture adaptation needs Stable Diffusion 2: "sd2" insists (a missing model stops the demo here,
    # before any work), "auto" uses it when its weights are on this machine, "none" skips it.
    from .core.base.errors import InputError
    from .core.guidance import ModelConfig, locate_models

    if guidance not in GUIDANCE_TYPES:
        raise InputError(f"guidance must be 'auto', 'sd2' or 'none', got {guidance!r}.")
    if guidance == "sd2":
        locate_models(ModelConfig(), need_inpaint=True)
    inputs = out / "input"
    if refresh and inputs.exists():
        shutil.rmtree(inputs)

    t = time.perf_counter()
    emit(progress, "example", 0, 1, "making the example asset with Blender")
    example_origin = make_example(inputs / "asset")
    photo_info = make_photo(inputs / "photo.png")
    emit(progress, "example", 1, 1, example_origin)
    inputs_seconds = time.perf_counter() - t

    # The whole pipeline, resumable: a second `make demo` reuses every stage.
    mesh, maps = load_asset_folder(inputs / "asset")
    asset_mesh = mesh
    config = RunConfig(preset=preset, guidance_type=guidance, photo_camera=DEMO_PHOTO_CAMERA, size=DEMO_SIZE,
                       prompt="a monkey head sculpture standing in a living room, its painted surface dusty and "
                              "worn, photo")
    run = run_pipeline(mesh, maps, inputs / "photo.png", DEMO_PLACEMENT, out, config, progress=progress,
                       bake_skipped_why="the bundled example is a SceneFit asset folder; `scenefit run` on a "
                                        ".glb/.gltf/.obj/.fbx/.blend file bakes a game asset")

    # The same composite under a constant light of the estimated map's mean radiance: what the
    # direction of the light adds.
    t = time.perf_counter()
    layout = RunLayout(out)
    estimated = load_environment(layout.file("light", "light"))
    constant = constant_environment(estimated.reshape(-1, 3).mean(axis=0))
    compose_stage = run.stages["compose"].report
    texture_path = Path(compose_stage["inputs"]["texture"])
    photo, photo_read = load_photo(inputs / "photo.png")
    texture = load_neural_texture(texture_path)
    view = texture_view(texture, mesh)
    mesh, stack = view.mesh, view.stack(texture)
    camera, _ = camera_of(out, photo.shape[1], photo.shape[0])   # the run's camera stage
    placement = Placement.parse(DEMO_PLACEMENT, (photo.shape[1], photo.shape[0])).pixel((photo.shape[0], photo.shape[1]))
    constant_report = compose_to_folder(
        ComposeInputs(mesh, stack, photo, placement, constant, camera),
        stage_config("compose", preset, size=DEMO_SIZE, spp=compose_stage["spp"]), out / "constant",
        {"light": f"constant, the estimated map's mean radiance {np.round(constant[0, 0], 4).tolist()}"})
    rows = {"photo | composite under a constant light | composite under the estimated light": [
        photo, read_image(out / "constant" / "composite.png")[..., :3], read_image(run.composite)[..., :3]]}
    constant_seconds = time.perf_counter() - t

    t = time.perf_counter()
    prior = adapted_by_the_test_prior(out, asset_mesh, inputs / "photo.png", texture_path,
                                      ComposeInputs(mesh, stack, photo, placement, estimated, camera),
                                      compose_stage["spp"], preset, progress)
    if prior is not None:
        rows[f"adapted by SceneFit's small TEST prior to '{PRIOR_INSTRUCTION}' (real adaptation uses SD2) | "
             "before | after"] = [np.full_like(photo, 0.12), read_image(run.composite)[..., :3],
                                  read_image(Path(prior["composite"]))[..., :3]]
    write_image(out / "sheet.png", contact_sheet(rows))
    prior_seconds = time.perf_counter() - t

    report: dict[str, Any] = {
        "stage": "demo",
        "preset": preset,
        "inputs": {"asset": example_origin, "photo": photo_info, "placement": DEMO_PLACEMENT},
        "stage_status": run.stage_status(),
        "convert": run.stages["convert"].report,
        "lighting": run.stages["light"].report,
        "adapt": run.stages["adapt"].to_report(),
        "compose": compose_stage,
        "constant_light_compose": {k: constant_report[k] for k in ("spp", "shadow", "outputs", "timings_seconds")},
        "test_prior_adapt": prior or {"status": "skipped", "why": f"the test prior is not at {PRIOR_FOLDER} "
                                                                    "(a checkout's devtools/prior)"},
        "sheet": str(out / "sheet.png"),
        "timings_seconds": {"inputs": round(inputs_seconds, 3), "run": run.seconds,
                            "constant_light_compose": round(constant_seconds, 3),
                            "test_prior_adapt": round(prior_seconds, 3)},
        "environment": environment_info(),
    }
    report["seconds_total"] = round(time.perf_counter() - started, 3)
    write_report(out / "report.json", report)
    return report


# The known-answer prior (devtools/prior): a 2.5 MB diffusion model SceneFit trains itself to measure its
# adaptation against, never a model for artists' work. The demo shows adaptation with it, labelled as such.
PRIOR_FOLDER = Path(__file__).resolve().parent / "devtools" / "prior"
PRIOR_INSTRUCTION = "make it blue"


def adapted_by_the_test_prior(out: Path, mesh, photo_path: Path, texture_path: Path, composed: ComposeInputs,
                              spp: int, preset: str, progress: ProgressCallback | None) -> dict[str, Any] | None:
    """The run's converted texture edited by the test prior ("make it blue", its known answer) and composed as
    the run's composite was (`composed`: its photo, placement, light and camera); None when the prior is not
    here (an installed extension carries no devtools)."""
    from .core.guidance import ModelConfig
    from .core.pipeline.run import GivenOutputs

    if not (PRIOR_FOLDER / "base" / "model_index.json").is_file():
        return None
    models = ModelConfig(base_model=str(PRIOR_FOLDER / "base"), inpaint_model=str(PRIOR_FOLDER / "inpaint"),
                         dtype_type="fp32", local_files_only=True)
    # The known-answer tests' small settings: 32-px views (the prior's own size), a few dozen steps.
    config = RunConfig(preset="draft", guidance_type="sd2", mode="edit", object_prompt="a monkey head",
                       instruction=PRIOR_INSTRUCTION, models=models, stage_overrides={"adapt": {
                           "iterations": 40, "stages": ((1.0, 32, 2, (300, 980)),), "views": 8,
                           "views_per_step": 1, "lr_texture": 2e-2, "checkpoint_every": 0, "preview_every": 0}})
    adapted = run_pipeline(mesh, None, photo_path, DEMO_PLACEMENT, out / "test_prior", config, progress=progress,
                           stages=("adapt",), given=GivenOutputs(texture=texture_path))
    texture = load_neural_texture(Path(adapted.outputs("adapt")["weights"]))
    view = texture_view(texture, mesh)
    folder = out / "test_prior" / "compose"
    compose_to_folder(replace(composed, mesh=view.mesh, maps=view.stack(texture)),
                      stage_config("compose", preset, size=DEMO_SIZE, spp=spp), folder,
                      {"texture": "the run's converted texture edited by the test prior"})
    return {"status": adapted.stages["adapt"].status, "instruction": PRIOR_INSTRUCTION,
            "models": str(PRIOR_FOLDER), "composite": str(folder / "composite.png"),
            "note": "a small test prior SceneFit trains to check its adaptation against known answers; real "
                    "adaptation uses Stable Diffusion 2"}
