"""The adapt stage: a neural texture restyled by diffusion critics (paper §3.1, §3.3, appendix).

Modes (`mode_type`):
- "scene": the paper's scene-conditional adaptation (setup (o)): the local view (object on solid
  colours, vanilla SD with reference feature injection, VSD) and the global views (object
  composited into the photo at its placement, crops at several scales, SD inpainting), weighed
  equally. Starts from the converted texture.
- "generate": scene-agnostic texture generation from a prompt (setup (a)): fresh texture, no
  reference, 72-view style camera sampling over elevations {20, 30, 45}, λ_FOV in [0.6, 1.21],
  view-dependent prompts, optional random spherical-Gaussian lights.
- "edit": scene-agnostic editing from an instruction (setup (c)): the object prompt and the
  instruction combined into one description, reference feature injection, local views only.

One iteration (per process; with torch.distributed each rank renders its own view and the
gradients are averaged):
  sample camera, background, timestep, noise -> render the texture (Mitsuba, differentiable)
  -> views -> VAE encode -> critics (UNet passes) -> backward through VAE, renderer and texture
  -> Adam step on the texture MLP/hash grid -> one LoRA step for ε_ψ on the rendered latents.
Every random choice of iteration i comes from a generator seeded by (seed, i, rank), so a run
resumed from a checkpoint repeats the uninterrupted one.
"""
from __future__ import annotations

import io
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from .atomic import write_bytes_atomic
from .camera import Camera
from .errors import InputError
from .guidance.critics import CriticConfig, ScoreCritic
from .guidance.injection import ReferenceInjector
from .guidance.lora import AMBIENT_LIGHT, LoraCritic, camera_condition
from .guidance.models import GuidanceModels, ModelConfig, load_guidance_models, locate_models
from .guidance.views import (Placement, background_color, global_view, latent_mask,
                             local_view, masked_image, sample_crops)
from .guidance.weighting import (ANNEAL_TYPES, NORMAL_WEIGHT_TYPES, interpolation_lambda, normal_weight_map,
                                 sample_timestep)
from .mesh import Mesh
from .progress import ProgressCallback, check_cancel, emit
from .render import AssetRenderer, SceneOptions, equirect_directions
from .texture.bake import torch_load_reason
from .texture.neural_texture import NeuralTexture, preset
from .texture.uv_raster import UVRaster

MODE_TYPES = ("scene", "generate", "edit")
VIEWS_TYPES = ("local+global", "local")
LIGHT_TYPES = ("ambient", "envmap", "random")
CHECKPOINT_FILE = "adapt_checkpoint.pt"
CHECKPOINT_FORMAT = "scenefit.adapt_checkpoint"
# Settings that may change between a run and its resumption.
RESUMABLE_FIELDS = ("checkpoint_every", "preview_every")


@dataclass(frozen=True)
class StageSpec:
    """One coarse-to-fine stage: its share of the iterations, render size, samples per pixel, t range."""

    fraction: float
    render_size: int
    spp: int
    t_range: tuple[int, int]

    def __post_init__(self) -> None:
        if not 0.0 < self.fraction <= 1.0:
            raise InputError(f"A stage's fraction must be in (0, 1], got {self.fraction}.")
        if self.render_size < 8 or self.spp < 1:
            raise InputError(f"A stage needs render_size >= 8 and spp >= 1, got {self.render_size}, {self.spp}.")
        lo, hi = self.t_range
        if not 0 <= lo <= hi <= 999:
            raise InputError(f"A stage's timestep range must satisfy 0 <= lo <= hi <= 999, got {self.t_range}.")
        object.__setattr__(self, "t_range", (int(lo), int(hi)))


PAPER_STAGES = (StageSpec(0.2, 256, 64, (30, 990)), StageSpec(0.8, 512, 128, (500, 990)))


