"""Run All and Adapt handed to the worker environment the preferences name (a Ray cluster, or another
SceneFit install with CUDA torch), and their results applied when they come back.

The job object is the same background job as a local one (workers/background.py): its work function is
workers.remote.work_remotely, which streams the worker's progress events and previews into the job's
queue, passes a cancel on to the worker and unpacks the job's folder into a new run folder. So the
panel, the status bar, Esc and the Cancel button work unchanged; only the gathering (`remote_work`)
and the applying (`apply_remote`, main thread) are this module's.
"""
from __future__ import annotations

from pathlib import Path
from urllib.parse import urlparse

import bpy

from ..core.base.errors import InputError
from ..core.pipeline.registry import STAGES
from .asset import scene_layout
from .folders import last_finished_run, run_folder
from .photo import photo_view
from .prefs import depth_model_preference, model_settings, preferences
from .results import apply_layout_results, materials_words, result_targets

# What the worker runs for each operator: the whole pipeline but the bake (Bake Asset writes the file here).
REMOTE_STAGES = tuple(stage for stage in STAGES if stage != "bake")
LOCAL_HOSTS = ("", "localhost", "127.0.0.1", "::1")


def worker_address(context) -> str | None:
    """Where the preferences send jobs: a Ray address, a Python interpreter, or None (this Blender).

    A Ray cluster on another machine is network access: refused unless Blender's online access is on.
    """
    prefs = preferences(context)
    if prefs is None or prefs.worker_type == "LOCAL":
        return None
    if prefs.worker_type == "INSTALL":
        python = Path(bpy.path.abspath(prefs.worker_python)).expanduser() if prefs.worker_python else None
        if python is None or not python.is_file():
            raise InputError(f"The SceneFit install's Python '{prefs.worker_python}' does not exist; set it in the "
                             "add-on preferences (Jobs), or run jobs in this Blender.")
        return str(python)
    address = prefs.ray_address.strip() or "local"
    if not is_local_address(address) and not bpy.app.online_access:
        raise InputError(f"Blender's online access is off, so SceneFit does not contact the Ray cluster at "
                         f"'{address}'; allow it in Preferences > System, or use the address 'local'.")
    return address


def sends_every_job(context) -> bool:
    """Whether every Run All and Adapt goes to the worker (else only those sent from the question)."""
    prefs = preferences(context)
    return worker_address(context) is not None and getattr(prefs, "worker_when", "ALWAYS") == "ALWAYS"


def is_local_address(address: str) -> bool:
    """'local' (a cluster started here) or an address on this machine."""
    if address == "local":
        return True
    host = urlparse(address if "://" in address else f"ray://{address}").hostname or ""
    return host in LOCAL_HOSTS


def remote_work(op, context, address: str) -> tuple:
    """(work function, plain data) that run the whole pipeline in the worker environment at `address`; the
    operator's quick-look settings travel as stage overrides. Run All and Adapt take what they take here:
    every material of the active object, or the selected objects as one asset (their atlas travels, and
    each material's maps are baked here from the texture that comes back)."""
    from ..workers.remote import work_remotely

    settings = context.scene.scenefit
    photo, layout = scene_layout(op, context, "A worker environment runs the pipeline that fits the asset into a "
                                              "photo; other modes run in this Blender")
    # as a local Run All hands them over: planned here, decoded in the job, procedural chains baked between ticks
    materials = layout.bake_data() if len(layout.materials) > 1 else None
    op._layout = result_targets(layout)   # where the results go: every slot of the asset
    objects, name = [bpy.data.objects[n] for n in layout.objects], layout.name
    models, _ = model_settings(context)
    from dataclasses import replace

    # The worker finds the models in its own cache and on its own device.
    models = replace(models, cache_dir=None, device_type="auto")
    check_models_reach_the_worker(address, {"base model": models.base_model, "inpainting model": models.inpaint_model,
                                            "depth model": depth_model_preference(context)})
    # The job's folder comes back whole as this run's new folder (nothing of it while it runs or if cancelled).
    folder = run_folder(context, op.job_name, name)
    earlier = last_finished_run(folder)   # its stages with this run's settings and inputs are reused, as here
    # How the photo is seen, as Run All here sees it (operators/photo.photo_view): the artist's camera or the
    # panel's values, where the asset stands, and the artist's sun.
    from ..core.pipeline.run_table import run_table
    from ..workers.blender_jobs import quick_overrides, view_config

    view = photo_view(context, photo, objects)
    # The run as a local Run All builds it (workers/blender_jobs.view_config), sent as a job's table.
    config = view_config(view, preset=settings.preset, prompt=settings.prompt, stage_overrides=quick_overrides(op),
                         scene_type=settings.scene_type, depth_model=depth_model_preference(context))
    return (work_remotely if materials is None else work_remotely_per_material), {
        "asset": layout.plan(context), "photo": str(photo), "worker": address, "at": tuple(view["placement"]),
        "out": str(folder.parent), "name": folder.name, "stages": REMOTE_STAGES, "models": models,
        "materials": materials, "earlier": str(earlier) if earlier else None,
        **{k: v for k, v in run_table(config).items() if v is not None}}


