"""Score-distillation critics (paper §3.1, eq. vsd): one interface for SDS, VSD and their interpolation.

For latents z = E(g(θ)), a timestep t and noise ε:

    z_t      = sqrt(ᾱ_t) z + sqrt(1 - ᾱ_t) ε
    ε_φ      = ε_φ(z_t, ∅) + s_cf (ε_φ(z_t, text) - ε_φ(z_t, ∅))            classifier-free guidance
    ε̂        = λ ε_ψ(z_t, text, camera) + (1 - λ) ε                         λ = 0: SDS; λ = 1: VSD
    ∇_z L    = w_t · w_n · (ε_φ - ε̂)                                        w_n: ⟨camera, normal⟩ map

The gradient is handed to autograd as is (no Jacobian of the UNet), after the guard rails
(float32, NaN/inf -> 0, optional clip). With reference latents, ε_φ and ε_ψ see the noised
reference through ReferenceInjector; with `inpaint` the UNet gets the 9-channel input.

Rows are independent: several images (the views of a step, their crops) go through one UNet call,
each with its own timestep, noise, text, condition, reference, weight map and inpainting input.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from ..base.errors import InputError
from .injection import Layout, ReferenceInjector
from .lora import LoraCritic
from .critic_config import CriticConfig
from .weighting import alphas_cumprod, guard_gradient, timestep_weight
from .views import inpainting_input

@dataclass
class CriticOutput:
    loss: torch.Tensor          # scalar whose gradient with respect to the latents is `grad`
    grad: torch.Tensor          # float32, guarded
    eps_phi: torch.Tensor
    eps_hat: torch.Tensor
    metrics: dict = field(default_factory=dict)
    row_metrics: list[dict] = field(default_factory=list)   # per row: its grad_norm and nonfinite count


class _InjectGradient(torch.autograd.Function):
    """Forward: a scalar (Σ z·g, for logging only); backward: exactly g (times the incoming scale)."""

    @staticmethod
    def forward(ctx, latents, grad):
        ctx.save_for_backward(grad)
        return (latents.detach().float() * grad).sum()

    @staticmethod
    def backward(ctx, grad_output):
        (grad,) = ctx.saved_tensors
        return (grad_output * grad).to(grad.dtype), None


def gradient_loss(latents: torch.Tensor, grad: torch.Tensor) -> torch.Tensor:
    """A scalar whose backward puts `grad` into the latents' gradient."""
    g = grad.to(latents.dtype) if latents.dtype == grad.dtype else grad
    out = _InjectGradient.apply(latents, g)
    return out


def to_epsilon(prediction: torch.Tensor, x_t: torch.Tensor, alpha_bar_t: float | torch.Tensor,
               prediction_type: str) -> torch.Tensor:
    """The UNet's output as a noise prediction (SD2-base predicts ε; SD2-768 predicts v); ᾱ_t a number
    or one per row, (B, 1, 1, 1)."""
    prediction = prediction.float()
    if prediction_type == "epsilon":
        return prediction
    if prediction_type == "v_prediction":
        if isinstance(alpha_bar_t, torch.Tensor):   # square roots in float64, as a Python number's are
            a = alpha_bar_t.double()
            return a.sqrt().float() * prediction + (1.0 - a).sqrt().float() * x_t.float()
        return (alpha_bar_t ** 0.5) * prediction + ((1.0 - alpha_bar_t) ** 0.5) * x_t.float()
    raise InputError(f"Unsupported scheduler prediction type {prediction_type!r}.")


