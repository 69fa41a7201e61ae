"""The model manager's buttons in the add-on's Preferences: Download (a background job with bytes, speed
and Esc / Cancel; a cancelled download resumes where it stopped), Remove (after a confirmation) and Open
Folder, for the Stable Diffusion 2 base and inpainting models and the depth model."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from ..workers import background
from .prefs import ADDON_PACKAGE, depth_model_preference, model_config, offline, preferences
from .jobs import JobOperator

MODEL_ITEMS = (
    ("base", "Stable Diffusion 2 base", "The diffusion model that restyles the texture"),
    ("inpaint", "Stable Diffusion 2 inpainting", "The diffusion model that paints the light map beyond the photo"),
    ("depth", "Depth model", "The model that measures how far each pixel of an indoor photo is"),
)
DOWNLOAD_JOB = "Download"


def model_specs(context=None):
    """The three models as the preferences name them, and the cache they are looked for in."""
    from ..core.guidance import model_store
    from ..core.guidance.models import hub_cache

    models = model_config(context, job=False)   # (not model_settings: its depth config's module imports torch)
    return model_store.model_specs(models, depth_model_preference(context)), hub_cache(models.cache_dir)


def model_states(context=None) -> list:
    """Each model's state, size and folder (file system only: cheap enough for a panel's draw)."""
    from ..core.guidance import model_store

    specs, cache = model_specs(context)
    return [model_store.model_state(spec, cache) for spec in specs]


def model_state(context, key: str):
    from ..core.guidance import model_store

    specs, cache = model_specs(context)
    return model_store.model_state(model_store.spec_named(specs, key), cache)


def downloading() -> background.Job | None:
    """The model download running now (None when the running job, if any, is another)."""
    job = background.active_job()
    return job if job is not None and job.name.startswith(DOWNLOAD_JOB) and not job.state.finished else None


def download_work(data: dict, progress, cancel) -> dict:
    """The job's thread: one model fetched into the cache, its progress in megabytes with the speed."""
    from ..core.guidance import model_store

    state = model_store.download_model(data["spec"], data["cache"], model_store.in_megabytes(progress), cancel)
    return state.as_dict()


def download_job(context, key: str) -> tuple[str, dict]:
    """(job name, plain data) of the download of model `key` (main thread): what `download_work` gets."""
    from ..core.base.errors import InputError
    from ..core.guidance import model_store

    specs, cache = model_specs(context)
    spec = model_store.spec_named(specs, key)
    if spec.is_folder:
        raise InputError(f"The {spec.label} is the folder '{spec.model}'; there is nothing to download.")
    return f"{DOWNLOAD_JOB} {spec.label}", {"spec": spec, "cache": cache}


class SCENEFIT_OT_download_model(JobOperator):
    """Download this model into the model cache, in the background (Esc or Cancel stops it; the next
    Download goes on from where it stopped)"""

    bl_idname = "scenefit.download_model"
    bl_label = "Download"
    bl_options = {"REGISTER", "INTERNAL"}
    job_name = DOWNLOAD_JOB

    model: EnumProperty(name="Model", items=MODEL_ITEMS, description="Which model to download")

    @classmethod
    def poll(cls, context):
        if offline(context):
            cls.poll_message_set("Downloads are off: Blender's Allow Online Access, or the add-on's Offline switch")
            return False
        if background.active_job() is not None and not background.active_job().state.finished:
            cls.poll_message_set("Another SceneFit job is running")
            return False
        return True

    def prepare(self, context):
        self.job_name, data = download_job(context, self.model)
        return download_work, data

    def modal(self, context, event):
        answer = super().modal(context, event)
        for window in context.window_manager.windows:   # the Preferences window shows the bar too
            for area in window.screen.areas:
                if area.type == "PREFERENCES":
                    area.tag_redraw()
        return answer

    def apply(self, context, result) -> str:
        from ..core.guidance.model_store import format_bytes

        return f"{result['label']}: {format_bytes(result['bytes_on_disk'])} in {result['where']}"


class SCENEFIT_OT_remove_model(bpy.types.Operator):
    """Delete this model from the model cache (other programs that use the same cache lose it too); a
    model given as your own folder is never deleted"""

    bl_idname = "scenefit.remove_model"
    bl_label = "Remove"
    bl_options = {"REGISTER", "INTERNAL"}

    model: EnumProperty(name="Model", items=MODEL_ITEMS, description="Which model to remove")

    @classmethod
    def poll(cls, context):
        if downloading() is not None:
            cls.poll_message_set("A model is downloading; cancel it first")
            return False
        return True

    def invoke(self, context, event):
        state = model_state(context, self.model)
        return context.window_manager.invoke_confirm(
            self, event, title=f"Remove {state.label}?", confirm_text="Remove", icon="WARNING",
            message=f"Deletes {state.where or state.cache} from the model cache.")

    def execute(self, context):
        from ..core.base.errors import SceneFitError
        from ..core.guidance import model_store

        specs, cache = model_specs(context)
        spec = model_store.spec_named(specs, self.model)
        try:
            freed = model_store.remove_model(spec, cache)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{spec.label}: removed {model_store.format_bytes(freed)}" if freed
                    else f"{spec.label} was not in the model cache")
        return {"FINISHED"}


def model_folder(context, key: str) -> str:
    """The folder Open Folder shows: the model's own, else the cache it would go into."""
    state = model_state(context, key)
    return state.where or state.cache


class SCENEFIT_OT_open_model_folder(bpy.types.Operator):
    """Show this model's folder (or the model cache, while it is missing) in the file manager"""

    bl_idname = "scenefit.open_model_folder"
    bl_label = "Open Folder"
    bl_options = {"REGISTER", "INTERNAL"}

    model: EnumProperty(name="Model", items=MODEL_ITEMS, description="Whose folder to show")

    def execute(self, context):
        from pathlib import Path

        folder = Path(model_folder(context, self.model))
        while not folder.is_dir() and folder != folder.parent:   # a cache not made yet: its nearest folder
            folder = folder.parent
        bpy.ops.wm.path_open(filepath=str(folder))
        return {"FINISHED"}


def earlier_model_cache() -> str | None:
    """The folder earlier SceneFit versions downloaded models into ('models' in the extension's user folder,
    which Blender deletes with the extension), when it holds a model: offered, never used unasked."""
    from pathlib import Path

    try:
        folder = Path(bpy.utils.extension_path_user(ADDON_PACKAGE, path="models", create=False))
    except (ValueError, KeyError):   # not installed as an extension (development)
        return None
    return str(folder) if folder.is_dir() and any(folder.glob("models--*")) else None


class SCENEFIT_OT_use_earlier_model_cache(bpy.types.Operator):
    """Look for models in the folder an earlier SceneFit downloaded them into, instead of downloading them again
    (it is deleted with the extension: move it elsewhere first to keep it)"""

    bl_idname = "scenefit.use_earlier_model_cache"
    bl_label = "Use Earlier Downloads"
    bl_options = {"REGISTER", "INTERNAL"}

    @classmethod
    def poll(cls, context):
        if earlier_model_cache() is None or preferences(context) is None:
            cls.poll_message_set("No models from an earlier SceneFit were found")
            return False
        return True

    def execute(self, context):
        folder = earlier_model_cache()
        preferences(context).model_cache = folder
        self.report({"INFO"}, f"Model cache: {folder}")
        return {"FINISHED"}


classes = (SCENEFIT_OT_download_model, SCENEFIT_OT_remove_model, SCENEFIT_OT_open_model_folder,
           SCENEFIT_OT_use_earlier_model_cache)

register, unregister = bpy.utils.register_classes_factory(classes)
