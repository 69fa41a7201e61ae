"""The paper's appearance model (§3.2): hash-grid encoding + 2-layer bias-free MLP, 3D point -> PBR.

A texel's 3D position (from the UV-space position map C) goes through a multi-resolution hash
encoding and a 2-layer MLP without bias; a sigmoid and a per-channel remap to [min, max] give the
five channels base colour RGB (linear), roughness and metallic.

The exact start (issue 23): with `residual` the texture is the asset's own maps plus what the
network learns, in logit space per channel: value = min + (max - min) * sigmoid(logit(base) + MLP(h(p))).
The MLP's last layer starts at zero, so before any step the texture *is* the asset's maps
(`base`, stored in texture.pt in the raster's UV layout), and adaptation starts from it exactly.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np
import torch

from ..base.errors import InputError
from .hashgrid import EncodingPlan, HashGrid3D
from .texture_config import NeuralTextureConfig


class SavedLayout(Protocol):
    """What a texture keeps of adaptation's new UV layout (core.surface_layout.SurfaceLayout, which imports
    this module): it is saved with the weights."""

    def to_payload(self) -> dict: ...

_Stack = TypeVar("_Stack", torch.Tensor, np.ndarray)

CHANNELS = ("base_r", "base_g", "base_b", "roughness", "metallic")




@dataclass(eq=False)
class TexelPlan:
    """Everything about a set of texels that does not change while a texture trains.

    texels: (K,) int64 flat indices (row-major in H*W) of the evaluated texels.
    points: (K, 3) float32 their positions in the grid's unit cube.
    gather: (H*W,) int64 row of the K evaluated values each texel copies (itself, or its nearest
        evaluated texel past a seam).
    encoding: the hash grid's sparse encoding of the K points.
    """

    shape: tuple[int, int]
    texels: torch.Tensor
    points: torch.Tensor
    gather: torch.Tensor
    encoding: EncodingPlan
    config: NeuralTextureConfig


class NeuralTexture(torch.nn.Module):
    """3D point -> (base colour RGB linear, roughness, metallic), each in its configured range."""

    def __init__(self, config: NeuralTextureConfig | None = None, seed: int | None = 0) -> None:
        super().__init__()
        self.config = config = config or NeuralTextureConfig()
        generator = None if seed is None else torch.Generator().manual_seed(int(seed))
        self.encoding = HashGrid3D(config.n_levels, config.n_features, config.log2_table,
                                   config.base_resolution, config.finest_resolution)
        self.mlp = torch.nn.Sequential(
            torch.nn.Linear(self.encoding.output_dim, config.hidden, bias=False),
            torch.nn.ReLU(),
            torch.nn.Linear(config.hidden, len(CHANNELS), bias=False),
        )
        # Deterministic initialisation for a given seed (the hash table: uniform(-1e-4, 1e-4)).
        with torch.no_grad():
            torch.nn.init.uniform_(self.encoding.table, -1e-4, 1e-4, generator=generator)
            for layer in (self.mlp[0], self.mlp[2]):
                torch.nn.init.kaiming_uniform_(layer.weight, a=5**0.5, generator=generator)
        self.register_buffer("_lo", torch.tensor(config.channel_min, dtype=torch.float32), persistent=False)
        self.register_buffer("_hi", torch.tensor(config.channel_max, dtype=torch.float32), persistent=False)
        if config.residual:
            with torch.no_grad():
                self.mlp[2].weight.zero_()   # the residual is exactly zero at the start
            self.register_buffer("base_logit", torch.zeros(config.resolution, config.resolution, len(CHANNELS)))
        self._plan_cache: tuple | None = None
        # Where adaptation re-mapped the surface (core.surface_layout.SurfaceLayout), saved with the weights.
        self.layout: SavedLayout | None = None

    # -- the exact start ---------------------------------------------------------------------------

    def set_base(self, stack) -> None:
        """The asset's own maps (R, R, 5), in the channels' units, as the texture's base."""
        if not self.config.residual:
            raise InputError("Only a residual neural texture has a base; make it with residual=True.")
        stack = _tensor(stack).to(self.base_logit.device, torch.float32)
        if tuple(stack.shape) != tuple(self.base_logit.shape):
            raise InputError(f"The base maps are {tuple(stack.shape)} but the texture is {tuple(self.base_logit.shape)}.")
        with torch.no_grad():
            self.base_logit.copy_(to_logit(stack, self._lo, self._hi))

    def residual_is_zero(self) -> bool:
        """True while the texture is its base exactly (nothing learned yet): no network pass needed."""
        return self.config.residual and not bool(self.mlp[2].weight.detach().any())

    def base_values(self, base_logit: torch.Tensor | None = None) -> torch.Tensor:
        """The base maps (H, W, 5) in the channels' units (the stored base, or one resampled from it)."""
        logits = self.base_logit if base_logit is None else base_logit
        return self._lo + (self._hi - self._lo) * torch.sigmoid(logits)

    def base_logit_at(self, rows: slice, cols: slice, size: int) -> torch.Tensor:
        """The stored base's window [rows, cols] (an atlas cell) resampled to size x size, as logits."""
        window = self.base_logit[rows, cols].permute(2, 0, 1)[None]
        mode = "area" if size < window.shape[-1] else "bilinear"
        kwargs = {} if mode == "area" else {"align_corners": False}
        return torch.nn.functional.interpolate(window, size=(size, size), mode=mode, **kwargs)[0].permute(1, 2, 0)

    # -- evaluation -------------------------------------------------------------------------------

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """points (N, 3) in normalised object space ([-bound, bound]^3) -> (N, 5)."""
        return self._head(self.encoding(self._unit(points)))

    def plan(self, position_map, mask, fill_index) -> TexelPlan:
        """Precompute the fixed part of evaluating a texture on `mask` texels of `position_map`.

        position_map (H, W, 3), mask (H, W) bool (texels to evaluate, e.g. UVRaster.border),
        fill_index (H*W,) nearest evaluated texel of every texel (UVRaster.fill_index).
        numpy arrays or tensors; a plan is tied to this texture's config and device.
        """
        device = self._lo.device
        pos, msk, fill = _tensor(position_map), _tensor(mask), _tensor(fill_index)
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise InputError(f"The position map must be (H, W, 3), got {tuple(pos.shape)}.")
        h, w = pos.shape[:2]
        if tuple(msk.shape) != (h, w):
            raise InputError(f"The mask is {tuple(msk.shape)} but the position map is {h}x{w}.")
        if fill.numel() != h * w:
            raise InputError(f"The seam fill index has {fill.numel()} entries for a {h}x{w} texture.")
        msk = msk.to(device=device, dtype=torch.bool).reshape(-1)
        fill = fill.to(device=device, dtype=torch.int64).reshape(-1)
        texels = torch.nonzero(msk).squeeze(1)
        if texels.numel() == 0:
            raise InputError("No texel is covered by the mesh's UV map; nothing to texture.")
        if fill.min() < 0 or fill.max() >= h * w or not bool(msk[fill].all()):
            raise InputError("The seam fill index points at texels outside the mask; build both from one UVRaster.")
        rank = torch.full((h * w,), -1, dtype=torch.int64, device=device)
        rank[texels] = torch.arange(texels.numel(), device=device)
        points = self._unit(pos.to(device=device, dtype=torch.float32).reshape(-1, 3)[texels])
        return TexelPlan(shape=(h, w), texels=texels, points=points, gather=rank[fill],
                         encoding=self.encoding.plan(points), config=self.config)

    def subset_plan(self, plan: TexelPlan, rows: torch.Tensor) -> TexelPlan:
        """A plan for some of a plan's texels (`rows` index plan.texels); its texture is (1, len(rows))."""
        rows = rows.to(plan.texels.device)
        points = plan.points[rows]
        return TexelPlan(shape=(1, rows.numel()), texels=plan.texels[rows], points=points,
                         gather=torch.arange(rows.numel(), device=rows.device),
                         encoding=self.encoding.plan(points), config=self.config)

    def texture_from_plan(self, plan: TexelPlan, base_logit: torch.Tensor | None = None) -> torch.Tensor:
        """(H, W, 5) texture on the plan's texels, dilated past seams. Differentiable.
        base_logit: a residual texture's base for this plan's raster (default: the stored one)."""
        if plan.config != self.config:
            raise InputError("This texel plan was made for a neural texture with another config.")
        values = self.values_from_plan(plan, base_logit)
        return values[plan.gather].view(*plan.shape, len(CHANNELS))

    def values_from_plan(self, plan: TexelPlan, base_logit: torch.Tensor | None = None) -> torch.Tensor:
        """(K, 5) values at the plan's texels only (in plan.texels order)."""
        features = self.mlp(self.encoding.forward_planned(plan.encoding))
        if self.config.residual:
            features = features + self._base_rows(plan.texels, base_logit)
        return self._lo + (self._hi - self._lo) * torch.sigmoid(features)

    def _base_rows(self, texels: torch.Tensor, base_logit: torch.Tensor | None) -> torch.Tensor:
        base = self.base_logit if base_logit is None else base_logit.to(self.base_logit.device)
        return base.reshape(-1, len(CHANNELS))[texels]

    def texture(self, position_map, mask, fill_index, base_logit: torch.Tensor | None = None) -> torch.Tensor:
        """(H, W, 5) texture: the network on `mask` texels, copied outward past seams via fill_index.

        The plan is cached while the same read-only numpy arrays (e.g. a UVRaster's) or unchanged
        tensors are passed again, so calling this every iteration costs one forward pass.
        base_logit: a residual texture's base for this raster when it is not the stored one's (the
        game bake's per-material raster); a residual still zero is its base, with no network pass.
        """
        if self.config.residual:
            base = self.base_logit if base_logit is None else base_logit
            h, w = np.shape(position_map)[:2]
            if tuple(base.shape[:2]) != (h, w):
                raise InputError(f"This texture's base is {tuple(base.shape[:2])} but the raster is {h}x{w}; give "
                                 "the base for this raster (base_logit_at).")
            if self.residual_is_zero():
                # The base itself, every texel: the asset's own image, uncovered texels included (a
                # palette several materials sample then bakes to the same pixels for each of them).
                return self.base_values(base).reshape(h, w, len(CHANNELS))
        if base_logit is not None:
            return self.texture_from_plan(self.plan(position_map, mask, fill_index), base_logit)
        key = _cache_key((position_map, mask, fill_index))
        if key is not None and self._plan_cache is not None and self._plan_cache[0] == key[0] \
                and all(ref() is obj for ref, obj in zip(self._plan_cache[1], (position_map, mask, fill_index))):
            plan = self._plan_cache[2]
        else:
            plan = self.plan(position_map, mask, fill_index)
            if key is not None:
                self._plan_cache = (key[0], key[1], plan)
        return self.texture_from_plan(plan)

    # -- helpers ----------------------------------------------------------------------------------

    def _unit(self, points: torch.Tensor) -> torch.Tensor:
        """Normalised object space [-bound, bound]^3 -> the grid's [0, 1]^3."""
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"Points must be (N, 3), got {tuple(points.shape)}.")
        return points.to(self._lo.device, torch.float32) / (2.0 * self.config.bound) + 0.5

    def _head(self, features: torch.Tensor) -> torch.Tensor:
        if self.config.residual:
            raise InputError("A residual neural texture is evaluated on texels (texture / texture_from_plan), "
                             "where its base is known, not at free points.")
        return self._lo + (self._hi - self._lo) * torch.sigmoid(self.mlp(features))

    def _apply(self, fn, recurse=True):  # .to(device) invalidates cached plans
        self._plan_cache = None
        return super()._apply(fn, recurse)