@dataclass(frozen=True)
class AdaptConfig:
    """Settings of the adapt stage; defaults are the paper's (see ADAPT_PRESETS for faster ones).

    prompt: the appearance description the critics are conditioned on (the paper's GPT-written,
    scene-conditional prompt); for "edit" it may be left empty and is then made from object_prompt
    and instruction. views: number of azimuths sampled around the object (24; 72 for "generate").
    """

    mode_type: str = "scene"
    prompt: str = ""
    negative_prompt: str = ""
    object_prompt: str = ""
    instruction: str = ""
    critic: CriticConfig = field(default_factory=CriticConfig)
    global_critic_type: str = "sds"
    views_type: str = "local+global"
    models: ModelConfig = field(default_factory=ModelConfig)
    iterations: int = 4000
    stages: tuple[StageSpec, ...] = PAPER_STAGES
    model_resolution: int = 512
    lr_texture: float = 1e-3
    lr_lora: float = 1e-4
    lora_rank: int = 4
    condition_dropout: float = 0.1
    views: int = 24
    elevation: float = 15.0
    elevation_choices: tuple[float, ...] = ()     # "generate": (20, 30, 45) with small perturbations
    fov_range: tuple[float, float] = (1.0, 1.21)
    background_random_p: float = 0.5
    global_crops: int = 1                         # crops scored per iteration
    light_type: str = "ambient"
    ambient: float = 1.0
    light_random_p: float = 0.0                   # "random": chance of a spherical-Gaussian light
    normal_weight_type: str = "cosine"
    timestep_anneal_type: str = "linear"
    max_depth: int = 3
    texture_preset: str = "balanced"              # "generate": the fresh texture's size preset
    seed: int = 0
    preview_every: int = 50
    checkpoint_every: int = 200

    def __post_init__(self) -> None:
        def need(ok: bool, message: str) -> None:
            if not ok:
                raise InputError(f"Adapt settings: {message}")

        need(self.mode_type in MODE_TYPES, f"mode_type must be one of {MODE_TYPES}, got {self.mode_type!r}.")
        need(self.views_type in VIEWS_TYPES, f"views_type must be one of {VIEWS_TYPES}, got {self.views_type!r}.")
        need(self.light_type in LIGHT_TYPES, f"light_type must be one of {LIGHT_TYPES}, got {self.light_type!r}.")
        need(self.global_critic_type == "sds",
             "global_critic_type must be 'sds' (a LoRA ε_ψ for the inpainting model is not implemented).")
        need(self.timestep_anneal_type in ANNEAL_TYPES, f"timestep_anneal_type must be one of {ANNEAL_TYPES}.")
        need(self.normal_weight_type in NORMAL_WEIGHT_TYPES, f"normal_weight_type must be one of {NORMAL_WEIGHT_TYPES}.")
        if self.mode_type == "edit":
            need(bool(self.prompt.strip()) or (bool(self.object_prompt.strip()) and bool(self.instruction.strip())),
                 "mode 'edit' needs a prompt, or an object prompt and an instruction.")
        else:
            need(bool(self.prompt.strip()), f"mode '{self.mode_type}' needs a prompt describing the appearance.")
        need(self.mode_type == "scene" or self.views_type == "local",
             f"mode '{self.mode_type}' has no photo; use views_type 'local'.")
        need(self.iterations >= 1, f"iterations must be at least 1, got {self.iterations}.")
        stages = tuple(s if isinstance(s, StageSpec) else StageSpec(*s) for s in self.stages)
        object.__setattr__(self, "stages", stages)
        need(len(stages) >= 1 and abs(sum(s.fraction for s in stages) - 1.0) < 1e-6,
             f"stage fractions must add up to 1, got {[s.fraction for s in stages]}.")
        need(self.model_resolution >= 8 and self.model_resolution % 8 == 0,
             f"model_resolution must be a multiple of 8, got {self.model_resolution}.")
        need(self.lr_texture > 0 and self.lr_lora > 0, "learning rates must be positive.")
        need(self.lora_rank >= 1, f"lora_rank must be at least 1, got {self.lora_rank}.")
        need(0.0 <= self.condition_dropout <= 1.0, "condition_dropout must be in [0, 1].")
        need(self.views >= 1, f"views must be at least 1, got {self.views}.")
        need(-90.0 < self.elevation < 90.0 and all(-90.0 < e < 90.0 for e in self.elevation_choices),
             "elevations must be strictly between -90 and 90 degrees.")
        lo, hi = self.fov_range
        need(0.0 < lo <= hi, f"fov_range must satisfy 0 < min <= max, got {self.fov_range}.")
        need(0.0 <= self.background_random_p <= 1.0 and 0.0 <= self.light_random_p <= 1.0,
             "probabilities must be in [0, 1].")
        need(self.global_crops >= 1, "global_crops must be at least 1.")
        need(self.ambient > 0, "ambient radiance must be positive.")
        need(self.max_depth >= 2, "max_depth must be at least 2.")
        need(self.preview_every >= 0 and self.checkpoint_every >= 0, "preview/checkpoint intervals must be >= 0.")
        preset(self.texture_preset)

    @property
    def effective_prompt(self) -> str:
        return self.prompt.strip() or edit_prompt(self.object_prompt, self.instruction)

    @property
    def uses_reference(self) -> bool:
        return self.mode_type in ("scene", "edit") and self.critic.reference_type == "inject"

    def to_dict(self) -> dict:
        return asdict(self)