def rows_of(tensor: torch.Tensor, n: int) -> torch.Tensor:
    """`tensor` (1 or k rows, k dividing n) repeated to n rows, in order ([a, b] -> [a, b, a, b])."""
    if tensor.shape[0] == n:
        return tensor
    if tensor.shape[0] == 1:
        return tensor.expand(n, *tensor.shape[1:])
    if n % tensor.shape[0]:
        raise InputError(f"{tensor.shape[0]} rows cannot fill a batch of {n}.")
    return tensor.repeat(n // tensor.shape[0], *([1] * (tensor.ndim - 1)))


def row_timesteps(t: int | Sequence[int], rows: int) -> list[int]:
    """One timestep per row: a number for all, or one each."""
    ts = [int(t)] * rows if isinstance(t, int) else [int(v) for v in t]
    if len(ts) != rows:
        raise InputError(f"{len(ts)} timesteps for {rows} rows.")
    return ts


class ScoreCritic:
    """ε_φ (and ε_ψ when given a LoraCritic) scoring latents; see the module docstring."""

    def __init__(self, unet, scheduler, config: CriticConfig, lora: LoraCritic | None = None,
                 injector: ReferenceInjector | None = None) -> None:
        if config.critic_type == "vsd" and lora is None:
            raise InputError("critic_type 'vsd' needs the LoRA model ε_ψ.")
        self.unet, self.config, self.lora, self.injector = unet, config, lora, injector
        self.alpha_bar = alphas_cumprod(scheduler)
        self.prediction_type = scheduler.config.prediction_type
        self.num_train_timesteps = len(self.alpha_bar)

    # -- UNet passes ---------------------------------------------------------------------------------
    def _unet(self, x_t: torch.Tensor, t: int | torch.Tensor, text: torch.Tensor, ref_t: torch.Tensor | None,
              uncond_rows: tuple[int, ...], class_labels: torch.Tensor | None, extra: tuple | None) -> torch.Tensor:
        """One batched UNet call on rows x_t (B; timestep t, one or (B,)) [+ ref_t (B)]; returns the B x rows' outputs."""
        n = x_t.shape[0]
        sample = x_t
        if extra is not None:
            mask, masked_latents = extra
            sample = inpainting_input(x_t, rows_of(mask, n), rows_of(masked_latents, n))
        layout = None
        if ref_t is not None:
            if self.injector is None:
                raise InputError("Reference latents were given but no ReferenceInjector is installed.")
            sample = torch.cat([sample, ref_t], dim=0)
            text = torch.cat([text, text], dim=0)
            if class_labels is not None:
                class_labels = torch.cat([class_labels, class_labels], dim=0)
            layout = Layout(n_x=n, ref_index=tuple(range(n)), uncond=uncond_rows,
                            control_scale=self.config.control_scale)
        timesteps = rows_of(torch.as_tensor(t, dtype=torch.long).reshape(-1).to(sample.device), sample.shape[0])
        dtype = self.unet.dtype
        with torch.no_grad():
            if self.injector is not None:
                with self.injector.layout(layout):
                    out = self.unet(sample.to(dtype), timesteps, encoder_hidden_states=text.to(dtype),
                                    class_labels=class_labels).sample
            else:
                out = self.unet(sample.to(dtype), timesteps, encoder_hidden_states=text.to(dtype),
                                class_labels=class_labels).sample
        return out[:n]

    def _alpha_rows(self, ts: list[int], like: torch.Tensor) -> torch.Tensor:
        """ᾱ_t per row, (B, 1, 1, 1) float64 (as exact as float(ᾱ_t))."""
        return self.alpha_bar[ts].to(device=like.device).view(-1, 1, 1, 1)

    def predict_phi(self, x_t, t, text_cond, text_uncond, ref_t=None, extra=None) -> torch.Tensor:
        """ε_φ with classifier-free guidance (rows [∅, text]); t one timestep for all rows or one per row."""
        b = x_t.shape[0]
        ts = row_timesteps(t, b)
        rows = torch.cat([x_t, x_t], dim=0)
        text = torch.cat([rows_of(text_uncond, b), rows_of(text_cond, b)], dim=0)
        refs = None if ref_t is None else torch.cat([ref_t, ref_t], dim=0)
        out = to_epsilon(self._unet(rows, torch.tensor(ts * 2), text, refs, tuple(range(b)), None, extra), rows,
                         rows_of(self._alpha_rows(ts, x_t), 2 * b), self.prediction_type)
        uncond, cond = out[:b], out[b:]
        return uncond + self.config.guidance_scale * (cond - uncond)

    def predict_psi(self, x_t, t, text_cond, text_uncond, condition, ref_t=None) -> torch.Tensor:
        """ε_ψ: LoRA on, camera/light condition (one (D,) for all rows or one per row, (B, D)); its own CFG
        over (text + condition) vs (∅ + no condition)."""
        b = x_t.shape[0]
        ts = row_timesteps(t, b)
        alpha = self._alpha_rows(ts, x_t)
        cond_labels = rows_of(condition.to(x_t.device).reshape(-1, condition.shape[-1]), b)
        assert self.lora is not None   # (the caller refused λ > 0 without ε_ψ)
        with self.lora.active():
            if self.config.lora_guidance_scale == 1.0:  # the unconditional branch has weight 0
                out = self._unet(x_t, torch.tensor(ts), rows_of(text_cond, b), ref_t, (), cond_labels, None)
                return to_epsilon(out, x_t, alpha, self.prediction_type)
            rows = torch.cat([x_t, x_t], dim=0)
            text = torch.cat([rows_of(text_uncond, b), rows_of(text_cond, b)], dim=0)
            labels = torch.cat([torch.zeros_like(cond_labels), cond_labels], dim=0)
            refs = None if ref_t is None else torch.cat([ref_t, ref_t], dim=0)
            out = to_epsilon(self._unet(rows, torch.tensor(ts * 2), text, refs, tuple(range(b)), labels, None), rows,
                             rows_of(alpha, 2 * b), self.prediction_type)
        uncond, cond = out[:b], out[b:]
        return uncond + self.config.lora_guidance_scale * (cond - uncond)

    # -- the critic ----------------------------------------------------------------------------------
    def __call__(self, latents: torch.Tensor, t: int | Sequence[int], noise: torch.Tensor, text_cond: torch.Tensor,
                 text_uncond: torch.Tensor, lam: float | Sequence[float] = 0.0, condition: torch.Tensor | None = None,
                 reference_latents: torch.Tensor | None = None, weight_map: torch.Tensor | None = None,
                 extra: tuple | None = None) -> CriticOutput:
        """Score `latents` (B rows) at timestep t (one for all rows, or one per row) with noise ε; `lam` is
        λ (0 for SDS). text_cond, condition, reference_latents, weight_map and extra's mask and masked
        latents hold one row for all or one per row."""
        ts = row_timesteps(t, latents.shape[0])
        if not all(0 <= v < self.num_train_timesteps for v in ts):
            raise InputError(f"Timestep {t} outside [0, {self.num_train_timesteps}).")
        alpha = self._alpha_rows(ts, latents)
        x_t = _noised(latents.detach(), noise, alpha)
        ref_t = None
        if reference_latents is not None and self.config.reference_type == "inject":
            ref_t = _noised(rows_of(reference_latents.detach(), len(ts)), noise, alpha)
        eps_phi = self.predict_phi(x_t, ts, text_cond, text_uncond, ref_t, extra)
        eps = noise.float()
        lams = [float(lam)] * len(ts) if isinstance(lam, (int, float)) else [float(v) for v in lam]
        if max(lams) > 0.0:
            if self.lora is None:
                raise InputError("λ > 0 needs the LoRA model ε_ψ (critic_type 'vsd').")
            eps_psi = self.predict_psi(x_t, ts, text_cond, text_uncond, condition, ref_t)
            lam_rows = lam if isinstance(lam, (int, float)) else torch.tensor(lams, device=eps.device).view(-1, 1, 1, 1)
            eps_hat = lam_rows * eps_psi + (1.0 - lam_rows) * eps
        else:
            eps_hat = eps
        weights = [timestep_weight(float(self.alpha_bar[v]), self.config.weighting_type) for v in ts]
        grad = torch.tensor(weights, dtype=eps_phi.dtype, device=eps_phi.device).view(-1, 1, 1, 1) * (eps_phi - eps_hat)
        if weight_map is not None:
            grad = grad * weight_map.to(grad.device, grad.dtype)
        bad_rows = (~torch.isfinite(grad)).flatten(1).sum(dim=1).tolist()
        grad, bad = guard_gradient(grad, self.config.grad_clip)
        loss = gradient_loss(latents, grad)
        rows = [{"grad_norm": float(norm), "nonfinite": int(b)}
                for norm, b in zip(grad.flatten(1).norm(dim=1).tolist(), bad_rows)]
        metrics = {"t": t, "w_t": weights[0] if isinstance(t, int) else weights, "lambda": lam,
                   "grad_norm": float(grad.norm()), "nonfinite": bad}
        return CriticOutput(loss=loss, grad=grad, eps_phi=eps_phi, eps_hat=eps_hat, metrics=metrics, row_metrics=rows)


def _noised(x0: torch.Tensor, noise: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """x_t = sqrt(ᾱ_t) x_0 + sqrt(1 - ᾱ_t) ε per row (weighting.add_noise with ᾱ_t (B, 1, 1, 1))."""
    a = alpha.double().clamp(0.0, 1.0)
    return (a.sqrt().float() * x0.float() + (1.0 - a).sqrt().float() * noise.float()).to(x0.dtype)
