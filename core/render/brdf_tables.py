"""Mitsuba's principled BSDF under uniform light, tabulated: how much light it reflects towards a view.

The loop renderer (core/render/loop_renderer.py) shades with these tables. For the principled BSDF as
the renderer's scenes use it (only base colour, roughness and metallic set; specular 0.5, no tint,
sheen or clearcoat), the light reflected under a uniform white environment is linear in the base
colour for a fixed metallic and linear in metallic:

    albedo = (1 - m) * base * D + (1 - m) * S + m * (base * A + B)

where D (diffuse lobe), S (dielectric specular), A and B (metallic Schlick's scale and bias) depend
only on the view's cosine to the shading normal and the roughness. Each entry is a Monte Carlo
integral of Mitsuba's own BSDF (`bsdf.sample`'s weight, f cos / pdf), so the tables are exact to
their sampling noise and grid, with no reimplementation of the BSDF to drift from Mitsuba's.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .backend import init_mitsuba

TABLE_SIZE = 32          # grid nodes over the view cosine [0, 1] and roughness [0, 1]
TABLE_SAMPLES = 4096     # BSDF samples per node and configuration
# (metallic, base colour) per configuration: D + S, S, B, A + B
_CONFIGS = ((0.0, 1.0), (0.0, 0.0), (1.0, 0.0), (1.0, 1.0))
_TABLES: dict[tuple[int, int], np.ndarray] = {}
# The default tables, as `python -m scenefit.core.render.brdf_tables` writes them (tests/core/render
# checks them against a fresh computation): computing them takes seconds a run need not spend.
STORED = Path(__file__).with_name("brdf_tables.npy")


def brdf_tables(size: int = TABLE_SIZE, samples: int = TABLE_SAMPLES) -> np.ndarray:
    """(4, size, size) float32: D, S, A, B at [cosine index, roughness index], nodes at i / (size - 1).
    The stored default, or computed once per process with a fixed seed."""
    key = (size, samples)
    if key not in _TABLES:
        stored = (size, samples) == (TABLE_SIZE, TABLE_SAMPLES) and STORED.is_file()
        _TABLES[key] = np.load(STORED) if stored else compute_tables(size, samples)
    return _TABLES[key]


def compute_tables(size: int, samples: int) -> np.ndarray:
    init_mitsuba()
    # lazy: Mitsuba is heavy and Blender may lack it
    import drjit as dr
    import mitsuba as mi

    # One BSDF whose maps vary along u (roughness node) and v (configuration): one kernel for all.
    rough = np.tile(np.linspace(0.0, 1.0, size, dtype=np.float32), (len(_CONFIGS), 1))[..., None]
    metal = np.repeat(np.array([m for m, _ in _CONFIGS], np.float32)[:, None, None], size, axis=1)
    base = np.repeat(np.repeat(np.array([b for _, b in _CONFIGS], np.float32)[:, None, None], size, axis=1), 3, 2)

    def bitmap(data):
        return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(data)), "raw": True,
                "filter_type": "nearest", "wrap_mode": "clamp"}

    bsdf = mi.load_dict({"type": "principled", "base_color": bitmap(base), "roughness": bitmap(rough),
                         "metallic": bitmap(metal)})
    cosines = np.linspace(0.0, 1.0, size)
    cosines[0] = 1e-4   # exactly grazing views see nothing; the node holds the limit
    out = np.zeros((len(_CONFIGS), size, size), np.float64)
    for c in range(len(_CONFIGS)):
        n = size * size * samples
        idx = np.arange(n)
        cos_i = cosines[(idx // samples) // size]
        r_i = (idx // samples) % size
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        si.wi = mi.Vector3f(np.sqrt(1 - cos_i ** 2).astype(np.float32), 0.0, cos_i.astype(np.float32))
        si.uv = mi.Point2f(((r_i + 0.5) / size).astype(np.float32), float((c + 0.5) / len(_CONFIGS)))
        u = _low_discrepancy(samples, size * size, 1234 + c)
        _, weight = bsdf.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
        values = np.array(weight[0], np.float64).reshape(size, size, samples)
        out[c] = values.mean(axis=2)
    d_plus_s, s, b, a_plus_b = out
    return np.stack([d_plus_s - s, s, a_plus_b - b, b]).astype(np.float32)


def _low_discrepancy(samples: int, nodes: int, seed: int) -> np.ndarray:
    """(3, nodes * samples) points of the R3 additive sequence, shifted at random per node (randomised
    quasi-Monte Carlo: the tables' noise falls far faster than with independent samples)."""
    phi = 1.2207440846057596   # the plastic number's 3-D generalisation: x^4 = x + 1
    alpha = np.array([1 / phi, 1 / phi ** 2, 1 / phi ** 3])
    points = (np.arange(1, samples + 1)[:, None] * alpha) % 1.0
    shifts = np.random.default_rng(seed).random((nodes, 1, 3))
    return np.ascontiguousarray(((points[None] + shifts) % 1.0).reshape(-1, 3).T, dtype=np.float32)


if __name__ == "__main__":
    np.save(STORED, compute_tables(TABLE_SIZE, TABLE_SAMPLES))
    print(f"wrote {STORED}")