def check_models_reach_the_worker(address: str, models: dict[str, str | None]) -> None:
    """One sentence (InputError) where a model the preferences give as a folder on this machine would be
    sent to a Ray cluster on another host, which cannot read it (a hub id is found in the worker's own
    cache; a cluster or an install on this machine reads the folder)."""
    if Path(address).is_file() or is_local_address(address):   # another install's Python, or this machine
        return
    for what, value in models.items():
        if value and Path(bpy.path.abspath(value)).expanduser().is_dir():
            raise InputError(f"The {what} is a folder on this machine ('{value}'), which the Ray cluster at "
                             f"'{address}' cannot read; give its hub id in the add-on preferences (Models), "
                             "or run jobs in this Blender.")


def work_remotely_per_material(data: dict, progress=None, cancel=None) -> dict:
    """work_remotely for an asset of several materials: the worker fits their atlas; each material's maps
    are then baked here from the texture that came back, in its own UVs (workers.blender_jobs.material_results,
    as after a local Run All), into the run folder's materials/."""
    from ..workers.remote import work_remotely
    from ..workers.blender_jobs import material_results

    result = work_remotely(data, progress, cancel)
    texture = run_result(result["folder"], result["report"])["texture"]
    result["material_maps"] = material_results(data, texture, Path(result["folder"]) / "materials")
    return result


def run_result(folder: str | Path, report: dict) -> dict:
    """What Blender applies from a worker's job folder (the run pipeline's layout): the last texture's
    maps (adapt's, else convert's), the light, the composite, each stage's status."""
    folder = Path(folder)
    stages = report["stages"]["run"]["stages"]
    last = "adapt" if stages.get("adapt", {}).get("status") in ("ran", "reused") else "convert"
    outputs = stages[last]["report"]["outputs"]

    def path(value):
        return str(folder / value) if isinstance(value, str) else value

    light = folder / "light" / "light.exr"
    composite = folder / "compose" / "composite.png"
    return {"stage": last, "report": str(folder / "report.json"), "texture": path(outputs["weights"]),
            "maps": {k: path(outputs[k]) for k in ("base_color", "roughness", "metallic")},
            "hdr": str(light) if light.is_file() else "", "composite": str(composite) if composite.is_file() else "",
            "stages": {name: stage["status"] for name, stage in stages.items()},
            "adapt_skipped": stages.get("adapt", {}).get("why", ""),
            # the camera the light stage used, which the Cycles set-up takes (as after a local run)
            "camera": {k: v for k, v in stages.get("light", {}).get("report", {}).get("decisions", {})
                       .get("photo_camera", {}).items() if k in ("fov_deg", "pitch_deg", "roll_deg")}}


def apply_remote(op, context, result: dict) -> str:
    """Main thread: the worker's results as new datablocks (the artist's own are kept); a Run's are
    applied by Run's own apply, as after a local run."""
    shaped = dict(run_result(result["folder"], result["report"]), material_maps=result.get("material_maps", []))
    done = f"Done on the worker ({result['report'].get('seconds', 0):.0f} s): "
    if op.job_name == "run":
        return done + op.apply(context, shaped).removeprefix("Done: ")
    if shaped["stage"] != "adapt":
        raise InputError(f"The worker did not adapt the texture: {shaped['adapt_skipped'] or 'no reason given'}; "
                         f"its results are in '{result['folder']}'.")
    mats = apply_layout_results(context, op._layout, shaped, "adapt")
    return done + materials_words(mats)
