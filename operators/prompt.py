"""Write Prompt: the Style prompt written by a language model from the object and the scene (the
paper's GPT-4 step), or the manually combined template when offline, for the artist to edit.

The chat request runs in a worker thread (a slow model must not freeze Blender); a modal timer
puts the answer into the Style prompt on the main thread. Under `blender -b` and from scripts,
execute() asks synchronously.
"""
from __future__ import annotations

import queue
import threading

import bpy

from ..core.base.errors import SceneFitError
from .polls import needs_setting
from .prefs import preferences

# Adapt's edit mode wants an instruction; the other modes a description.
PROMPT_MODE = {"edit": "instruct"}


def gather_prompt_job(context) -> dict:
    """Everything the worker needs, read from bpy on the main thread: the request, the service
    (None when no endpoint is set) and the offline switches."""
    from ..core.guidance.prompting import PromptRequest, resolve_service

    settings = context.scene.scenefit
    prefs = preferences(context)
    mode = settings.mode
    photo = bpy.path.abspath(settings.photo_path) if settings.photo_path else ""
    request = PromptRequest(object_prompt=settings.object_prompt, scene_prompt=settings.scene_prompt,
                            mode_type=PROMPT_MODE.get(mode, "describe"), photo=photo if mode == "scene" else "")
    offline = bool(prefs and prefs.offline)
    service = None if offline else resolve_service(
        getattr(prefs, "prompt_endpoint", ""), getattr(prefs, "prompt_model", ""), getattr(prefs, "prompt_api_key", ""),
        key_source="add-on preferences")
    return {"request": request, "service": service, "offline": offline, "online_access": bpy.app.online_access,
            "target": "instruction" if mode == "edit" else "prompt"}


def run_prompt_job(job: dict):
    """The one place the operator calls core (worker thread: no bpy here)."""
    from ..core.guidance.prompting import write_prompt

    return write_prompt(job["request"], job["service"], offline=job["offline"], online_access=job["online_access"])


def apply_prompt(context, operator, target: str, result) -> None:
    """Put the prompt where the Style section shows it, and say how it was made."""
    settings = context.scene.scenefit
    setattr(settings, target, result.prompt)
    settings.prompt_source = (f"Written by {result.model}" + (" (cached)" if result.cached else "")
                              if result.model_written else f"Template (not model-written): {result.reason}")
    operator.report({"INFO"}, settings.prompt_source)
    for warning in result.warnings:
        operator.report({"WARNING"}, warning)


class SCENEFIT_OT_generate_prompt(bpy.types.Operator):
    """Write the prompt from the object and the scene with a language model (offline: a simple template); edit it before the run"""

    bl_idname = "scenefit.generate_prompt"
    bl_label = "Write Prompt"
    bl_options = {"REGISTER"}

    poll = needs_setting("object_prompt", "Say what the asset is first (the Object field above)")

    def execute(self, context):
        try:
            job = gather_prompt_job(context)
            result = run_prompt_job(job)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        apply_prompt(context, self, job["target"], result)
        return {"FINISHED"}

    def invoke(self, context, event):
        try:
            job = gather_prompt_job(context)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self._job, self._answers = job, queue.Queue()

        def work() -> None:
            try:
                self._answers.put(("done", run_prompt_job(job)))
            except SceneFitError as error:
                self._answers.put(("error", str(error)))
            except Exception as error:  # an unexpected failure still ends the modal loop
                self._answers.put(("error", f"Writing the prompt failed: {error!r}"))

        context.scene.scenefit.prompt_source = "Asking the language model…"
        threading.Thread(target=work, name="scenefit-prompt", daemon=True).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            kind, payload = self._answers.get_nowait()
        except queue.Empty:
            return {"RUNNING_MODAL"}
        context.window_manager.event_timer_remove(self._timer)
        if kind == "error":
            context.scene.scenefit.prompt_source = payload
            self.report({"ERROR"}, payload)
            return {"CANCELLED"}
        apply_prompt(context, self, self._job["target"], payload)
        return {"FINISHED"}


classes = (SCENEFIT_OT_generate_prompt,)

register, unregister = bpy.utils.register_classes_factory(classes)