def edit_prompt(object_prompt: str, instruction: str) -> str:
    """The appendix's manual combination: "a leather sofa" + "add dust to the sofa" -> "a leather sofa, with dust to the sofa".

    "add X" becomes "with X"; "make it X" becomes "X"; other instructions are appended as they are.
    """
    obj, ins = object_prompt.strip().rstrip("."), instruction.strip().rstrip(".")
    lower = ins.lower()
    if lower.startswith("add "):
        ins = "with " + ins[4:]
    elif lower.startswith("make it "):
        ins = ins[8:]
    return f"{obj}, {ins}" if obj else ins


# Mode-specific settings from the appendix, applied before the user's own overrides.
MODE_OVERRIDES: dict[str, dict] = {
    "scene": {},
    "generate": {"views": 72, "elevation_choices": (20.0, 30.0, 45.0), "fov_range": (0.6, 1.21),
                 "views_type": "local", "critic": CriticConfig(lambda_end=0.9, reference_type="none")},
    "edit": {"views_type": "local", "stages": (StageSpec(1.0, 512, 128, (500, 990)),),
             "critic": CriticConfig(lambda_end=1.0, reference_type="inject")},
}


def _scale_stages(stages: tuple[StageSpec, ...], size_scale: float, spp_scale: float) -> tuple[StageSpec, ...]:
    return tuple(StageSpec(s.fraction, max(8, int(round(s.render_size * size_scale / 8)) * 8),
                           max(1, int(round(s.spp * spp_scale))), s.t_range) for s in stages)


# final: the paper's numbers. balanced / draft: fewer iterations, smaller renders, fewer samples.
ADAPT_PRESETS: dict[str, dict] = {
    "final": {},
    "balanced": {"iterations": 1500, "size_scale": 0.75, "spp_scale": 0.5},
    "draft": {"iterations": 300, "size_scale": 0.5, "spp_scale": 0.25, "preview_every": 25, "checkpoint_every": 100},
}


def adapt_preset(name: str, mode_type: str = "scene", **overrides) -> AdaptConfig:
    """A named preset for a mode, with fields replaced by `overrides`."""
    if name not in ADAPT_PRESETS:
        raise InputError(f"Unknown adapt preset '{name}'; choose one of {', '.join(ADAPT_PRESETS)}.")
    if mode_type not in MODE_TYPES:
        raise InputError(f"mode_type must be one of {MODE_TYPES}, got {mode_type!r}.")
    values = dict(MODE_OVERRIDES[mode_type])
    spec = dict(ADAPT_PRESETS[name])
    size_scale, spp_scale = spec.pop("size_scale", 1.0), spec.pop("spp_scale", 1.0)
    values["stages"] = _scale_stages(values.get("stages", PAPER_STAGES), size_scale, spp_scale)
    values.update(spec)
    values.update(overrides)
    return AdaptConfig(mode_type=mode_type, **values)


