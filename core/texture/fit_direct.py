"""Direct conversion: fit a neural texture to an asset's own maps by regression in texture space.

When the asset has a plain UV texture, texel (i, j) of the target maps and texel (i, j) of the
position map describe the same surface point, so no rendering is needed: the network is fitted to
the target on the covered texels. The schedule is the paper's (Adam, lr 0.02 annealed to 0.001);
the paper does not say how it anneals: we use cosine annealing by default (it keeps the rate high
for longer, which matters for short CPU-sized runs) and offer exponential (see learning_rate()).

Metric and loss: PSNR over covered texels and all five channels, with base colour measured
*sRGB-encoded* (as the image file and the eye see it) and roughness/metallic linear, all in [0, 1].
The loss is the MSE in that same space, so the fit optimises the number it is judged by.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..base.errors import Cancelled, InputError
from .neural_texture import NeuralTexture
from ..data.uv_raster import seam_fill_index

ProgressFn = Callable[[int, float, float], None]


@dataclass
class FitResult:
    """What a fit did. psnr_history[i] / loss_history[i] are measured before step i on its batch
    (on all covered texels when batch_texels is None); final_psnr on all covered texels after the last step."""

    iterations: int
    seconds: float
    setup_seconds: float
    final_psnr: float
    psnr_history: list[float] = field(default_factory=list)
    loss_history: list[float] = field(default_factory=list)
    schedule: str = "cosine"


SCHEDULES = ("cosine", "exponential")


def learning_rate(it: int, iterations: int, lr_start: float, lr_end: float, schedule: str = "cosine") -> float:
    """lr at step `it` of `iterations`, lr_start at the first step and lr_end at the last.

    cosine: lr_end + (lr_start - lr_end) (1 + cos(pi t)) / 2; exponential: lr_start (lr_end / lr_start)^t,
    with t = it / (iterations - 1).
    """
    t = it / max(iterations - 1, 1)
    if schedule == "cosine":
        return lr_end + (lr_start - lr_end) * 0.5 * (1.0 + math.cos(math.pi * t))
    if schedule == "exponential":
        return lr_start * (lr_end / lr_start) ** t
    raise InputError(f"Unknown learning-rate schedule '{schedule}'; choose one of {', '.join(SCHEDULES)}.")


def encode_for_metric(texture: torch.Tensor) -> torch.Tensor:
    """(..., 5) linear channels -> sRGB-encoded base colour + linear roughness/metallic, clamped to [0, 1]."""
    texture = texture.clamp(0.0, 1.0)
    rgb = texture[..., :3]
    srgb = torch.where(rgb <= 0.0031308, rgb * 12.92,
                       1.055 * torch.pow(rgb.clamp_min(0.0031308), 1.0 / 2.4) - 0.055)
    return torch.cat((srgb, texture[..., 3:]), dim=-1)


def masked_psnr(pred, target, mask) -> float:
    """PSNR in dB of (H, W, 5) linear textures over texels where mask (H, W) is True (see module doc)."""
    pred_t, target_t = _as_tensor(pred), _as_tensor(target)
    mask_t = mask.to(torch.bool) if torch.is_tensor(mask) else torch.from_numpy(np.array(mask, dtype=bool))
    if pred_t.shape != target_t.shape or pred_t.shape[:2] != mask_t.shape or pred_t.shape[-1] != 5:
        raise InputError(f"PSNR needs two (H, W, 5) textures and an (H, W) mask; got "
                         f"{tuple(pred_t.shape)}, {tuple(target_t.shape)}, {tuple(mask_t.shape)}.")
    if not bool(mask_t.any()):
        raise InputError("PSNR over an empty mask is undefined: no texel is covered.")
    with torch.no_grad():
        diff = encode_for_metric(pred_t[mask_t]) - encode_for_metric(target_t[mask_t])
        return _psnr(float(diff.square().mean()))


def fit_direct(
    texture: NeuralTexture,
    position_map,
    mask,
    target,
    iterations: int = 300,
    lr_start: float = 0.02,
    lr_end: float = 0.001,
    batch_texels: int | None = None,
    seed: int = 0,
    progress: ProgressFn | None = None,
    cancel: threading.Event | None = None,
    stop_at_psnr: float | None = None,
    schedule: str = "cosine",
) -> FitResult:
    """Fit `texture` in place to `target` (H, W, 5: linear base colour, roughness, metallic) on `mask`.

    position_map (H, W, 3) and mask (H, W) come from rasterize_uv at the target's resolution (use
    UVRaster.mask, the exact coverage). batch_texels: None uses every covered texel each step;
    an int splits them (shuffled once with `seed`) into fixed batches visited in turn.
    progress(iteration, loss, psnr) is called after each step; setting `cancel` stops at the next
    step and raises Cancelled (the texture keeps what it learnt). stop_at_psnr ends early once the
    measured PSNR reaches it.
    """
    _check_settings(iterations, lr_start, lr_end, batch_texels, schedule)
    started = time.perf_counter()
    plan, wanted, batches = _fit_batches(texture, position_map, mask, target, batch_texels, seed)
    setup_seconds = time.perf_counter() - started

    optimizer = torch.optim.Adam(texture.parameters(), lr=lr_start, betas=(0.9, 0.99), eps=1e-15,
                                 **_fast_adam_options(next(texture.parameters()).device))
    result = FitResult(iterations=0, seconds=0.0, setup_seconds=setup_seconds, final_psnr=float("nan"),
                       schedule=schedule)
    texture.train()
    for it in range(iterations):
        if cancel is not None and cancel.is_set():
            result.seconds = time.perf_counter() - started
            raise Cancelled(f"Texture conversion cancelled after {it} of {iterations} iterations.")
        # Annealed learning rate.
        for group in optimizer.param_groups:
            group["lr"] = learning_rate(it, iterations, lr_start, lr_end, schedule)
        batch_plan, batch_target = batches[it % len(batches)]
        # Forward on the batch's texels, MSE in the metric's space, backward, step.
        optimizer.zero_grad(set_to_none=True)
        predicted = encode_for_metric(texture.values_from_plan(batch_plan))
        loss = (predicted - batch_target).square().mean()
        loss.backward()
        optimizer.step()

        loss_value = float(loss.detach())
        psnr = _psnr(loss_value)
        result.loss_history.append(loss_value)
        result.psnr_history.append(psnr)
        result.iterations = it + 1
        if progress is not None:
            progress(it, loss_value, psnr)
        if stop_at_psnr is not None and psnr >= stop_at_psnr and len(batches) == 1:
            break

    # The final score on every covered texel.
    texture.eval()
    with torch.no_grad():
        predicted = encode_for_metric(texture.values_from_plan(plan))
        result.final_psnr = _psnr(float((predicted - wanted).square().mean()))
    result.seconds = time.perf_counter() - started
    return result


def _check_settings(iterations: int, lr_start: float, lr_end: float, batch_texels: int | None,
                    schedule: str) -> None:
    if iterations < 1:
        raise InputError(f"Direct fitting needs at least one iteration, got {iterations}.")
    if not (lr_start > 0 and lr_end > 0):
        raise InputError(f"Learning rates must be positive, got {lr_start} -> {lr_end}.")
    if schedule not in SCHEDULES:
        raise InputError(f"Unknown learning-rate schedule '{schedule}'; choose one of {', '.join(SCHEDULES)}.")
    if batch_texels is not None and batch_texels < 1:
        raise InputError(f"batch_texels must be a positive number of texels or None, got {batch_texels}.")


def _fit_batches(texture: NeuralTexture, position_map, mask, target, batch_texels: int | None, seed: int):
    """What stays fixed for the whole fit: the covered texels' encoding plan, their targets in the
    metric's space, and the (plan, target) batches visited in turn."""
    device = next(texture.parameters()).device
    target_t = _as_tensor(target).to(device)
    mask_np = np.asarray(mask.cpu() if torch.is_tensor(mask) else mask, dtype=bool)
    if target_t.ndim != 3 or target_t.shape[2] != 5 or tuple(target_t.shape[:2]) != mask_np.shape:
        raise InputError(f"The target maps are {tuple(target_t.shape)}; they must be (H, W, 5) at the "
                         f"position map's resolution {mask_np.shape}. Rasterise the UVs at the texture's size.")
    if not bool(torch.isfinite(target_t).all()):
        raise InputError("The target maps hold NaN or infinite values.")
    plan = texture.plan(position_map, mask_np, seam_fill_index(mask_np))
    wanted = encode_for_metric(target_t.reshape(-1, 5)[plan.texels])
    if batch_texels is None or batch_texels >= plan.texels.numel():
        return plan, wanted, [(plan, wanted)]
    generator = torch.Generator().manual_seed(int(seed))
    order = torch.randperm(plan.texels.numel(), generator=generator).to(device)
    batches = [(texture.subset_plan(plan, chunk), wanted[chunk]) for chunk in torch.split(order, int(batch_texels))]
    return plan, wanted, batches


def _fast_adam_options(device: torch.device) -> dict:
    """The fused Adam kernel where this torch has it for the device (CPU since 2.4, CUDA), else foreach."""
    return {"fused": True} if device.type in ("cpu", "cuda") else {"foreach": True}


def _as_tensor(x) -> torch.Tensor:
    if torch.is_tensor(x):
        return x.to(torch.float32)
    return torch.from_numpy(np.array(x, dtype=np.float32))  # a copy: torch wants writable memory


def _psnr(mse: float) -> float:
    return float("inf") if mse <= 0.0 else -10.0 * math.log10(mse)
