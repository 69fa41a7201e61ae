"""The neural texture's shape (NeuralTextureConfig) and the balanced preset's hash grid: data a stage config
and the presets hold, without torch (core/texture/neural_texture.py builds the network from it)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..base.errors import InputError
from ..data.mesh import NORMALIZED_RADIUS


@dataclass(frozen=True)
class NeuralTextureConfig:
    """Shape of the neural texture. Defaults follow the paper / Instant-NGP; core/pipeline/presets.py has faster ones.

    resolution: texture map size (H = W) the position map is rasterised and the maps are baked at.
    n_levels, n_features, log2_table, base_resolution, finest_resolution: the hash grid (Instant-NGP
        names: L, F, log2 T, N_min, N_max).
    hidden: width of the MLP's hidden layer.
    *_range: (min, max) each output channel is remapped to after the sigmoid. The paper gives no
        numbers; base colour and metallic span [0, 1], roughness keeps a small floor (0.03) so
        the GGX lobe never degenerates to a perfect mirror.
    bound: positions are expected in [-bound, bound]^3 (meshes normalised into the radius-0.5 sphere).
    """

    resolution: int = 512
    n_levels: int = 16
    n_features: int = 2
    log2_table: int = 19
    base_resolution: int = 16
    finest_resolution: int = 2048
    hidden: int = 64
    base_color_range: tuple[float, float] = (0.0, 1.0)
    roughness_range: tuple[float, float] = (0.03, 1.0)
    metallic_range: tuple[float, float] = (0.0, 1.0)
    bound: float = NORMALIZED_RADIUS
    residual: bool = False            # the exact start: the asset's maps (a stored base) + a learned residual

    def __post_init__(self) -> None:
        def need(ok: bool, message: str) -> None:
            if not ok:
                raise InputError(f"Neural texture config: {message}")

        for name in ("resolution", "n_levels", "n_features", "log2_table", "base_resolution",
                     "finest_resolution", "hidden"):
            value = getattr(self, name)
            need(isinstance(value, (int, np.integer)) and not isinstance(value, bool),
                 f"{name} must be an integer, got {value!r}.")
        need(1 <= self.resolution <= 16384, f"resolution {self.resolution} must be between 1 and 16384 texels.")
        need(1 <= self.n_levels <= 32, f"n_levels {self.n_levels} must be between 1 and 32.")
        need(self.n_features in (1, 2, 4, 8), f"n_features {self.n_features} must be 1, 2, 4 or 8.")
        need(8 <= self.log2_table <= 24, f"log2_table {self.log2_table} must be between 8 and 24.")
        need(self.base_resolution >= 2, f"base_resolution {self.base_resolution} must be at least 2.")
        need(self.finest_resolution >= self.base_resolution,
             f"finest_resolution {self.finest_resolution} must be at least base_resolution {self.base_resolution}.")
        need(self.hidden >= 1, f"hidden {self.hidden} must be at least 1.")
        for name in ("base_color_range", "roughness_range", "metallic_range"):
            value = getattr(self, name)
            need(isinstance(value, (tuple, list)) and len(value) == 2, f"{name} must be a (min, max) pair, got {value!r}.")
            lo, hi = float(value[0]), float(value[1])
            need(0.0 <= lo < hi <= 1.0, f"{name} {tuple(value)} must satisfy 0 <= min < max <= 1.")
            object.__setattr__(self, name, (lo, hi))  # lists from JSON become tuples
        need(float(self.bound) > 0.0, f"bound {self.bound} must be positive.")

    @property
    def channel_min(self) -> tuple[float, ...]:
        return (self.base_color_range[0],) * 3 + (self.roughness_range[0], self.metallic_range[0])

    @property
    def channel_max(self) -> tuple[float, ...]:
        return (self.base_color_range[1],) * 3 + (self.roughness_range[1], self.metallic_range[1])

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(values: dict) -> "NeuralTextureConfig":
        known = NeuralTextureConfig.__dataclass_fields__
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise InputError(f"Neural texture config has unknown fields {unknown}; was it saved by a newer SceneFit?")
        return NeuralTextureConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})  # type: ignore[arg-type]



# The balanced preset's hash grid (core/pipeline/preset_tables.py, "texture"): what a stage config that
# makes a texture holds by default, as every stage's default is balanced (tests/architecture/test_wiring.py pins it).
BALANCED_TEXTURE = NeuralTextureConfig(n_levels=12, log2_table=18, finest_resolution=1024)