@dataclass
class AdaptInputs:
    """What the stage works on. mesh: normalised (radius 0.5); raster: its UV raster at the texture's
    resolution; texture: the converted neural texture (None only for "generate"); photo: sRGB float
    (H, W, 3) in [0, 1] and placement ("scene"); envmap: (He, 2He, 3) linear ("envmap" light)."""

    mesh: Mesh
    raster: UVRaster
    texture: NeuralTexture | None = None
    photo: np.ndarray | None = None
    placement: Placement | None = None
    envmap: np.ndarray | None = None

    def validate(self, config: AdaptConfig) -> None:
        if config.mode_type != "generate" and self.texture is None:
            raise InputError(f"Mode '{config.mode_type}' adapts an existing texture; convert the asset first.")
        if config.views_type == "local+global":
            if self.photo is None or self.placement is None:
                raise InputError("Scene-conditional adaptation needs the photo and where the object goes in it.")
            photo = np.asarray(self.photo)
            if photo.ndim != 3 or photo.shape[2] != 3 or min(photo.shape[:2]) < 8:
                raise InputError(f"The photo must be an RGB image of at least 8x8 pixels, got {photo.shape}.")
        if config.light_type == "envmap" and self.envmap is None:
            raise InputError("light_type 'envmap' needs an environment map (e.g. the estimated HDR map).")
        if self.texture is not None and self.texture.config.resolution != self.raster.resolution[0]:
            raise InputError(f"The texture is {self.texture.config.resolution}² but the UV raster is "
                             f"{self.raster.resolution[0]}²; rasterise at the texture's resolution.")


@dataclass
class AdaptResult:
    texture: NeuralTexture
    iterations: int
    seconds: float
    history: list[dict]
    timings: dict[str, float]           # seconds summed over the iterations run here, per phase
    resumed_from: int = 0
    decisions: dict = field(default_factory=dict)
    peak_memory_mb: float | None = None

    def seconds_per_iteration(self) -> dict[str, float]:
        n = max(1, self.iterations - self.resumed_from)
        return {k: v / n for k, v in self.timings.items()}


# -- lights ----------------------------------------------------------------------------------------

def spherical_gaussian_environment(light: tuple[float, float, float, float, float], height: int = 32) -> np.ndarray:
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


def _sample_light(config: AdaptConfig, rng: np.random.Generator, envmap: np.ndarray | None, height: int):
    """(envmap, light vector) for this iteration."""
    if config.light_type == "envmap":
        mean = float(np.mean(envmap))
        return envmap, (AMBIENT_LIGHT[0], AMBIENT_LIGHT[1], 0.0, mean, mean)
    if config.light_type == "random" and rng.uniform() < config.light_random_p:
        light = (float(rng.uniform(0.0, 1.0)), float(rng.uniform(0.0, 0.5)), 0.08, float(rng.uniform(12.0, 15.0)), 0.8)
        return spherical_gaussian_environment(light, height), light
    a = config.ambient
    return None, (AMBIENT_LIGHT[0], AMBIENT_LIGHT[1], 0.0, a, a)


def view_suffix(azimuth_deg: float) -> str:
    """View-dependent prompting (DreamFusion): front within 45 degrees of azimuth 0, back within 45 of 180."""
    a = (azimuth_deg + 180.0) % 360.0 - 180.0
    return "front view" if abs(a) <= 45.0 else "back view" if abs(a) >= 135.0 else "side view"


# -- distributed -------------------------------------------------------------------------------------

def _rank_world() -> tuple[int, int]:
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def _average_gradients(params) -> None:
    """Mean of each parameter's gradient over the ranks (views are spread one per rank)."""
    import torch.distributed as dist

    if not (dist.is_available() and dist.is_initialized()):
        return
    world = dist.get_world_size()
    for p in params:
        if p.grad is None:
            p.grad = torch.zeros_like(p)
        dist.all_reduce(p.grad, op=dist.ReduceOp.SUM)
        p.grad /= world


def init_distributed(backend: str | None = None) -> tuple[int, int]:
    """Join the process group described by torchrun's environment (RANK, WORLD_SIZE, MASTER_ADDR...).

    nccl on CUDA, gloo otherwise; each rank uses GPU `LOCAL_RANK`. Returns (rank, world size).
    """
    import os

    import torch.distributed as dist

    if not dist.is_initialized():
        backend = backend or ("nccl" if torch.cuda.is_available() else "gloo")
        dist.init_process_group(backend)
        if torch.cuda.is_available():
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", 0)))
    return dist.get_rank(), dist.get_world_size()


