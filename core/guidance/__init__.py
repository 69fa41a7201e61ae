"""Diffusion guidance: model loading, score-distillation critics (SDS/VSD), LoRA ε_ψ, reference feature
injection, and the local/global views they score.

models.py     locate_models / load_guidance_models / load_depth_estimator (the one place models are loaded)
critics.py    ScoreCritic, CriticConfig: ∇z = w_t w_n (ε_φ - (λ ε_ψ + (1 - λ) ε))
lora.py       LoraCritic: peft adapter on the base UNet + camera/light class embedding
injection.py  ReferenceInjector: attention processors concatenating the reference's K, V
views.py      local view on solid colours, global view crops in the photo, the 9-channel inpainting input
weighting.py  timesteps, w_t, λ schedule, ⟨camera, normal⟩ map, guard rails
"""
from ..scene.placement import Placement
from .critics import CRITIC_TYPES, CriticConfig, CriticOutput, ScoreCritic
from .injection import ReferenceInjector
from .lora import LoraCritic, camera_condition
from .models import GuidanceModels, ModelConfig, load_guidance_models, locate_models, models_available

__all__ = [
    "CRITIC_TYPES", "CriticConfig", "CriticOutput", "GuidanceModels", "LoraCritic", "ModelConfig", "Placement",
    "ReferenceInjector", "ScoreCritic", "camera_condition", "load_guidance_models", "locate_models",
    "models_available",
]
