"""The score-distillation critic's settings (CriticConfig) and the names its schedules take: data a stage
config holds, without torch (core/guidance/critics.py and weighting.py compute with them)."""
from __future__ import annotations

from dataclasses import dataclass

from ..base.errors import InputError, check_choice

WEIGHTING_TYPES = ("sds", "uniform")          # w_t = 1 - ᾱ_t (DreamFusion) or 1
ANNEAL_TYPES = ("linear", "none")             # timestep window moving from high to low noise, or fixed
NORMAL_WEIGHT_TYPES = ("cosine", "none")      # ⟨camera, normal⟩ term in w_t, or none
CRITIC_TYPES = ("sds", "vsd")
REFERENCE_TYPES = ("inject", "none")


@dataclass(frozen=True)
class CriticConfig:
    """critic_type "vsd" uses ε̂ = λ ε_ψ + (1 - λ) ε with λ annealed from 1 to lambda_end; "sds" is λ = 0.

    control_scale is s_c, injection_fraction is p (reference_type "inject"); the paper's defaults
    are s_c = 0, p = 1, s_cf = 7.5, λ = 1.
    """

    critic_type: str = "vsd"
    guidance_scale: float = 7.5
    lora_guidance_scale: float = 1.0
    lambda_end: float = 1.0
    weighting_type: str = "sds"
    reference_type: str = "inject"
    control_scale: float = 0.0
    injection_fraction: float = 1.0
    grad_clip: float | None = None

    def __post_init__(self) -> None:
        check_choice("critic_type", self.critic_type, CRITIC_TYPES)
        check_choice("reference_type", self.reference_type, REFERENCE_TYPES)
        check_choice("weighting_type", self.weighting_type, WEIGHTING_TYPES)
        if not 0.0 <= self.lambda_end <= 1.0:
            raise InputError(f"lambda_end must be in [0, 1], got {self.lambda_end}.")
        if not 0.0 <= self.control_scale <= 1.0:
            raise InputError(f"control_scale s_c must be in [0, 1], got {self.control_scale}.")
        if not 0.0 <= self.injection_fraction <= 1.0:
            raise InputError(f"injection_fraction p must be in [0, 1], got {self.injection_fraction}.")
        if self.guidance_scale < 0 or self.lora_guidance_scale < 0:
            raise InputError("Guidance scales must not be negative.")
        if self.grad_clip is not None and not self.grad_clip > 0:
            raise InputError(f"grad_clip must be positive or None, got {self.grad_clip}.")
