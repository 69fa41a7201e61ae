"""Intel Open Image Denoise (through PyPI `pyoidn`) for final renders, guided by albedo and normal AOVs.

OIDN's "RT" filter is trained on path-traced images: `hdr=True` for linear radiance (any range),
albedo in [0, 1] and normals in [-1, 1] from the first hit (Mitsuba's `aov` integrator gives both).
Renders that reach here at a few samples per pixel come out close to a high-sample reference at a
fraction of the time (benchmarks/bench_compose.py measures how close and how fast).
"""
from __future__ import annotations

import numpy as np

from ..base.errors import RendererUnavailableError

DENOISER_TYPES = ("auto", "oidn", "none")   # auto: OIDN where pyoidn is installed (no wheel for linux-arm64)


def oidn_available() -> tuple[bool, str]:
    try:
        import pyoidn  # noqa: F401
    except ImportError as error:
        return False, f"pyoidn is not installed ({error}); pip install pyoidn (see requirements.txt)"
    return True, "Intel Open Image Denoise (pyoidn)"


def denoise(color: np.ndarray, albedo: np.ndarray | None = None, normal: np.ndarray | None = None,
            hdr: bool = True) -> np.ndarray:
    """(H, W, 3) float32 denoised copy of `color`; albedo/normal (H, W, 3) guide it when given."""
    ok, why = oidn_available()
    if not ok:
        raise RendererUnavailableError(f"Denoising needs Intel Open Image Denoise: {why}.")
    import pyoidn  # lazy: pyoidn is optional (no wheel for linux-arm64)

    def prep(image):
        return None if image is None else np.ascontiguousarray(image[..., :3], dtype=np.float32)

    color = prep(color)
    albedo = prep(albedo)
    normal = prep(normal)
    if albedo is None:
        normal = None  # OIDN takes normals only together with an albedo
    return np.asarray(pyoidn.denoise(color, albedo, normal, hdr=hdr, quality="high"), dtype=np.float32)
