"""Run All and Adapt handed to the worker environment the preferences name (a Ray cluster, or another
SceneFit install with CUDA torch), and their results applied when they come back.

The job object is the same background job as a local one (workers/background.py): its work function is
workers.remote.send_run, which streams the worker's progress events and previews into the job's
queue, passes a cancel on to the worker and unpacks the job's folder into a new run folder. So the
panel, the status bar, Esc and the Cancel button work unchanged; only the gathering (`remote_work`)
and the applying (`apply_remote`, main thread) are this module's.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlparse

import bpy

if TYPE_CHECKING:   # (workers.remote and its batch modules load when a job is sent, not at every click)
    from ..workers.remote import RemoteRun

from ..core.base.errors import InputError
from ..core.pipeline.registry import STAGES
from ..workers.job_seam import read_run_outcome
from .folders import last_finished_run
from .prefs import preferences
from .results import apply_layout_results, materials_words

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
    """(work function, RemoteRun) that run the whole pipeline in the worker environment at `address`: the
    same request a Run All here sends (operators/run_request.gather_run), its RunConfig as it is, the
    worker finding the models in its own cache and on its own device. Every material of the active object,
    or the selected objects as one asset (their atlas travels, and each material's maps are baked here from
    the texture that comes back)."""
    from dataclasses import replace

    from ..workers.remote import RemoteRun, send_run
    from .run_request import gather_run

    guidance = op.chosen_guidance(context) if hasattr(op, "chosen_guidance") else context.scene.scenefit.guidance
    request, layout = gather_run(op, context, "A worker environment runs the pipeline that fits the asset into "
                                              "a photo; other modes run in this Blender", guidance)
    config = request.config
    check_models_reach_the_worker(address, {"base model": config.models.base_model,
                                            "inpainting model": config.models.inpaint_model,
                                            "depth model": config.depth_model})
    config = replace(config, models=replace(config.models, cache_dir=None, device_type="auto"))
    op._request = request = replace(request, config=config)
    # The job's folder comes back whole as this run's new folder (nothing of it while it runs or if cancelled).
    folder = Path(request.out)
    earlier = last_finished_run(folder)   # its stages with this run's settings and inputs are reused, as here
    sent = RemoteRun(name=folder.name, worker=address, out=str(folder.parent), stages=REMOTE_STAGES, run=config,
                     photo=request.photo, at=request.placement, asset=layout.plan(context),
                     earlier=str(earlier) if earlier else None)
    # as a local Run All hands them over: planned here, decoded in the job, procedural chains baked between ticks
    materials = layout.bake_data() if len(layout.materials) > 1 else None
    if materials is None:
        return send_run, sent
    return send_run_per_material, RemoteRunPerMaterial(sent, materials)


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


@dataclass(frozen=True)
class RemoteRunPerMaterial:
    """A RemoteRun of an asset of several materials, with what each material's bake here needs."""

    run: "RemoteRun"
    materials: dict


def send_run_per_material(data: RemoteRunPerMaterial, progress=None, cancel=None) -> dict:
    """send_run for an asset of several materials: the worker fits their atlas; each material's maps
    are then baked here from the texture that came back, in its own UVs (workers.blender_jobs.material_results,
    as after a local Run All), into the run folder's materials/."""
    from ..workers.blender_jobs import material_results
    from ..workers.remote import send_run

    result = send_run(data.run, progress, cancel)
    texture = read_run_outcome(result["folder"]).texture
    result["material_maps"] = material_results(data.materials, texture, Path(result["folder"]) / "materials")
    return result


def apply_remote(op, context, result: dict) -> str:
    """Main thread: the worker's results as new datablocks (the artist's own are kept); a Run's are
    applied by Run's own apply, as after a local run (the same outcome, job_seam.run_outcome)."""
    outcome = read_run_outcome(result["folder"], tuple(result.get("material_maps", ())))
    done = f"Done on the worker ({result['report'].get('seconds', 0):.0f} s): "
    if op.job_name == "run":
        return done + op.apply(context, outcome).removeprefix("Done: ")
    if outcome.stage != "adapt":
        raise InputError(f"The worker did not adapt the texture: {outcome.adapt_skipped or 'no reason given'}; "
                         f"its results are in '{result['folder']}'.")
    mats = apply_layout_results(context, op._layout, outcome, "adapt")
    return done + materials_words(mats)
