"""The diffusion light critic: core/guidance's VSD ScoreCritic behind the light stage's critic interface.

    critic(renders (V, h, w, 3) linear HDR, CriticRequest) -> (V, h, w, 3) image-space gradients

Per view (appendix "Light Estimation"): the linear render is tone-mapped by the extended Reinhard
curve (the forward of the prior's inverse tone curve, so a clipped photo texel and the prior's HDR
texel look alike), sRGB-encoded to [0, 1], resized to the model's resolution and VAE-encoded; t is
drawn uniformly in request.t_range ([750, 990]); the ScoreCritic gives
∇z = w_t (ε_φ(z_t, text; CFG 7.5) - ε_ψ(z_t, text, camera)) (VSD, λ = 1), which autograd carries
back through the VAE and the tone curve to the render's pixels. ε_ψ then takes one LoRA step on the
detached latents, its learning rate annealed with the scales' (linearly to 0.1 x). ε_ψ is conditioned
on the view's camera and the current light (the appendix's c_x, c_y, c_r, c_v, b_v, taken from the
map the renders were made under: request.light, see hdr.LightVector). Text
conditioning is the prompt in the request (estimate.py's object prompt / SPHERE_PROMPT with the
dark-environment suffix and tint).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from ..guidance.critics import CriticConfig, ScoreCritic
from ..guidance.lora import AMBIENT_LIGHT, LoraCritic, camera_condition
from ..guidance.models import GuidanceModels
from ..guidance.views import linear_to_srgb_torch
from .hdr import DEFAULT_L_WHITE, CriticRequest


@dataclass(frozen=True)
class DiffusionCriticConfig:
    """The paper's light-critic settings: VSD with λ = 1, CFG 7.5, LoRA lr 1e-4 annealed to 0.1 x."""

    guidance_scale: float = 7.5
    lambda_vsd: float = 1.0
    lora_rank: int = 4
    lr_lora: float = 1e-4
    lr_lora_final_factor: float = 0.1
    condition_dropout: float = 0.1
    model_resolution: int = 512
    l_white: float = DEFAULT_L_WHITE        # the tone curve applied to renders before encoding
    negative_prompt: str = ""
    seed: int = 0

    def __post_init__(self) -> None:
        if self.guidance_scale < 0:
            raise InputError(f"guidance_scale must not be negative, got {self.guidance_scale}.")
        if not 0.0 <= self.lambda_vsd <= 1.0:
            raise InputError(f"lambda_vsd must be in [0, 1], got {self.lambda_vsd}.")
        if self.lora_rank < 1 or not self.lr_lora > 0 or not 0 < self.lr_lora_final_factor <= 1:
            raise InputError("lora_rank must be >= 1, lr_lora positive and lr_lora_final_factor in (0, 1].")
        if not 0.0 <= self.condition_dropout < 1.0:
            raise InputError(f"condition_dropout must be in [0, 1), got {self.condition_dropout}.")
        if self.model_resolution < 8 or self.model_resolution % 8:
            raise InputError(f"model_resolution must be a multiple of 8 (>= 8), got {self.model_resolution}.")
        if not self.l_white > 1.0:
            raise InputError(f"l_white must be above 1, got {self.l_white}.")


def tonemap_srgb_torch(radiance: torch.Tensor, l_white: float = DEFAULT_L_WHITE) -> torch.Tensor:
    """Linear HDR -> sRGB [0, 1] by the extended Reinhard curve L (1 + L / Lw^2) / (1 + L); differentiable."""
    x = radiance.clamp_min(0.0)
    return linear_to_srgb_torch(x * (1.0 + x / (l_white * l_white)) / (1.0 + x))


