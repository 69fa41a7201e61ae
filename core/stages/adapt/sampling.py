"""Every random choice of one view of one adapt step: camera, light, background, timestep, noise, crops.

A view's choices come from generators seeded by (seed, iteration, view index) only, so a run
resumed from a checkpoint repeats the uninterrupted one, and the views of a step are the same
whether one device renders all of them or each rank of torch.distributed renders its share.

Scene and edit modes draw their views from a fixed bank (`draw_view_bank`, drawn once from the seed):
`view_variants` entries on each of the paper's `views` azimuths, each with its own field of view,
background, reference-render seed and global crops. What depends only on an entry (the reference
render's latents, the ⟨camera, normal⟩ weights, each crop's mask and masked-photo latents) is then
the same every time the entry comes back, so the stage computes it once (core/stages/adapt/constants.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ...render.orbit_camera import Camera
from ...guidance.lora import AMBIENT_LIGHT
from ...guidance.views import background_color, sample_crops
from ...guidance.weighting import interpolation_lambda, sample_timestep
from ...scene.frame import equirect_directions
from .config import AdaptConfig, StageSpec, stage_at

Light = tuple[float, float, float, float, float]   # the appendix's (c_x, c_y, c_r, c_v, b_v)


@dataclass
class ViewSample:
    """What one view of one step looks at and with which noise."""

    index: int                          # the view's index within the step (0 .. views_per_step - 1)
    stage: StageSpec
    camera: Camera
    envmap: np.ndarray | None           # None: the stage's base map (ambient, or the user's map)
    light: Light
    background: tuple[float, float, float]
    t: int
    lam: float
    noise: torch.Tensor                 # (1, 4, h, w) on the CPU
    render_seed: int
    prompt: str
    crops: list[tuple[float, float, float]]
    rng: np.random.Generator            # for the draws that follow (ε_ψ's update)
    generator: torch.Generator
    entry: int | None = None            # the view bank's entry (None: drawn afresh, "generate")
    reference_seed: int = 0             # the reference render's seed (the entry's, so it can be cached)


@dataclass(frozen=True)
class BankView:
    """One fixed view of the bank: an azimuth of the paper's set and the choices drawn for it once."""

    azimuth_deg: float
    elevation_deg: float
    fov_multiplier: float
    background: tuple[float, float, float]
    reference_seed: int
    crops: tuple[tuple[float, float, float], ...]


# The bank's own stream of the seed (the steps' streams are (seed, iteration, view)).
BANK_STREAM = 0x5CE4E


def uses_view_bank(config: AdaptConfig) -> bool:
    """Scene and edit modes have constant work per view (the reference, the photo); "generate" has none."""
    return config.mode_type != "generate"


def draw_view_bank(config: AdaptConfig, photo_hw: tuple[int, int] | None,
                   object_box: tuple[float, float, float] | None) -> list[BankView]:
    """`views` x `view_variants` fixed views: each azimuth of the paper's set, with λ_FOV, elevation,
    background, reference seed and crops drawn as a step would draw them, once, from the seed."""
    rng = np.random.default_rng([config.seed, BANK_STREAM])
    bank = []
    for k in range(config.views):
        for _ in range(config.view_variants):
            camera = _camera(config, rng, k, 8)
            background = background_color(rng, config.background_random_p)
            crops: tuple = ()
            if config.views_type == "local+global" and photo_hw is not None and object_box is not None:
                crops = tuple(sample_crops(photo_hw, object_box, config.global_crops, rng))
            bank.append(BankView(camera.azimuth_deg, camera.elevation_deg, camera.fov_multiplier, background,
                                 int(rng.integers(2**31 - 2**16)), crops))
    return bank