# -- checkpoints ---------------------------------------------------------------------------------------

def _settings_key(config: AdaptConfig) -> dict:
    d = config.to_dict()
    for name in RESUMABLE_FIELDS:
        d.pop(name, None)
    return d


def save_checkpoint(path: Path, iteration: int, config: AdaptConfig, texture: NeuralTexture, optimizer,
                    lora: LoraCritic | None, history: list[dict]) -> Path:
    payload = {
        "format": CHECKPOINT_FORMAT, "iteration": iteration, "settings": _settings_key(config),
        "texture_config": texture.config.to_dict(),
        "texture": {k: v.detach().cpu() for k, v in texture.state_dict().items()},
        "optimizer": optimizer.state_dict(), "lora": None if lora is None else lora.state_dict(),
        "history": history,
    }
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return write_bytes_atomic(path, buffer.getvalue())


def _load_checkpoint(path: Path, config: AdaptConfig) -> dict | None:
    if not path.is_file():
        return None
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as error:
        raise InputError(f"The checkpoint '{path}' cannot be read ({torch_load_reason(error)}); delete it to start "
                         "over.") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise InputError(f"'{path}' is not a SceneFit adapt checkpoint; delete it to start over.")
    if payload["settings"] != _settings_key(config):
        theirs, ours = payload["settings"], _settings_key(config)
        differ = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
        raise InputError(f"The checkpoint '{path}' was made with other settings ({', '.join(differ)}); "
                         f"use the same settings to resume, or delete it to start over.")
    return payload


# -- the stage ----------------------------------------------------------------------------------------

def stage_at(config: AdaptConfig, iteration: int) -> StageSpec:
    edge = 0.0
    for stage in config.stages:
        edge += stage.fraction
        if iteration < round(edge * config.iterations):
            return stage
    return config.stages[-1]


def sample_camera(config: AdaptConfig, rng: np.random.Generator, size: int) -> Camera:
    """One of `views` evenly spaced azimuths, the user's elevation (or one of the choices, perturbed),
    and λ_FOV uniform in fov_range."""
    azimuth = 360.0 * int(rng.integers(config.views)) / config.views
    if config.elevation_choices:
        elevation = float(config.elevation_choices[int(rng.integers(len(config.elevation_choices)))])
        elevation = float(np.clip(elevation + rng.uniform(-5.0, 5.0), -89.0, 89.0))
    else:
        elevation = config.elevation
    fov = float(rng.uniform(*config.fov_range))
    return Camera(azimuth, elevation, fov, width=size, height=size)


class _Timer:
    def __init__(self, device) -> None:
        self.totals: dict[str, float] = {}
        self.cuda = getattr(device, "type", "") == "cuda"

    def add(self, name: str, start: float) -> float:
        if self.cuda:
            torch.cuda.synchronize()
        now = time.perf_counter()
        self.totals[name] = self.totals.get(name, 0.0) + now - start
        return now


def _encode(models: GuidanceModels, images: torch.Tensor) -> torch.Tensor:
    """SD latents (float32) of sRGB images in [0, 1]: the posterior mean, scaled."""
    x = (images * 2.0 - 1.0).to(models.device, models.vae.dtype)
    return models.vae.encode(x).latent_dist.mean.float() * models.latent_scale


