"""The add-on's preferences as the operators read them: offline, the model cache, the models and device."""
from __future__ import annotations

import bpy

ADDON_PACKAGE = __package__.rpartition(".")[0]


def preferences(context=None):
    """The add-on preferences, or None when SceneFit was registered without being enabled as an add-on."""
    addon = (context or bpy.context).preferences.addons.get(ADDON_PACKAGE)
    return addon.preferences if addon is not None else None


def offline(context=None) -> bool:
    """No downloads when the artist asked for it or Blender's online access is off."""
    prefs = preferences(context)
    return bool(prefs.offline if prefs is not None else False) or not bpy.app.online_access


def model_cache(context=None) -> str | None:
    """The preference's folder, else None: the Hugging Face cache (HF_HUB_CACHE / HF_HOME), where weights other
    tools fetched are found, and which outlives the extension (its user folder is deleted with it)."""
    prefs = preferences(context)
    if prefs is not None and prefs.model_cache:
        return bpy.path.abspath(prefs.model_cache)
    return None


def depth_model_preference(context=None) -> str | None:
    """The preferences' depth model (hub id or folder), None for the default: what a run's RunConfig/Job takes."""
    prefs = preferences(context)
    return (prefs.depth_model or None) if prefs is not None else None


def model_settings(context=None):
    """(ModelConfig, DepthConfig) from the preferences: hub ids or folders, cache, offline, device. The depth
    config's module imports torch: a job's click takes model_config alone."""
    from ..core.stages.light.depth import depth_config_for

    models = model_config(context, job=False)
    prefs = preferences(context)
    return models, depth_config_for(models, model=prefs.depth_model if prefs is not None else None)


def model_config(context=None, job: bool = True):
    """The ModelConfig of the preferences (hub ids or folders, cache, offline, device), without torch. A job's
    (job=True) never downloads: models come only through the manager (Download in the preferences), so a job
    starts at once, its cost is what was asked, and its cancel is never stuck in a download."""
    from ..core.guidance.models import ModelConfig

    prefs = preferences(context)
    cache, local_only = model_cache(context), job or offline(context)
    device = prefs.device if prefs is not None else "auto"
    kwargs = {}
    if prefs is not None:
        kwargs = {"base_model": prefs.base_model, "inpaint_model": prefs.inpaint_model,
                  "attention_slicing": prefs.attention_slicing, "vae_tiling": prefs.vae_tiling,
                  "cpu_offload": prefs.cpu_offload}
    return ModelConfig(cache_dir=cache, local_files_only=local_only, device_type=device, **kwargs)