def sample_view(config: AdaptConfig, iteration: int, index: int, latent_res: int, envmap: np.ndarray | None,
                photo_hw: tuple[int, int] | None, object_box: tuple[float, float, float] | None,
                bank: list[BankView] | None = None) -> ViewSample:
    """The choices for view `index` of step `iteration`; object_box: the square (x0, y0, side) in photo
    pixels that every global crop must hold (None: no global views); bank: the fixed views to pick
    from (None: camera, background and crops drawn afresh)."""
    rng = np.random.default_rng([config.seed, iteration, index])
    generator = torch.Generator().manual_seed(int(rng.integers(2**62)))
    progress = iteration / max(1, config.iterations - 1)
    stage = stage_at(config, iteration)
    entry = None
    if bank:
        entry = int(rng.integers(len(bank)))
        fixed = bank[entry]
        camera = Camera(fixed.azimuth_deg, fixed.elevation_deg, fixed.fov_multiplier, width=stage.render_size,
                        height=stage.render_size)
        background = fixed.background
    else:
        camera = sample_camera(config, rng, stage.render_size)
    env, light = sample_light(config, rng, envmap)
    if not bank:
        background = background_color(rng, config.background_random_p)
    t = sample_timestep(rng, stage.t_range, progress, config.timestep_anneal_type)
    noise = torch.randn(1, 4, latent_res, latent_res, generator=generator)
    lam = interpolation_lambda(progress, config.critic.lambda_end, config.critic.critic_type)
    prompt = config.effective_prompt
    if config.mode_type == "generate":
        prompt = f"{prompt}, {view_suffix(camera.azimuth_deg)}"
    render_seed = int(rng.integers(2**31 - 2**16))
    crops, reference_seed = [], render_seed
    if bank:
        assert entry is not None   # (a view of the bank has its entry)
        crops, reference_seed = list(bank[entry].crops), bank[entry].reference_seed
    elif config.views_type == "local+global" and photo_hw is not None and object_box is not None:
        crops = sample_crops(photo_hw, object_box, config.global_crops, rng)
    return ViewSample(index, stage, camera, env, light, background, t, lam, noise, render_seed, prompt, crops,
                      rng, generator, entry, reference_seed)


def sample_camera(config: AdaptConfig, rng: np.random.Generator, size: int) -> Camera:
    """One of `views` evenly spaced azimuths, the user's elevation (or one of the choices, perturbed),
    and λ_FOV uniform in fov_range."""
    return _camera(config, rng, int(rng.integers(config.views)), size)


def view_azimuths(views: int) -> list[float]:
    """The `views` evenly spaced azimuths (degrees) the orbit cameras are drawn from."""
    return [360.0 * k / views for k in range(views)]


def _camera(config: AdaptConfig, rng: np.random.Generator, k: int, size: int) -> Camera:
    azimuth = view_azimuths(config.views)[k]
    if config.elevation_choices:
        elevation = float(config.elevation_choices[int(rng.integers(len(config.elevation_choices)))])
        elevation = float(np.clip(elevation + rng.uniform(-5.0, 5.0), -89.0, 89.0))
    else:
        elevation = config.elevation
    fov = float(rng.uniform(*config.fov_range))
    return Camera(azimuth, elevation, fov, width=size, height=size)


def view_suffix(azimuth_deg: float) -> str:
    """View-dependent prompting (DreamFusion): front within 45 degrees of azimuth 0, back within 45 of 180."""
    a = (azimuth_deg + 180.0) % 360.0 - 180.0
    return "front view" if abs(a) <= 45.0 else "back view" if abs(a) >= 135.0 else "side view"


def spherical_gaussian_environment(light: Light, height: int = 32) -> np.ndarray:
    """The appendix's light: background b_v plus an isotropic spherical Gaussian of intensity c_v,
    radius c_r centred at image coordinates (c_x, c_y) of the latitude-longitude map (Blender's
    equirectangular convention, v from the top)."""
    cx, cy, cr, cv, bv = light
    dirs = equirect_directions(height, 2 * height)
    # Direction at the centre pixel (c_x, c_y).
    i = min(height - 1, max(0, int(cy * height)))
    j = min(2 * height - 1, max(0, int(cx * 2 * height)))
    mu = dirs[i, j]
    env = np.full((height, 2 * height, 3), bv, np.float32)
    if cr > 0 and cv > 0:
        env += (cv * np.exp((dirs @ mu - 1.0) / cr))[..., None].astype(np.float32)
    return env


def sample_light(config: AdaptConfig, rng: np.random.Generator, envmap: np.ndarray | None,
                 height: int = 16) -> tuple[np.ndarray | None, Light]:
    """(environment map for this view, or None for the base map; its light vector for ε_ψ)."""
    if config.light_type == "envmap":
        assert envmap is not None   # (AdaptInputs refuses light_type envmap without a map)
        mean = float(np.mean(envmap))
        return None, (AMBIENT_LIGHT[0], AMBIENT_LIGHT[1], 0.0, mean, mean)
    if config.light_type == "random" and rng.uniform() < config.light_random_p:
        light = (float(rng.uniform(0.0, 1.0)), float(rng.uniform(0.0, 0.5)), 0.08, float(rng.uniform(12.0, 15.0)), 0.8)
        return spherical_gaussian_environment(light, height), light
    a = config.ambient
    return None, (AMBIENT_LIGHT[0], AMBIENT_LIGHT[1], 0.0, a, a)
