"""What the paper's parametrisation of the light can reach on the field's diffuse sphere.

The light stage's map is its LDR panorama with one scale per region (hdr = ldr (1 + sum_k m_k (s_k - 1)),
core/stages/light/hdr.compose_hdr), so the map, and every sphere rendered under it, is linear in the
scales. Here the scales are fitted to the true map directly: log scales (the paper's parametrisation)
minimising the diffuse sphere's squared error against the truth's, seen from the photo's side. It
answers one question: are the estimate's losses to the constant in its regions (no scale can fix
them) or in how the scales are found from the photo (cues, critic)? Development measurement only: it
needs the true map.
"""
from __future__ import annotations

import numpy as np
import torch

from scenefit.core.data.imageio import srgb_to_linear
from scenefit.core.stages.light.measure import probe_geometry, render_probe

STEPS = 1500           # Adam steps on a view's 2-4 log scales, from the cues' scales (robust far from
LEARNING_RATE = 0.05   # the optimum), then L-BFGS to polish (precise where a scale barely shows)
LOG_LIMIT = 12.0    # exp(+-12): 1.6e5, the old 1e5 cap's order, so one fit cannot run off to infinity


def region_bases(ldr_srgb: np.ndarray, regions: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The map as rest + sum_k s_k basis_k, exactly compose_hdr's ldr (1 + sum_k m_k (s_k - 1)): rest is
    ldr (1 - sum_k m_k) (the texels outside every region stay at scale 1, as the paper keeps them),
    basis_k each region's linear LDR radiance."""
    ldr = srgb_to_linear(np.asarray(ldr_srgb, np.float32)).astype(np.float32)
    masks = {name: np.asarray(mask, np.float32) for name, mask in regions.items()}
    covered = sum(masks.values()) if masks else np.zeros(ldr.shape[:2], np.float32)
    return ldr * (1.0 - covered)[..., None], {name: ldr * m[..., None] for name, m in masks.items()}


def fitted_scales(rest: np.ndarray, bases: dict[str, np.ndarray], truth: np.ndarray, forward: np.ndarray,
                  start: dict[str, float]) -> dict[str, float]:
    """Region scales (from `start`) minimising the diffuse sphere's squared error against `truth`'s.
    All maps at the truth's size."""
    if not bases:
        return {}
    mask = probe_geometry(forward)[0]
    names = list(bases)
    # Rendering is linear in the map: render each basis once, then fit the weights.
    rendered = torch.tensor(np.stack([render_probe(bases[n], "diffuse", forward)[mask] for n in names]), dtype=torch.float64)
    fixed = torch.tensor(render_probe(rest, "diffuse", forward)[mask], dtype=torch.float64)
    target = torch.tensor(render_probe(truth, "diffuse", forward)[mask], dtype=torch.float64)
    logs = torch.tensor([np.log(max(start.get(n, 1.0), 1e-6)) for n in names], dtype=torch.float64, requires_grad=True)

    def loss_of(values: torch.Tensor) -> torch.Tensor:
        weights = torch.exp(values.clamp(-LOG_LIMIT, LOG_LIMIT))
        return ((fixed + (weights[:, None, None] * rendered).sum(0) - target) ** 2).mean()

    optimiser = torch.optim.Adam([logs], lr=LEARNING_RATE)
    for _ in range(STEPS):
        optimiser.zero_grad()
        loss_of(logs).backward()
        optimiser.step()
    adam = logs.detach().clone()
    polish = torch.optim.LBFGS([logs], max_iter=200, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        polish.zero_grad()
        loss = loss_of(logs)
        loss.backward()
        return loss

    polish.step(closure)
    with torch.no_grad():   # keep Adam's answer should the polish have gone anywhere worse
        best = logs.detach() if torch.isfinite(loss_of(logs)) and loss_of(logs) <= loss_of(adam) else adam
    return {n: float(np.exp(np.clip(v, -LOG_LIMIT, LOG_LIMIT))) for n, v in zip(names, best.numpy())}


def ceiling_map(rest: np.ndarray, bases: dict[str, np.ndarray], scales: dict[str, float]) -> np.ndarray:
    return (rest + sum(bases[n] * s for n, s in scales.items())).astype(np.float32)
