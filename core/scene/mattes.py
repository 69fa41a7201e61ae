"""The one compositing rule, and the paper's shadow matte (appendix, "Scene Composition")."""
from __future__ import annotations


def paper_shadow_matte(intensity, floor, threshold_fraction: float):
    """The appendix's shadow ("Scene Composition"): floor pixels darker than threshold_fraction x the
    floor's mean intensity are shadowed; their intensity divided by the lit pixels' mean is the matte
    ("scale by norm([1,1,1]) / E(I | lit) and convert to transparency"), lit pixels keep the photo (1).

    intensity: (h, w) torch tensor (differentiable: the light stage's critic views pass gradients
    through the shadowed pixels); floor: (h, w) bool. Returns (matte, threshold, lit mean, shadowed).
    """
    import torch  # lazy: torch takes seconds to load

    if not bool(floor.any()):
        return torch.ones_like(intensity), 0.0, 0.0, torch.zeros_like(floor)
    threshold = threshold_fraction * intensity[floor].mean()
    shadowed = floor & (intensity < threshold)
    lit = floor & ~shadowed
    lit_mean = intensity[lit].mean() if bool(lit.any()) else intensity[floor].mean()
    matte = torch.where(shadowed, (intensity / lit_mean.clamp_min(1e-12)).clamp(0.0, 1.0), torch.ones_like(intensity))
    return matte, float(threshold.detach()), float(lit_mean.detach()), shadowed


def composite_linear(object_rgb, alpha, photo_linear, matte):
    """The one compositing rule, in linear light: the asset's premultiplied radiance over the photo,
    which its shadow matte darkens. Arithmetic only, so it serves numpy (compose) and torch (the adapt
    stage's global views, differentiable in object_rgb and alpha) alike."""
    return object_rgb + (1.0 - alpha) * photo_linear * matte
