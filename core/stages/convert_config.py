"""How to convert (ConvertConfig): data a preset resolves and a run keys, without torch (core/stages/convert.py
does the conversion)."""
from __future__ import annotations

from dataclasses import dataclass, replace

from ..base.errors import InputError
from ..base.limits import check_render_size
from ..texture.texture_config import BALANCED_TEXTURE, NeuralTextureConfig

METHOD_TYPES = ("direct", "inverse")
INIT_TYPES = ("exact", "fit")


@dataclass(frozen=True)
class ConvertConfig:
    """How to convert. Defaults are the "balanced" preset (core/pipeline/presets.py)."""

    init_type: str = "exact"          # exact: the asset's maps + a zero residual; fit: the paper's fitted network
    method_type: str = "direct"       # fit only: direct (texels against the maps) | inverse (through renders)
    texture: NeuralTextureConfig = BALANCED_TEXTURE   # the hash grid; resolution and residual are set by the run
    resolution: int | None = None     # None: the asset's base colour resolution, capped at max_resolution
    screen_px: int | None = None      # the object's height in the composite, pixels: no more texels than it shows
    max_resolution: int = 1024        # texels per side at most (larger maps are area-averaged to it)
    iterations: int = 400             # fit only: optimisation steps
    lr_start: float = 0.02            # paper: 0.02 annealed to 0.001
    lr_end: float = 0.001             # the learning rate at the last step
    batch_texels: int | None = None   # direct: texels per step (None = all)
    render_size: int = 256            # inverse: render resolution and samples per pixel
    spp: int = 16                     # inverse: samples per pixel
    seed: int = 0                     # the network's initialisation and the texel batches

    def __post_init__(self) -> None:
        if self.init_type not in INIT_TYPES:
            raise InputError(f"init_type must be one of {INIT_TYPES}, got {self.init_type!r}.")
        if self.method_type not in METHOD_TYPES:
            raise InputError(f"method_type must be one of {METHOD_TYPES}, got {self.method_type!r}.")
        if self.iterations < 1:
            raise InputError(f"iterations must be at least 1, got {self.iterations}.")
        if self.screen_px is not None and self.screen_px < 1:
            raise InputError(f"screen_px must be at least 1 pixel, got {self.screen_px}.")
        if self.resolution is not None and not 8 <= self.resolution <= 8192:
            raise InputError(f"resolution must be between 8 and 8192 texels, got {self.resolution}.")
        if not 8 <= self.max_resolution <= 8192:
            raise InputError(f"max_resolution must be between 8 and 8192 texels, got {self.max_resolution}.")
        if self.batch_texels is not None and self.batch_texels < 1:
            raise InputError(f"batch_texels must be at least 1 (or left out for all), got {self.batch_texels}.")
        if not 1 <= self.spp <= 65536:
            raise InputError(f"spp must be between 1 and 65536, got {self.spp}.")
        if not (0 < self.lr_end and 0 < self.lr_start):
            raise InputError(f"lr_start and lr_end must be positive, got {self.lr_start}, {self.lr_end}.")
        if not 8 <= self.render_size:
            raise InputError(f"render_size must be at least 8 pixels, got {self.render_size}.")
        check_render_size(self.render_size, self.render_size, "render_size")
        if not isinstance(self.texture, NeuralTextureConfig):
            raise InputError(f"texture must be a NeuralTextureConfig, got {type(self.texture).__name__}.")

    def texture_config(self, resolution: int) -> NeuralTextureConfig:
        return replace(self.texture, resolution=resolution, residual=self.init_type == "exact")
