"""Which light critic a run uses: the user's, or for "auto" the diffusion critic when Stable Diffusion 2's
base weights are on this machine. Without torch: a run decides it before any model loads."""
from __future__ import annotations

from ...base.decision import Decision
from ...guidance import models as guidance_models
from ...guidance.models import ModelConfig


def critic_choice(asked: str, models: ModelConfig) -> Decision:
    """The light critic for `asked` ("auto", "diffusion" or "none"): auto is the diffusion critic when the
    SD2 base weights are on this machine (never a download), else none. `scenefit light`, Blender's
    Estimate Light and a batch light job decide it here; the whole pipeline follows its run's guidance
    (core.run.guidance_found), which also needs the inpainting weights."""
    if asked != "auto":
        return Decision(asked, "the user's choice")
    found, where = guidance_models.models_available(models, need_inpaint=False)
    if found:
        return Decision("diffusion", f"Stable Diffusion 2 found ({where})")
    return Decision("none", "Stable Diffusion 2 weights are not on this machine, so the prior sets the scales")