class DiffusionLightCritic:
    """VSD critic for the light scales; one LoRA ε_ψ shared by every view, told apart by its camera and
    conditioned on the current light."""

    def __init__(self, models: GuidanceModels, cameras, prompts: tuple[str, ...],
                 config: DiffusionCriticConfig = DiffusionCriticConfig()) -> None:
        if config.model_resolution // models.vae_scale_factor < 1:
            raise InputError("model_resolution is smaller than one latent texel.")
        self.models, self.config = models, config
        self.cameras = [(c.origin, c.forward) for c in cameras]
        for p in tuple(prompts) + (config.negative_prompt,):
            models.embed(p)
        self.lora = LoraCritic(models.unet, rank=config.lora_rank, lr=config.lr_lora,
                               condition_dropout=config.condition_dropout, seed=config.seed)
        self.score = ScoreCritic(models.unet, models.scheduler,
                                 CriticConfig(critic_type="vsd", guidance_scale=config.guidance_scale,
                                              lambda_end=config.lambda_vsd, reference_type="none"), lora=self.lora)
        self.rng = np.random.default_rng(config.seed)
        self.generator = torch.Generator().manual_seed(config.seed)
        self.history: list[dict] = []

    def condition(self, view: int, light: tuple[float, ...] | None) -> torch.Tensor:
        """ε_ψ's class condition: the view's camera-to-world matrix and the light vector (ambient if none)."""
        origin, forward = self.cameras[view]
        return camera_condition(origin, forward, AMBIENT_LIGHT if light is None else light)

    def _encode(self, image: torch.Tensor) -> torch.Tensor:
        x = (image * 2.0 - 1.0).to(self.models.device, self.models.vae.dtype)
        return self.models.vae.encode(x).latent_dist.mean.float() * self.models.latent_scale

    def _anneal_lora(self, request: CriticRequest) -> None:
        n = max(request.iterations - 1, 1)
        factor = 1.0 - (1.0 - self.config.lr_lora_final_factor) * min(request.iteration, n) / n
        for group in self.lora.optimizer.param_groups:
            group["lr"] = self.config.lr_lora * factor

    def __call__(self, renders: torch.Tensor, request: CriticRequest) -> torch.Tensor:
        if len(request.prompts) != renders.shape[0]:
            raise InputError(f"The light critic got {renders.shape[0]} views and {len(request.prompts)} prompts.")
        indices = request.view_indices or tuple(range(renders.shape[0]))
        self._anneal_lora(request)
        uncond = self.models.embed(self.config.negative_prompt)
        size = self.config.model_resolution
        grads = []
        for i, (prompt, view) in enumerate(zip(request.prompts, indices)):
            # Tone-map, encode to sRGB [0, 1], resize and VAE-encode; gradients stop at `leaf`.
            leaf = renders[i].detach().to(self.models.device, torch.float32).requires_grad_(True)
            with torch.enable_grad():
                image = tonemap_srgb_torch(leaf, self.config.l_white).permute(2, 0, 1)[None]
                if image.shape[-2:] != (size, size):
                    image = F.interpolate(image, size=(size, size), mode="bilinear", align_corners=False)
                latents = self._encode(image)
                # VSD at t ~ U[t_range]: ∇z = w_t (ε_φ (CFG) - ε_ψ).
                t = int(self.rng.integers(request.t_range[0], request.t_range[1] + 1))
                noise = torch.randn(latents.shape, generator=self.generator).to(latents.device)
                text = self.models.embed(prompt)
                condition = self.condition(view, request.light)
                out = self.score(latents, t, noise, text, uncond, lam=self.config.lambda_vsd, condition=condition)
                out.loss.backward()
            grads.append(torch.nan_to_num(leaf.grad, nan=0.0, posinf=0.0, neginf=0.0))
            # ε_ψ learns the current renderings (one LoRA step on the detached latents, handed over in the
            # UNet's dtype: LoraCritic.train_step feeds them to the UNet as they come).
            t_lora = int(self.rng.integers(0, self.score.num_train_timesteps))
            unet_dtype = self.models.unet.dtype
            lora_noise = torch.randn(latents.shape, generator=self.generator).to(latents.device, unet_dtype)
            drop = bool(self.rng.uniform() < self.config.condition_dropout)
            lora_loss = self.lora.train_step(latents.detach().to(unet_dtype), text, condition, t_lora, lora_noise,
                                             float(self.score.alpha_bar[t_lora]), drop, self.score.prediction_type)
            self.lora.step()
            self.history.append({"iteration": request.iteration, "view": int(view), "t": t, "light": request.light,
                                 "grad_norm": out.metrics["grad_norm"], "lora_loss": round(lora_loss, 6)})
        return torch.stack(grads).to(renders.device, renders.dtype)