def adapt_texture(inputs: AdaptInputs, config: AdaptConfig, progress: ProgressCallback | None = None,
                  cancel: threading.Event | None = None, checkpoint_dir: str | Path | None = None,
                  models: GuidanceModels | None = None) -> AdaptResult:
    """Run the adapt stage; returns a new NeuralTexture (the input texture is left as it was).

    Models are located (and a missing one reported) before any work. With `checkpoint_dir`, a
    checkpoint is written every `checkpoint_every` iterations and a run with the same settings
    resumes from it.
    """
    started = time.perf_counter()
    inputs.validate(config)
    need_inpaint = config.views_type == "local+global"
    if models is None:
        paths = locate_models(config.models, need_inpaint)   # fails here, before any work
        models = load_guidance_models(config.models, need_inpaint, paths)
    elif need_inpaint and models.inpaint_unet is None:
        raise InputError("Global views need the inpainting model; load the models with need_inpaint=True.")
    rank, world = _rank_world()
    device = models.device

    # Text embeddings once per prompt; the text encoder is released afterwards.
    prompt = config.effective_prompt
    prompts = ([f"{prompt}, {v}" for v in ("front view", "side view", "back view")]
               if config.mode_type == "generate" else [prompt])
    for p in prompts + [config.negative_prompt]:
        models.embed(p)
    models.release_text_encoder()
    uncond = models.embed(config.negative_prompt)

    # The texture being adapted (a copy) and the frozen reference texture.
    resolution = inputs.raster.resolution[0]
    if inputs.texture is None:
        texture = NeuralTexture(preset(config.texture_preset, resolution=resolution), seed=config.seed)
    else:
        texture = NeuralTexture(inputs.texture.config, seed=None)
        texture.load_state_dict(inputs.texture.state_dict())
    texture = texture.to(device)
    raster = inputs.raster
    plan = texture.plan(raster.position, raster.border, raster.fill_index)
    reference_stack = None
    if config.uses_reference:
        with torch.no_grad():
            reference_stack = texture.texture_from_plan(plan).detach()

    base_env = inputs.envmap if config.light_type == "envmap" else np.full((16, 32, 3), config.ambient, np.float32)
    renderer = AssetRenderer(inputs.mesh, (resolution, resolution), np.asarray(base_env, np.float32),
                             SceneOptions(max_depth=config.max_depth, hide_emitters=True))
    base_env_t = torch.from_numpy(np.ascontiguousarray(base_env, np.float32))

    optimizer = torch.optim.Adam(texture.parameters(), lr=config.lr_texture)
    lora = None
    if config.critic.critic_type == "vsd":
        lora = LoraCritic(models.unet, rank=config.lora_rank, lr=config.lr_lora,
                          condition_dropout=config.condition_dropout, seed=config.seed)
    injector = ReferenceInjector(models.unet, config.critic.injection_fraction) if config.uses_reference else None
    local_critic = ScoreCritic(models.unet, models.scheduler, config.critic, lora=lora, injector=injector)
    global_critic = None
    if need_inpaint:
        global_critic = ScoreCritic(models.inpaint_unet, models.scheduler,
                                    replace(config.critic, critic_type="sds", reference_type="none"))
    alpha_bar = local_critic.alpha_bar
    latent_res = config.model_resolution // models.vae_scale_factor

    # Resume.
    checkpoint_path = Path(checkpoint_dir) / CHECKPOINT_FILE if checkpoint_dir is not None else None
    history: list[dict] = []
    start = 0
    payload = _load_checkpoint(checkpoint_path, config) if checkpoint_path is not None else None
    if payload is not None:
        texture.load_state_dict(payload["texture"])
        optimizer.load_state_dict(payload["optimizer"])
        if lora is not None and payload["lora"] is not None:
            lora.load_state_dict(payload["lora"])
        history, start = list(payload["history"]), int(payload["iteration"])

    timer = _Timer(device)
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats()
    photo = None if inputs.photo is None else np.clip(np.asarray(inputs.photo, np.float32), 0.0, 1.0)
    iteration = start
    for iteration in range(start, config.iterations):
        check_cancel(cancel)
        progress_fraction = iteration / max(1, config.iterations - 1)
        rng = np.random.default_rng([config.seed, iteration, rank])
        gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
        stage = stage_at(config, iteration)
        camera = sample_camera(config, rng, stage.render_size)
        env_np, light = _sample_light(config, rng, inputs.envmap, base_env.shape[0])
        env_t = base_env_t if env_np is None or env_np is inputs.envmap else torch.from_numpy(env_np)
        bg = background_color(rng, config.background_random_p)
        t = sample_timestep(rng, stage.t_range, progress_fraction, config.timestep_anneal_type)
        noise = torch.randn(1, 4, latent_res, latent_res, generator=gen).to(device)
        lam = interpolation_lambda(progress_fraction, config.critic.lambda_end, config.critic.critic_type)
        condition = camera_condition(camera.origin, camera.forward, light)
        text = models.embed(f"{prompt}, {view_suffix(camera.azimuth_deg)}" if config.mode_type == "generate" else prompt)
        render_seed = int(rng.integers(2**31 - 2**16))
        metrics: dict = {"t": t, "lambda": round(lam, 4), "stage_size": stage.render_size}

        # Render, without gradients, the reference and the normals, then the texture (differentiable;
        # last, so the scene holds its maps when the backward pass replays the paths).
        t0 = time.perf_counter()
        reference_view = None
        if reference_stack is not None:
            with torch.no_grad():
                ref = renderer.render(camera, reference_stack[..., 0:3], reference_stack[..., 3:4],
                                      reference_stack[..., 4:5], env_t, spp=stage.spp, seed=render_seed)
                reference_view = local_view(ref.rgb, ref.alpha, bg, config.model_resolution)
        weight_map = None
        if config.normal_weight_type != "none":
            aov = renderer.render_aovs(camera)
            weight_map = normal_weight_map(aov["normal"], aov["coverage"], camera.forward, (latent_res, latent_res),
                                           weight_type=config.normal_weight_type).to(device)
        stack = texture.texture_from_plan(plan)
        out = renderer.render(camera, stack[..., 0:3], stack[..., 3:4], stack[..., 4:5], env_t, spp=stage.spp,
                              seed=render_seed)
        rendered = torch.cat([out.rgb, out.alpha], dim=-1)
        t0 = timer.add("render", t0)

        # Views -> latents (gradients stop at `leaf`, so the two halves of backward can be timed).
        leaf = rendered.detach().to(device).requires_grad_(True)
        rgb, alpha = leaf[..., 0:3], leaf[..., 3:4]
        image = local_view(rgb, alpha, bg, config.model_resolution)
        latents = _encode(models, image)
        reference_latents = None
        if reference_view is not None:
            with torch.no_grad():
                reference_latents = _encode(models, reference_view.to(device))
        global_inputs = []
        if global_critic is not None:
            for crop in sample_crops(photo.shape[:2], inputs.placement, config.global_crops, rng):
                g_image, g_alpha = global_view(rgb, alpha, photo, inputs.placement, crop, config.model_resolution)
                g_latents = _encode(models, g_image)
                with torch.no_grad():
                    masked_latents = _encode(models, masked_image(g_image, g_alpha))
                global_inputs.append((g_latents, latent_mask(g_alpha, (latent_res, latent_res)), masked_latents))
        t0 = timer.add("vae", t0)

        # Critics: ∇z = w_t w_n (ε_φ - ε̂), local and global weighed equally.
        local = local_critic(latents, t, noise, text, uncond, lam=lam, condition=condition,
                             reference_latents=reference_latents, weight_map=weight_map)
        metrics.update({"local_grad_norm": local.metrics["grad_norm"], "nonfinite": local.metrics["nonfinite"]})
        global_losses = []
        for g_latents, mask, masked_latents in global_inputs:
            g = global_critic(g_latents, t, noise, text, uncond, extra=(mask, masked_latents))
            global_losses.append(g.loss)
            metrics["global_grad_norm"] = g.metrics["grad_norm"]
            metrics["nonfinite"] += g.metrics["nonfinite"]
        if global_losses:
            total = 0.5 * local.loss + 0.5 * torch.stack(global_losses).mean()
        else:
            total = local.loss
        t0 = timer.add("unet", t0)

        # Backward: through the VAE to the rendered pixels, then through Mitsuba to the texture.
        optimizer.zero_grad(set_to_none=True)
        total.backward()
        t0 = timer.add("vae_backward", t0)
        pixel_grad = torch.nan_to_num(leaf.grad, nan=0.0, posinf=0.0, neginf=0.0).to(rendered.device)
        rendered.backward(pixel_grad)
        for p in texture.parameters():
            if p.grad is not None:
                p.grad.nan_to_num_(0.0, 0.0, 0.0)
        _average_gradients(texture.parameters())
        optimizer.step()
        t0 = timer.add("render_backward_and_step", t0)

        # ε_ψ learns the current renderings (one LoRA step on the detached local latents).
        if lora is not None:
            t_lora = int(rng.integers(0, local_critic.num_train_timesteps))
            lora_noise = torch.randn(latents.shape, generator=gen).to(device)
            drop = bool(rng.uniform() < config.condition_dropout)
            metrics["lora_loss"] = lora.train_step(latents, text, condition, t_lora, lora_noise,
                                                   float(alpha_bar[t_lora]), drop, local_critic.prediction_type)
            _average_gradients(lora.parameters())
            lora.step()
            t0 = timer.add("lora", t0)

        history.append({k: (round(v, 6) if isinstance(v, float) else v) for k, v in metrics.items()})
        done = iteration + 1
        if rank == 0:
            preview = None
            if config.preview_every and (done % config.preview_every == 0 or done == config.iterations):
                preview = (image.detach()[0].permute(1, 2, 0).clamp(0, 1).cpu().numpy() * 255).round().astype(np.uint8)
            emit(progress, "adapt", done, config.iterations,
                 f"{config.mode_type}: stage {stage.render_size}px, t={t}", metrics, preview)
            if checkpoint_path is not None and config.checkpoint_every and (
                    done % config.checkpoint_every == 0 or done == config.iterations):
                save_checkpoint(checkpoint_path, done, config, texture, optimizer, lora, history)

    peak = None
    if device.type == "cuda":
        peak = torch.cuda.max_memory_allocated() / 2**20
    else:
        try:
            import resource

            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        except Exception:
            peak = None
    decisions = {"mode": config.mode_type, "prompt": prompt, "critic": config.critic.critic_type,
                 "views": config.views_type, "reference_injection": config.uses_reference,
                 "injected_layers": 0 if injector is None else len(injector.injected),
                 "models": {k: str(v) for k, v in models.paths.items()}, "world_size": world,
                 "device": str(device), "dtype": str(models.dtype).replace("torch.", "")}
    return AdaptResult(texture=texture, iterations=config.iterations, seconds=time.perf_counter() - started,
                       history=history, timings=timer.totals, resumed_from=start, decisions=decisions,
                       peak_memory_mb=peak)


