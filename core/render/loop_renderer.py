"""The optimisation loop's renderer: deferred shading of cached G-buffers in torch, exact gradients.

In the adapt stage only the texture changes: mesh, cameras and light are fixed for the whole run.
So each view is traced once by Mitsuba (core/render/gbuffer.py: which texels each sub-pixel sample
reads, its shading normal and view, and its light with visibility), and a step renders it by reading
the texture at those texels and shading analytically with Mitsuba's own principled BSDF tabulated
(core/render/brdf_tables.py), split-sum style:

    radiance = (1 - m) base D(cos, r) diffuse + ((1 - m) S(cos, r) + m (base A(cos, r) + B(cos, r))) specular(r)

(specular(r) interpolated between the cached roughness levels). The image is a plain torch function
of the maps, so autograd's gradients to the texture are exact, on whichever device the maps are.
`LoopRenderer.render` takes what `AssetRenderer.render` takes; spp and seed are the G-buffer's, fixed.
Mitsuba's path tracer stays the reference (compose, light and the checks use it); how far the two
agree on the corpus is measured by benchmarks/bench_loop_render.py.
"""
from __future__ import annotations

import hashlib
import time

import numpy as np
import torch

from .brdf_tables import brdf_tables
from .gbuffer import LEVELS, GBuffer, GBufferOptions, PrefilteredEnvironment, trace_gbuffer
from .renderer import ENVMAP_KEY, RENDERER_TYPES, AssetRenderer, RenderOutput, SceneOptions, pad_envmap
from ..base.errors import InputError
from ..data.mesh import Mesh

MAX_CACHED_VIEWS = 256   # adapt's bank: 48 views, plus a global view per turn and render size


def asset_renderer(renderer_type: str, mesh: Mesh, maps_shape: tuple[int, int], envmap: np.ndarray,
                   options: SceneOptions = SceneOptions(), normal_map: np.ndarray | None = None):
    """The renderer `renderer_type` names: "loop" (this module) or "path" (Mitsuba's path tracing, with
    the integrator `options` names); both render(camera, base_color, roughness, metallic, envmap, spp, seed)."""
    if renderer_type not in RENDERER_TYPES:
        raise InputError(f"The renderer must be one of {RENDERER_TYPES}, got {renderer_type!r}.")
    if renderer_type == "loop":
        return LoopRenderer(mesh, maps_shape, envmap, options, normal_map=normal_map)
    return AssetRenderer(mesh, maps_shape, envmap, options, normal_map=normal_map)


class LoopRenderer:
    """One asset's scene (Mitsuba, for tracing) and its views' G-buffers, cached per camera and light."""

    def __init__(self, mesh: Mesh, maps_shape: tuple[int, int], envmap: np.ndarray,
                 options: SceneOptions = SceneOptions(), variant: str | None = None,
                 normal_map: np.ndarray | None = None, gbuffer: GBufferOptions = GBufferOptions()) -> None:
        if options.floor or options.sphere is not None:
            raise InputError("The loop renderer draws the asset alone; a floor or sphere needs the path tracer.")
        self.tracer = AssetRenderer(mesh, maps_shape, envmap, options, variant, normal_map)
        self.maps_shape, self.envmap_shape = self.tracer.maps_shape, self.tracer.envmap_shape
        self.normal_map, self.gbuffer_options = normal_map, gbuffer
        self._cache: dict[tuple, tuple[GBuffer, torch.Tensor]] = {}
        self._moved: dict[tuple, GBuffer] = {}   # copies on the maps' device (CUDA): moved once, not per step
        self._tables: dict[tuple, torch.Tensor] = {}
        self._prefiltered: dict[str, PrefilteredEnvironment] = {}   # per light map: every view under it reads them
        self.traced = self.reused = 0
        self.trace_seconds = 0.0   # spent tracing G-buffers, so a caller can tell it from the shading

    def gbuffer(self, camera, envmap) -> tuple[GBuffer, torch.Tensor]:
        """The view's G-buffer and the light's colour (the constant environment's, else ones); traced on
        first use, then kept."""
        return self._cache[self._traced(camera, envmap)]

    def _on(self, key: tuple, device: torch.device) -> GBuffer:
        """The G-buffer `key` on `device` (the one traced, where it is already there)."""
        gb = self._cache[key][0]
        if gb.slots.device == device:
            return gb
        if (key, str(device)) not in self._moved:
            self._moved[(key, str(device))] = gb.to(device)
        return self._moved[(key, str(device))]

    def _traced(self, camera, envmap) -> tuple:
        """The cache's key of the view's G-buffer, traced first if it is not there."""
        env = np.ascontiguousarray(torch.as_tensor(envmap).detach().cpu().float().numpy())
        if tuple(env.shape) != tuple(self.envmap_shape):
            raise InputError(f"Environment map shape {env.shape} differs from the scene's {self.envmap_shape}.")
        light = hashlib.blake2b(env.tobytes(), digest_size=16).hexdigest()
        key = (camera, light)
        if key in self._cache:
            self.reused += 1
            return key
        constant = bool(np.all(env == env.reshape(-1, 3)[0]))
        t0 = time.perf_counter()
        self.tracer.params[ENVMAP_KEY] = pad_envmap(torch.from_numpy(env)).numpy()
        self.tracer.params.update()
        prefiltered = None if constant else self._prefiltered_for(light, env)
        traced = trace_gbuffer(self.tracer, camera, self.gbuffer_options, self.normal_map, env, constant, prefiltered)
        self.trace_seconds += time.perf_counter() - t0
        colour = torch.from_numpy(env.reshape(-1, 3)[0].copy()) if constant else torch.ones(3)
        if len(self._cache) >= MAX_CACHED_VIEWS:   # views that never come back (a random light) must not pile up
            oldest = next(iter(self._cache))
            self._cache.pop(oldest)
            self._moved = {k: v for k, v in self._moved.items() if k[0] != oldest}
        self._cache[key] = (traced, colour)
        self.traced += 1
        return key

    def _prefiltered_for(self, light: str, env: np.ndarray) -> PrefilteredEnvironment:
        """The light map's pre-filtered tables (the scene's environment is set to it), built on first use."""
        if light not in self._prefiltered:
            if len(self._prefiltered) >= 4:   # a random light per view must not keep every map's tables
                self._prefiltered.pop(next(iter(self._prefiltered)))
            self._prefiltered[light] = PrefilteredEnvironment(self.tracer.scene, env)
        return self._prefiltered[light]

    def render_aovs(self, camera) -> dict[str, np.ndarray]:
        return self.tracer.render_aovs(camera)

    def cached_bytes(self) -> int:
        return sum(g.nbytes() for g, _ in self._cache.values())

    def render(self, camera, base_color, roughness, metallic, envmap, spp: int | None = None,
               seed: int | None = None) -> RenderOutput:
        """RGBA of the maps (torch (H, W, 3|1), linear) seen by `camera` under `envmap`; differentiable in
        the maps. spp and seed are accepted for AssetRenderer's signature: the G-buffer's samples are fixed."""
        t0 = time.perf_counter()
        key = self._traced(camera, envmap)
        stack = torch.cat([_channels(base_color, 3), _channels(roughness, 1), _channels(metallic, 1)], dim=-1)
        if tuple(stack.shape[:2]) != tuple(self.maps_shape):
            raise InputError(f"The maps are {tuple(stack.shape[:2])}, expected {self.maps_shape}.")
        rgb, alpha = shade(self._on(key, stack.device), stack, self._cache[key][1], self._tables_on(stack))
        return RenderOutput(rgb=rgb, alpha=alpha, seconds=time.perf_counter() - t0)

    def _tables_on(self, like: torch.Tensor) -> torch.Tensor:
        key = (like.device, like.dtype)
        if key not in self._tables:
            self._tables[key] = torch.from_numpy(brdf_tables()).to(device=like.device, dtype=like.dtype)
        return self._tables[key]