# Values this close to a channel's ends are the ends: logit(0) is -inf, and 1e-6 is below one 16-bit level.
LOGIT_EPS = 1e-6


def to_logit(stack: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Channel values -> the logits the texture's sigmoid maps back to them (clamped to the range)."""
    unit = ((stack - lo) / (hi - lo)).clamp(LOGIT_EPS, 1.0 - LOGIT_EPS)
    return torch.log(unit) - torch.log1p(-unit)


def split_channels(stack: _Stack) -> tuple[_Stack, _Stack, _Stack]:
    """The 5-channel stack (..., 5) as the renderer takes it: base colour (..., 3), roughness (..., 1),
    metallic (..., 1) (views, not copies)."""
    return stack[..., 0:3], stack[..., 3:4], stack[..., 4:5]


def _tensor(x) -> torch.Tensor:
    """A tensor view of x; read-only numpy arrays are copied (torch wants writable memory)."""
    if torch.is_tensor(x):
        return x
    x = np.asarray(x)
    return torch.from_numpy(x if x.flags.writeable else x.copy())


def _cache_key(arrays) -> tuple | None:
    """A key that identifies unchanged inputs, or None when they might change in place."""
    versions = []
    refs = []
    for a in arrays:
        if torch.is_tensor(a):
            versions.append((id(a), a._version))
        elif isinstance(a, np.ndarray) and not a.flags.writeable:
            versions.append((id(a), 0))
        else:
            return None
        refs.append(weakref.ref(a))
    return tuple(versions), tuple(refs)
