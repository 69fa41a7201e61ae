"""Timesteps, the weight w_t, the VSD/SDS interpolation λ, and the numerical guard rails.

Everything here is plain math on tensors, written out where it happens.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from ..base.errors import InputError

from .critic_config import ANNEAL_TYPES, NORMAL_WEIGHT_TYPES, WEIGHTING_TYPES

# ᾱ_t is kept inside [ALPHA_EPS, 1 - ALPHA_EPS] wherever it is divided by (t -> 0 and t -> T).
ALPHA_EPS = 1e-6


def alphas_cumprod(scheduler) -> torch.Tensor:
    """ᾱ_t for t = 0..T-1 as float64 on the CPU (exact, whatever the models' dtype)."""
    return scheduler.alphas_cumprod.detach().to("cpu", torch.float64)


def sample_timestep(rng: np.random.Generator, t_range: tuple[int, int], progress: float,
                    anneal_type: str = "linear", window: float = 0.25, num_train_timesteps: int = 1000) -> int:
    """One integer timestep in t_range.

    anneal "linear": a window of `window` x the range slides from the top (progress 0) to the bottom
    (progress 1), so noise levels go from high to low (the paper's appendix); "none": uniform.
    """
    lo: float = int(t_range[0])
    hi: float = int(t_range[1])
    if anneal_type == "linear":
        width = window * (hi - lo)
        centre = hi - (hi - lo) * min(max(progress, 0.0), 1.0)
        lo, hi = max(lo, centre - width / 2), min(hi, centre + width / 2)
    elif anneal_type != "none":
        raise InputError(f"anneal_type must be one of {ANNEAL_TYPES}, got {anneal_type!r}.")
    t = int(round(rng.uniform(lo, hi)))
    return min(max(t, 0), num_train_timesteps - 1)


def timestep_weight(alpha_bar_t: float, weighting_type: str = "sds") -> float:
    """The scalar part of w_t."""
    if weighting_type == "sds":
        return float(1.0 - alpha_bar_t)
    if weighting_type == "uniform":
        return 1.0
    raise InputError(f"weighting_type must be one of {WEIGHTING_TYPES}, got {weighting_type!r}.")


def interpolation_lambda(progress: float, lambda_end: float, critic_type: str) -> float:
    """λ of ε̂ = λ ε_ψ + (1 - λ) ε: 0 for SDS; for VSD annealed linearly from 1 to λ_e."""
    if critic_type == "sds":
        return 0.0
    p = min(max(float(progress), 0.0), 1.0)
    return 1.0 + (float(lambda_end) - 1.0) * p


def normal_weight_map(normals: np.ndarray, coverage: np.ndarray, forward: np.ndarray, latent_hw: tuple[int, int],
                      floor: float = 0.1, weight_type: str = "cosine") -> torch.Tensor | None:
    """(1, 1, h, w) per-latent weight from ⟨camera, normal⟩: faces seen at grazing angles count less.

    normals (H, W, 3) world shading normals and coverage (H, W) from the renderer's AOV pass; the
    weight is max(|n · -forward|, floor) on the object and 1 on the background, area-averaged down
    to the latent grid. None when weight_type is "none".
    """
    if weight_type == "none":
        return None
    if weight_type != "cosine":
        raise InputError(f"normal_weight_type must be one of {NORMAL_WEIGHT_TYPES}, got {weight_type!r}.")
    cos = np.abs(np.asarray(normals, np.float32) @ (-np.asarray(forward, np.float32)))
    w = np.where(np.asarray(coverage) > 0, np.maximum(cos, floor), 1.0).astype(np.float32)
    w = torch.from_numpy(w)[None, None]
    return torch.nn.functional.interpolate(w, size=latent_hw, mode="area")


def guard_gradient(grad: torch.Tensor, clip: float | None = None) -> tuple[torch.Tensor, int]:
    """Float32 gradient with NaN/±inf replaced by 0 and optionally clipped to [-clip, clip].

    Returns the gradient and how many entries were not finite (fp16 overflow shows up here).
    """
    grad = grad.float()
    bad = int((~torch.isfinite(grad)).sum())
    grad = torch.nan_to_num(grad, nan=0.0, posinf=0.0, neginf=0.0)
    if clip is not None:
        grad = grad.clamp(-clip, clip)
    return grad, bad


def predicted_x0(x_t: torch.Tensor, eps: torch.Tensor, alpha_bar_t: float) -> torch.Tensor:
    """x̂_0 = (x_t - sqrt(1 - ᾱ) ε) / sqrt(ᾱ), with ᾱ kept away from 0 (t -> T) for stability."""
    a = min(max(float(alpha_bar_t), ALPHA_EPS), 1.0 - ALPHA_EPS)
    return (x_t.float() - math.sqrt(1.0 - a) * eps.float()) / math.sqrt(a)


def add_noise(x0: torch.Tensor, noise: torch.Tensor, alpha_bar_t: float) -> torch.Tensor:
    """x_t = sqrt(ᾱ_t) x_0 + sqrt(1 - ᾱ_t) ε (computed in float32, returned in x0's dtype)."""
    a = min(max(float(alpha_bar_t), 0.0), 1.0)
    return (math.sqrt(a) * x0.float() + math.sqrt(1.0 - a) * noise.float()).to(x0.dtype)
