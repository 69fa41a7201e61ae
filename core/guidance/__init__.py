"""Diffusion guidance: model loading, score-distillation critics (SDS/VSD), LoRA ε_ψ, reference feature
injection, and the local/global views they score.

models.py     locate_models / load_guidance_models / load_depth_estimator (the one place models are loaded)
critics.py    ScoreCritic, CriticConfig: ∇z = w_t w_n (ε_φ - (λ ε_ψ + (1 - λ) ε))
lora.py       LoraCritic: peft adapter on the base UNet + camera/light class embedding
injection.py  ReferenceInjector: attention processors concatenating the reference's K, V
views.py      local view on solid colours, global view crops in the photo, the 9-channel inpainting input
weighting.py  timesteps, w_t, λ schedule, ⟨camera, normal⟩ map, guard rails
"""
from importlib import import_module
from typing import TYPE_CHECKING, Any

from ..scene.placement import Placement
from .models import GuidanceModels, ModelConfig, load_guidance_models, locate_models, models_available

if TYPE_CHECKING:
    from .critic_config import CRITIC_TYPES, CriticConfig
    from .critics import CriticOutput, ScoreCritic
    from .injection import ReferenceInjector
    from .lora import LoraCritic, camera_condition

# The critics, LoRA and injection load torch (a second or more): imported when first named, so a RunConfig's
# ModelConfig (built on Blender's main thread) or the model store does not load it.
_TORCH_NAMES = {"CRITIC_TYPES": "critic_config", "CriticConfig": "critic_config", "CriticOutput": "critics",
                "ScoreCritic": "critics", "ReferenceInjector": "injection", "LoraCritic": "lora",
                "camera_condition": "lora"}


def __getattr__(name: str) -> Any:
    if name in _TORCH_NAMES:
        return getattr(import_module(f"{__name__}.{_TORCH_NAMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "CRITIC_TYPES", "CriticConfig", "CriticOutput", "GuidanceModels", "LoraCritic", "ModelConfig", "Placement",
    "ReferenceInjector", "ScoreCritic", "camera_condition", "load_guidance_models", "locate_models",
    "models_available",
]