def _channels(tensor: torch.Tensor, channels: int) -> torch.Tensor:
    if tensor.ndim == 2:
        tensor = tensor[..., None]
    if tensor.shape[-1] != channels:
        raise InputError(f"A map has {tensor.shape[-1]} channels, expected {channels}.")
    return tensor


def shade(gb: GBuffer, stack: torch.Tensor, colour: torch.Tensor, tables: torch.Tensor
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """(h, w, 3) radiance and (h, w, 1) alpha of the maps `stack` (H, W, 5) on G-buffer `gb`."""
    device, dtype = stack.device, stack.dtype
    if gb.slots.device != device:
        gb = gb.to(device)
    flat = stack.reshape(-1, stack.shape[-1])
    taps = torch.index_select(flat, 0, gb.texels.reshape(-1)).view(*gb.texels.shape, flat.shape[-1])
    values = (taps * gb.weights.to(dtype)[..., None]).sum(dim=1)
    base, rough, metal = values[:, 0:3], values[:, 3:4], values[:, 4:5]
    cosine = gb.cosine.to(dtype)
    # grid_sample: x along roughness (the tables' last axis), y along the cosine.
    grid = torch.stack([rough[:, 0] * 2 - 1, cosine.clamp(0, 1) * 2 - 1], dim=-1).view(1, 1, -1, 2)
    lut = torch.nn.functional.grid_sample(tables[None], grid, mode="bilinear", padding_mode="border",
                                          align_corners=True)[0, :, 0].T
    d, s, a, b = (lut[:, i:i + 1] for i in range(4))
    light_d, light_s = gb.diffuse.to(dtype), _specular_at(gb.specular.to(dtype), rough)
    radiance = (1 - metal) * base * d * light_d + ((1 - metal) * s + metal * (base * a + b)) * light_s
    weight = (cosine > 0).to(dtype) * gb.share.to(dtype)
    radiance = radiance * weight[:, None] * colour.to(device=device, dtype=dtype)
    image = torch.zeros(gb.height * gb.width, 3, device=device, dtype=dtype).index_add(0, gb.slots, radiance)
    return image.view(gb.height, gb.width, 3), gb.alpha.to(device=device, dtype=dtype)


def _specular_at(levels: torch.Tensor, rough: torch.Tensor) -> torch.Tensor:
    """The cached specular light (n, K, C) at roughness `rough` (n, 1), linear between the K levels."""
    position = rough[:, 0].clamp(0, 1) * (len(LEVELS) - 1)
    low = position.detach().floor().clamp(max=len(LEVELS) - 2).long()
    frac = (position - low.to(position.dtype))[:, None]
    pick = torch.arange(len(levels), device=levels.device)
    return levels[pick, low] * (1 - frac) + levels[pick, low + 1] * frac