def adapt_and_bake(mesh: Mesh, texture: NeuralTexture | None, config: AdaptConfig, out_dir: str | Path,
                   photo: np.ndarray | None = None, placement: Placement | None = None,
                   envmap: np.ndarray | None = None, resolution: int | None = None,
                   progress: ProgressCallback | None = None, cancel: threading.Event | None = None,
                   models: GuidanceModels | None = None) -> tuple[AdaptResult, dict]:
    """Adapt (or, for "generate", make) the asset's texture and bake it into out_dir/maps.

    mesh is the asset as given (normalised here); checkpoints go to out_dir/checkpoint so that
    running the same command again resumes. Returns the result and a report dict.
    """
    from .mesh import normalize_to_unit_sphere
    from .texture.bake import bake_maps
    from .texture.uv_raster import rasterize_uv

    out_dir = Path(out_dir)
    if models is None:  # missing weights stop the run here, before any work
        models = load_guidance_models(config.models, config.views_type == "local+global")
    normalized, _ = normalize_to_unit_sphere(mesh)
    res = texture.config.resolution if texture is not None else int(resolution or preset(config.texture_preset).resolution)
    raster = rasterize_uv(normalized, res)
    inputs = AdaptInputs(mesh=normalized, raster=raster, texture=texture, photo=photo, placement=placement,
                         envmap=envmap)
    result = adapt_texture(inputs, config, progress=progress, cancel=cancel, checkpoint_dir=out_dir / "checkpoint",
                           models=models)
    check_cancel(cancel)
    paths = bake_maps(result.texture, raster.position, raster.border, raster.fill_index, out_dir / "maps")
    per_it = result.seconds_per_iteration()
    report = {
        "stage": "adapt", "config": config.to_dict(), "decisions": result.decisions,
        "iterations": result.iterations, "resumed_from": result.resumed_from, "seconds": round(result.seconds, 3),
        "seconds_per_iteration": {k: round(v, 4) for k, v in per_it.items()},
        "peak_memory_mb": None if result.peak_memory_mb is None else round(result.peak_memory_mb, 1),
        "last_metrics": result.history[-1] if result.history else {},
        "outputs": {k: str(v) for k, v in paths.items()},
    }
    return result, report
