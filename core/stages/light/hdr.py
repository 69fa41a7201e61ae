"""From the LDR map to an HDR map: one light scale per bright region, set by a prior and optimised by
rendering the object and the white-sphere apparatus (paper §3.4-3.6, appendix "Light Estimation").

    HDR = LDR_linear * (1 + sum_r mask_r * (exp(s_r) - 1))        s_r: log scale of region r

LDR_linear is the LDR map decoded from sRGB (radiance in the photo's exposure units); regions are
disjoint. Scales live in log space (Adam steps are relative, s is clamped to [LOG_SCALE_MIN,
LOG_SCALE_MAX] so the map stays finite).

Critics. Anything callable as `critic(renders, request) -> Tensor` scores the renders:
renders is (V, h, w, 3) linear radiance (during optimisation V = 1: one view at a time, named by
request.view_indices / view_names; object views first, the sphere last), and the return value is either per-view losses (V,) or image-space gradients (V, h, w, 3), which are turned
into the surrogate loss sum(grad.detach() * render) (the SDS/VSD convention). `ReferenceCritic`
(reference_critic.py) compares with renders under the true map; a diffusion critic from
core/guidance plugs in through the same call and reads the prompt and t range from the request.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
import torch

from ...render.orbit_camera import Camera
from ...base.errors import InputError
from ...data.imageio import linear_to_srgb, srgb_to_linear
from ...data.mesh import Mesh
from ...base.progress import ProgressCallback, check_cancel, emit
from ...render.renderer import AssetRenderer, SceneOptions, SphereSpec
from ...scene.frame import equirect_directions
from ...texture.neural_texture import split_channels
from .config import DEFAULT_L_WHITE, ApparatusConfig, OptimiseConfig

LOG_SCALE_MIN = math.log(1e-4)
LOG_SCALE_MAX = math.log(1e6)
SPHERE_PROMPT = "A gigantic diffuse white (spray-painted) sphere (ball)"
DARK_SUFFIX = "in a dark environment"
DARK_BACKGROUND_BELOW = 0.2
DARK_LIGHTS_BELOW = 50.0


# -- the HDR map -----------------------------------------------------------------------------------
def compose_hdr(ldr_linear: torch.Tensor, masks: dict[str, torch.Tensor], log_scales: dict[str, torch.Tensor]) -> torch.Tensor:
    """LDR (H, W, 3) linear with each region multiplied by exp(its log scale); differentiable in the scales."""
    factor = torch.ones_like(ldr_linear[..., :1])
    for name, mask in masks.items():
        factor = factor + mask[..., None].to(ldr_linear.dtype) * (torch.exp(log_scales[name]) - 1.0)
    return ldr_linear * factor


class LightVector:
    """The current map as the appendix's light vector (c_x, c_y, c_r, c_v, b_v), for conditioning ε_ψ.

    The dominant region is the one holding the most power (scale x radiance x solid angle); (c_x, c_y)
    is its power-weighted centre in map coordinates (u, v from the top, as the appendix samples
    lights), c_r its size as 1 - cos of the angular radius of a disc of the same solid angle (the
    appendix's Gaussian exp((d.mu - 1) / c_r) has that width), c_v its mean radiance and b_v the mean
    radiance outside every region. Per-region sums are taken once; each call only rescales them.
    """

    def __init__(self, ldr_linear: torch.Tensor, masks: dict[str, torch.Tensor]) -> None:
        h, w = ldr_linear.shape[:2]
        level = ldr_linear.double().mean(dim=-1)
        rows = (torch.arange(h, dtype=torch.float64) + 0.5) / h
        omega = (torch.sin(math.pi * rows) * (math.pi / h) * (2 * math.pi / w))[:, None].expand(h, w)
        dirs = torch.from_numpy(equirect_directions(h, w))
        outside = torch.ones(h, w, dtype=torch.bool)
        self.regions = {}
        for name, mask in masks.items():
            m = mask.bool()
            outside &= ~m
            power = float((level * omega)[m].sum())
            area = float(omega[m].sum())
            centre = (dirs[m] * (level * omega)[m][:, None]).sum(dim=0)
            self.regions[name] = (power, area, centre / max(float(centre.norm()), 1e-12))
        self.background = float((level * omega)[outside].sum() / omega[outside].sum()) if bool(outside.any()) else 0.0

    def __call__(self, scales: dict[str, float]) -> tuple[float, float, float, float, float]:
        if not self.regions:
            return (0.25, 0.0, 0.0, self.background, self.background)
        name = max(self.regions, key=lambda k: self.regions[k][0] * scales[k])
        power, area, centre = self.regions[name]
        x, y, z = (float(v) for v in centre)
        c_x = (0.5 - math.atan2(y, x) / (2 * math.pi)) % 1.0
        c_y = 0.5 - math.asin(max(-1.0, min(1.0, z))) / math.pi
        c_r = area / (2 * math.pi)
        return (round(c_x, 5), round(c_y, 5), round(c_r, 5), power * scales[name] / max(area, 1e-12), self.background)


def hdr_from_scales(ldr_srgb: np.ndarray, regions: dict[str, np.ndarray], scales: dict[str, float]) -> np.ndarray:
    """The HDR map (float32, linear) for given scales (not logs)."""
    ldr = torch.from_numpy(srgb_to_linear(ldr_srgb))
    masks = {k: torch.from_numpy(v) for k, v in regions.items()}
    logs = {k: torch.tensor(math.log(scales[k])) for k in regions}
    return compose_hdr(ldr, masks, logs).numpy().astype(np.float32)


def inverse_tonemap(display_linear: np.ndarray, l_white: float = DEFAULT_L_WHITE) -> np.ndarray:
    """Invert the extended Reinhard operator L_d = L (1 + L / Lw^2) / (1 + L):

        L = (Lw^2 / 2) * (L_d - 1 + sqrt((1 - L_d)^2 + 4 L_d / Lw^2))

    L_d in [0, 1] (a linear display value, i.e. the photo decoded from sRGB); L_d = 1 (clipped) gives
    L = Lw, the brightest radiance the photo is assumed to have clipped, in the photo's exposure units.
    """
    ld = np.clip(np.asarray(display_linear, np.float64), 0.0, 1.0)
    lw2 = float(l_white) ** 2
    return (lw2 / 2.0 * (ld - 1.0 + np.sqrt((1.0 - ld) ** 2 + 4.0 * ld / lw2))).astype(np.float32)


def prior_scales(ldr_srgb: np.ndarray, regions: dict[str, np.ndarray], l_white: float = DEFAULT_L_WHITE) -> dict[str, float]:
    """The inverse-tone-mapping prior: a region's scale is sum(L(I)) / sum(I) over its texels, where I is
    the texel's linear intensity (mean of RGB) and L the inverse tone curve above: the scale that gives
    the region the total radiance the inverse tone curve would give it."""
    level = srgb_to_linear(ldr_srgb).mean(axis=-1)
    scales = {}
    for name, mask in regions.items():
        i = level[mask].astype(np.float64)
        scales[name] = float(max(inverse_tonemap(i, l_white).sum() / max(i.sum(), 1e-9), 1.0))
    return scales


def tonemap_preview(hdr: np.ndarray, l_white: float = DEFAULT_L_WHITE) -> np.ndarray:
    """sRGB [0, 1] preview by the extended Reinhard operator (the forward of `inverse_tonemap`), so the
    prior's HDR previews as the LDR map and brighter lights roll off instead of clipping."""
    x = np.maximum(np.asarray(hdr, np.float64), 0.0)
    lw2 = float(l_white) ** 2
    return linear_to_srgb((x * (1.0 + x / lw2) / (1.0 + x)).astype(np.float32))


# -- light-conditional prompt ----------------------------------------------------------------------
def is_dark_environment(hdr: np.ndarray, regions: dict[str, np.ndarray]) -> tuple[bool, dict]:
    """The appendix's rule: dark when mean background intensity < 0.2 AND mean light-area intensity < 50.

    Intensities are means of RGB of the HDR map (the background is the LDR map decoded from sRGB);
    with no light region the light-area mean is taken as 0.
    """
    level = np.asarray(hdr, np.float64)[..., :3].mean(axis=-1)
    lights = np.zeros(level.shape, bool)
    for mask in regions.values():
        lights |= mask
    background = float(level[~lights].mean()) if (~lights).any() else 0.0
    light_mean = float(level[lights].mean()) if lights.any() else 0.0
    dark = background < DARK_BACKGROUND_BELOW and light_mean < DARK_LIGHTS_BELOW
    return dark, {"background_mean": round(background, 5), "light_mean": round(light_mean, 5), "dark": dark,
                  "rule": f"background < {DARK_BACKGROUND_BELOW} and lights < {DARK_LIGHTS_BELOW}"}


def light_prompt(base: str, dark: bool, tint: str | None = None) -> str:
    parts = [base] + ([DARK_SUFFIX] if dark else []) + ([tint.strip()] if tint and tint.strip() else [])
    return ", ".join(parts)


# -- critics ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CriticRequest:
    """What a critic may need besides the images: one prompt and name per view, progress, t range."""

    prompts: tuple[str, ...]
    view_names: tuple[str, ...]
    iteration: int
    iterations: int
    t_range: tuple[int, int] = (750, 990)
    alphas: torch.Tensor | None = None   # (V, h, w, 1) coverage of the object and sphere, for critics that composite
    view_indices: tuple[int, ...] = ()   # which of the scene's views these renders are
    light: tuple[float, ...] | None = None   # the current map as (c_x, c_y, c_r, c_v, b_v), see `light_vector`
    floor_alphas: torch.Tensor | None = None  # (V, h, w, 1) coverage of the floor (its shadow goes into the photo)


class Critic(Protocol):
    def __call__(self, renders: torch.Tensor, request: CriticRequest) -> torch.Tensor: ...


def per_view_losses(output: torch.Tensor, renders: torch.Tensor) -> torch.Tensor:
    """(V,) losses from a critic's output: losses as they are, or gradients via the surrogate loss."""
    if output.ndim == 1 and output.shape[0] == renders.shape[0]:
        return output
    if output.shape == renders.shape:
        return (output.detach() * renders).flatten(1).sum(dim=1)
    raise InputError(f"A critic must return (V,) losses or (V, h, w, 3) gradients; got {tuple(output.shape)}.")


# -- the apparatus scene ---------------------------------------------------------------------------
class ApparatusScene:
    """The object (fixed appearance) on the floor with the sphere beside it, rendered under an HDR map."""

    def __init__(self, mesh: Mesh, maps: torch.Tensor, envmap_shape: tuple[int, int], config: ApparatusConfig,
                 photo_azimuth_deg: float = 0.0) -> None:
        self.config = config
        floor_z = float(mesh.positions[:, 2].min())
        center = (config.sphere_offset[0], config.sphere_offset[1], floor_z + config.sphere_radius)
        self.sphere = SphereSpec(center=center, radius=config.sphere_radius, albedo=1.0)
        h, w = envmap_shape
        self.maps = tuple(m.contiguous() for m in split_channels(maps))
        self.renderer = AssetRenderer(mesh, tuple(maps.shape[:2]), np.full((h, w, 3), 0.5, np.float32),
                                      SceneOptions(floor=config.floor, sphere=self.sphere, max_depth=config.max_depth,
                                                   integrator_type="prb"))
        size = config.render_size
        self.cameras = [Camera(azimuth_deg=photo_azimuth_deg + a, elevation_deg=config.elevation_deg,
                               fov_multiplier=config.fov_multiplier, width=size, height=size)
                        for a in config.object_azimuths]
        # The sphere's view: from the photo's direction, framing the sphere (radius r at distance 2
        # subtends about 2 asin(r / 2); lambda chosen to leave a 20 % margin).
        lam = 1.2 * config.sphere_radius / 0.5
        self.cameras.append(Camera(azimuth_deg=photo_azimuth_deg, elevation_deg=config.elevation_deg,
                                   fov_multiplier=lam, width=size, height=size, target=center))
        self.view_names = tuple(f"object_az{a:+.0f}" for a in config.object_azimuths) + ("sphere",)
        self.weights = torch.tensor(config.view_weights, dtype=torch.float32)
        self.mesh, self.floor_z = mesh, floor_z
        self._object_alphas: dict[int, torch.Tensor] = {}

    def object_alpha(self, index: int) -> torch.Tensor:
        """(h, w, 1) coverage of the object and the sphere alone (the floor left out), for view `index`.
        Geometry only, so rendered once per view (without the floor, 4x the spp for clean edges)."""
        if index not in self._object_alphas:
            if not self.config.floor:
                with torch.no_grad():
                    self._object_alphas[index] = self.render_view(torch.full(self.renderer.envmap_shape, 0.5), index)[1]
            else:
                if not hasattr(self, "_no_floor"):
                    self._no_floor = AssetRenderer(self.mesh, self.renderer.maps_shape,
                                                   np.full(self.renderer.envmap_shape, 0.5, np.float32),
                                                   SceneOptions(sphere=self.sphere, max_depth=2))
                with torch.no_grad():
                    out = self._no_floor.render(self.cameras[index], *self.maps,  # type: ignore[call-arg, misc]
                                                torch.full(self.renderer.envmap_shape, 0.5), spp=4 * self.config.spp)
                self._object_alphas[index] = out.alpha
        return self._object_alphas[index]

    def photo_squares(self, object_box: tuple[float, float, float]) -> list[tuple[float, float, float]]:
        """Where each view's square rendering goes in the photo (x0, y0, side in pixels), as the paper
        alpha-blends a rendering "according to the user-provided position and size": object_box is the
        square the normalised object (1 unit across) spans, standing on the floor; a view with FOV
        multiplier λ spans λ units at its target (core/render/orbit_camera.py), centred on the target's place."""
        ox, oy, side = object_box
        unit = side                                   # photo pixels per world unit at the object
        base_x, floor_y = ox + side / 2, oy + side    # the object's foot on the floor
        squares = []
        for camera in self.cameras:
            tx, _, tz = camera.target
            cx, cy = base_x + tx * unit, floor_y - (tz - self.floor_z) * unit
            span = camera.fov_multiplier * unit
            squares.append((cx - span / 2, cy - span / 2, span))
        return squares

    def render(self, envmap: torch.Tensor, spp: int | None = None, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        """(V, h, w, 3) radiance and (V, h, w, 1) alpha, one per view. For evaluation (no gradients): the
        renderer's one sensor is moved for every view, so a backward pass after several views would
        replay them all from the last camera; `render_view` + immediate backward is the training path."""
        with torch.no_grad():
            outs = [self.render_view(envmap, i, spp, seed) for i in range(len(self.cameras))]
        return torch.stack([o[0] for o in outs]), torch.stack([o[1] for o in outs])

    def render_view(self, envmap: torch.Tensor, index: int, spp: int | None = None,
                    seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.renderer.render(self.cameras[index], *self.maps, envmap, spp=spp or self.config.spp,  # type: ignore[call-arg, misc]
                                   seed=seed * 16 + index)
        return out.rgb, out.alpha


# -- optimisation ----------------------------------------------------------------------------------
@dataclass
class OptimiseResult:
    log_scales: dict[str, float]
    loss_history: list[float] = field(default_factory=list)
    scale_history: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0


def optimise_scales(scene: ApparatusScene, ldr_srgb: np.ndarray, regions: dict[str, np.ndarray],
                    initial_scales: dict[str, float], critic: Critic, prompts: tuple[str, ...],
                    config: OptimiseConfig = OptimiseConfig(), progress: ProgressCallback | None = None,
                    cancel: threading.Event | None = None,
                    on_iteration: Callable[[int, dict[str, float]], None] | None = None) -> OptimiseResult:
    """Adam on the log scales: render every view -> critic -> weighted loss -> backward -> step -> clamp."""
    t0 = time.perf_counter()
    ldr = torch.from_numpy(srgb_to_linear(ldr_srgb))
    masks = {k: torch.from_numpy(v) for k, v in regions.items()}
    log_scales = {k: torch.tensor(math.log(max(initial_scales[k], 1e-12)), requires_grad=True) for k in regions}
    result = OptimiseResult({k: float(v.detach()) for k, v in log_scales.items()})
    if not regions or config.iterations == 0:
        result.seconds = time.perf_counter() - t0
        return result
    optimizer = torch.optim.Adam(list(log_scales.values()), lr=config.lr)
    n = config.iterations
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda it: 1.0 - (1.0 - config.lr_final_factor) * min(it, n - 1) / max(n - 1, 1))
    light_vector = LightVector(ldr, masks)
    for it in range(n):
        check_cancel(cancel)
        optimizer.zero_grad()
        loss = 0.0
        light = light_vector({k: math.exp(float(v.detach())) for k, v in log_scales.items()})
        for v in range(len(scene.cameras)):
            # Compose the HDR map from the current scales and render one view.
            envmap = compose_hdr(ldr, masks, log_scales)
            render, alpha = scene.render_view(envmap, v, seed=config.seed * 100003 + it)
            # Score it and weight it ({1/6, 1/6, 1/6, 1/2}); backward now, while the sensor is this view's
            # (Mitsuba replays the path from the renderer's current camera on backward).
            coverage = scene.object_alpha(v)
            request = CriticRequest((prompts[v],), (scene.view_names[v],), it, n, config.t_range, coverage[None], (v,),
                                    light, (alpha - coverage).clamp(0.0, 1.0)[None])
            view_loss = scene.weights[v] * per_view_losses(critic(render[None], request), render[None]).sum()
            view_loss.backward()
            loss += float(view_loss.detach())
        # Step in log space, then keep the scales finite.
        optimizer.step()
        schedule.step()
        with torch.no_grad():
            for s in log_scales.values():
                s.clamp_(LOG_SCALE_MIN, LOG_SCALE_MAX)
        current = {k: float(v.detach()) for k, v in log_scales.items()}
        result.loss_history.append(loss)
        result.scale_history.append({k: math.exp(v) for k, v in current.items()})
        if on_iteration is not None:
            on_iteration(it, current)
        emit(progress, "light", it + 1, n, metrics={"loss": loss,
                                                    **{f"scale_{k}": math.exp(v) for k, v in current.items()}})
    result.log_scales = {k: float(v.detach()) for k, v in log_scales.items()}
    result.seconds = time.perf_counter() - t0
    return result
