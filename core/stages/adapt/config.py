"""The adapt stage's settings: one frozen dataclass whose defaults are the paper's complete setup (m).

Where a value comes from (appendix "Texture Adaptation" and "Scene-Agnostic Texture Generation"):
- scene / edit: 512 px renders, 128 spp, t in [500, 990] for all 4000 iterations, annealed from
  high to low noise; constant lr 1e-3 (texture MLP) and 1e-4 (LoRA); 4 views per step (the
  paper's 4 GPUs, one view each); 24 azimuths at the user's elevation; λ_FOV in [1.0, 1.21].
- generate: the coarse-to-fine schedule (20% at 256 px, 64 spp, t in [30, 990]; then 512 px,
  128 spp, t in [500, 990]); 72 views over elevations {20, 30, 45}; λ_FOV in [0.6, 1.21].
The paper does not say how many global-view crops it scores per view; we take 2 (docs/engineers/method.md).
"""
from __future__ import annotations

import math

from dataclasses import asdict, dataclass, field

from ...base.limits import check_render_size
from ...base.names import MODES, SHADOW_TYPES
from ...base.errors import InputError
from ...guidance.critic_config import ANNEAL_TYPES, NORMAL_WEIGHT_TYPES, CriticConfig
from ...guidance.models import ModelConfig
from ...render.renderer import RENDERER_TYPES
from ...texture.texture_config import BALANCED_TEXTURE, NeuralTextureConfig

MODE_TYPES = MODES   # (core/base/names.py)
VIEWS_TYPES = ("local+global", "local")
LIGHT_TYPES = ("ambient", "envmap", "random")
ADAPT_RENDERERS = ("auto", *RENDERER_TYPES)
# Where the loop renderer agrees with path tracing to >= 35 dB on every corpus view measured
# (benchmarks/results/loop_render.md, 256 px, path at 256 spp, views held out from the G-buffer's tuning):
# the local views' constant ambient light 38.3-42.0 dB, the global views' HDR map 42.3-45.8 dB (8 views each).
# Before each sample read the texture on its own (16 per pixel, not 4) ambient was 34.2-38.6: path traced.
LOOP_AGREES = {"local": True, "global": True}
# The diffusion model's image side at most: SD2 works at 512 (768 for its v-model); twice that is already
# four times the memory per image.
MAX_MODEL_RESOLUTION = 2048


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class StageSpec:
    """One stage of the schedule: its share of the iterations, render size, samples per pixel, t range."""

    fraction: float
    render_size: int
    spp: int
    t_range: tuple[int, int]

    def __post_init__(self) -> None:
        if not _number(self.fraction) or not 0.0 < self.fraction <= 1.0:
            raise InputError(f"A stage's fraction must be in (0, 1], got {self.fraction!r}.")
        if not _whole(self.render_size) or not _whole(self.spp) or self.render_size < 8 or not 1 <= self.spp <= 65536:
            raise InputError(f"A stage needs a whole render_size >= 8 and a whole spp from 1 to 65536, got "
                             f"{self.render_size!r}, {self.spp!r}.")
        check_render_size(self.render_size, self.render_size, "a stage's render_size")
        if not isinstance(self.t_range, (tuple, list)) or len(self.t_range) != 2 or \
                not all(_whole(t) for t in self.t_range):
            raise InputError(f"A stage's timestep range must be two whole numbers, got {self.t_range!r}.")
        lo, hi = self.t_range
        if not 0 <= lo <= hi <= 999:
            raise InputError(f"A stage's timestep range must satisfy 0 <= lo <= hi <= 999, got {self.t_range}.")
        object.__setattr__(self, "t_range", (int(lo), int(hi)))


# Setup (m) and editing (c): one stage, 512 px, 128 spp, t in [500, 990] throughout.
SCENE_STAGES = (StageSpec(1.0, 512, 128, (500, 990)),)
# Setup (a), scene-agnostic generation: coarse 20% then fine 80%.
GENERATE_STAGES = (StageSpec(0.2, 256, 64, (30, 990)), StageSpec(0.8, 512, 128, (500, 990)))


@dataclass(frozen=True)
class AdaptConfig:
    """Settings of the adapt stage; defaults are the paper's setup (m) (core/pipeline/presets.py has faster ones).

    prompt: the appearance description the critics are conditioned on (the paper's GPT-written,
    scene-conditional prompt); for "edit" it may be left empty and is then made from object_prompt
    and instruction. views: number of azimuths sampled around the object (24; 72 for "generate").
    views_per_step: views whose gradients are averaged in one step (spread over the ranks of
    torch.distributed when there are several; on one device rendered in turn and, where the renders
    can wait for one backward (the loop renderer's), scored in one batch per model: AdaptSystem.train_views).
    global_crops: global views (crops of the photo at several scales) scored per view.
    view_variants: scene and edit modes draw from a fixed bank of views x view_variants views (each
    with its λ_FOV, background and crops), so what depends only on a view is computed once.
    shadow_type / shadow_spp: the global views' shadow, made by the compose stage's floor passes.
    renderer: "loop" (G-buffers traced once per view, shaded in torch: core/render/loop_renderer.py),
    "path" (the paper's differentiable path tracing, Mitsuba `prb`, every step), or "auto": the loop
    renderer for the views whose light it was measured to agree with path tracing on to >= 35 dB on the
    corpus (LOOP_AGREES), path tracing for the others.
    batch_views: a step's views through the VAE, each critic's UNet and ε_ψ's update in one pass per
    model where their renders can wait for one backward (the loop renderer's): the same gradients to
    float rounding, fewer passes, more memory (every image's encoder graph at once). False: one image
    at a time, the least memory (a run may resume with either).
    """

    mode_type: str = "scene"                      # scene (setup m) | generate (a) | edit (c)
    prompt: str = ""
    negative_prompt: str = ""                     # what the critics are steered away from
    object_prompt: str = ""                       # the object alone (local views; edit: with the instruction)
    instruction: str = ""                         # edit: what to change, verb first
    critic: CriticConfig = field(default_factory=CriticConfig)   # the score-distillation critic (VSD, guidance scale)
    views_type: str = "local+global"              # local+global (the paper's) | local (solid backgrounds only)
    models: ModelConfig = field(default_factory=ModelConfig)     # the SD2 models (core/guidance/models.py)
    iterations: int = 4000                        # optimisation steps
    stages: tuple[StageSpec, ...] = SCENE_STAGES  # the schedule: fraction, render size, spp, timestep range
    model_resolution: int = 0                     # the diffusion model's image side (0: its own config's)
    lr_texture: float = 1e-3                      # the texture's learning rate (constant)
    lr_lora: float = 1e-4                         # the LoRA noise predictor's learning rate (constant)
    lora_rank: int = 4                            # the LoRA adapter's rank
    condition_dropout: float = 0.1                # how often the LoRA's camera condition is zeroed in training
    views: int = 24
    views_per_step: int = 4
    view_variants: int = 2                        # fixed views per azimuth (sampling.draw_view_bank)
    elevation: float = 15.0                       # degrees above the horizon the views look from
    elevation_choices: tuple[float, ...] = ()     # "generate": (20, 30, 45) with small perturbations
    fov_range: tuple[float, float] = (1.0, 1.21)  # λ_FOV drawn from this range (docs: conventions)
    background_random_p: float = 0.5             # local views: chance of a random solid background, else grey
    global_crops: int = 2
    shadow_type: str = "ratio"                    # the global views' shadow (core/stages/compose.py SHADOW_TYPES)
    shadow_spp: int = 32                          # samples per pixel of its floor passes (once per turn)
    light_type: str = "ambient"                   # ambient | envmap | random: the local views' light
    ambient: float = 1.0                          # the ambient light's radiance
    light_random_p: float = 0.0                   # "random": chance of a spherical-Gaussian light
    normal_weight_type: str = "cosine"            # w_t weighted by ⟨camera, normal⟩ (cosine) or not
    timestep_anneal_type: str = "linear"          # how the timestep window slides from high to low
    max_depth: int = 3                            # light bounces per path in the renders
    renderer: str = "auto"                        # "auto" | "loop" | "path" (ADAPT_RENDERERS)
    batch_views: bool = True                      # a step's images through each model in one pass (False: one at a time)
    texture: NeuralTextureConfig = BALANCED_TEXTURE   # "generate": the fresh texture (resolution: the raster's)
    seed: int = 0                                 # the views, timesteps and noise (the same on one device or four)
    preview_every: int = 50                       # iterations between previews
    checkpoint_every: int = 200                   # iterations between checkpoints (a stopped run resumes)

    def __post_init__(self) -> None:
        def need(ok: bool, message: str) -> None:
            if not ok:
                raise InputError(f"Adapt settings: {message}")

        need(self.mode_type in MODE_TYPES, f"mode_type must be one of {MODE_TYPES}, got {self.mode_type!r}.")
        need(self.views_type in VIEWS_TYPES, f"views_type must be one of {VIEWS_TYPES}, got {self.views_type!r}.")
        need(self.light_type in LIGHT_TYPES, f"light_type must be one of {LIGHT_TYPES}, got {self.light_type!r}.")
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
        need(isinstance(self.batch_views, bool), f"batch_views must be true or false, got {self.batch_views!r}.")
        stages = tuple(s if isinstance(s, StageSpec) else StageSpec(*s) for s in self.stages)
        object.__setattr__(self, "stages", stages)
        need(len(stages) >= 1 and abs(sum(s.fraction for s in stages) - 1.0) < 1e-6,
             f"stage fractions must add up to 1, got {[s.fraction for s in stages]}.")
        need(self.model_resolution == 0 or (8 <= self.model_resolution <= MAX_MODEL_RESOLUTION
                                            and self.model_resolution % 8 == 0),
             f"model_resolution must be 0 (the model's own) or a multiple of 8 from 8 to {MAX_MODEL_RESOLUTION}, "
             f"got {self.model_resolution}.")
        need(self.lr_texture > 0 and self.lr_lora > 0, "learning rates must be positive.")
        need(self.lora_rank >= 1, f"lora_rank must be at least 1, got {self.lora_rank}.")
        need(0.0 <= self.condition_dropout <= 1.0, "condition_dropout must be in [0, 1].")
        need(self.views >= 1, f"views must be at least 1, got {self.views}.")
        need(self.view_variants >= 1, f"view_variants must be at least 1, got {self.view_variants}.")
        need(self.views_per_step >= 1, f"views_per_step must be at least 1, got {self.views_per_step}.")
        need(-90.0 < self.elevation < 90.0 and all(-90.0 < e < 90.0 for e in self.elevation_choices),
             "elevations must be strictly between -90 and 90 degrees.")
        lo, hi = self.fov_range
        need(0.0 < lo <= hi, f"fov_range must satisfy 0 < min <= max, got {self.fov_range}.")
        need(0.0 <= self.background_random_p <= 1.0 and 0.0 <= self.light_random_p <= 1.0,
             "probabilities must be in [0, 1].")
        need(self.global_crops >= 1, "global_crops must be at least 1.")
        need(self.shadow_type in SHADOW_TYPES, f"shadow_type must be one of {SHADOW_TYPES}, got {self.shadow_type!r}.")
        need(self.shadow_spp >= 1, f"shadow_spp must be at least 1, got {self.shadow_spp}.")
        need(self.ambient > 0, "ambient radiance must be positive.")
        need(self.max_depth >= 2, "max_depth must be at least 2.")
        need(self.renderer in ADAPT_RENDERERS, f"renderer must be one of {ADAPT_RENDERERS}, got {self.renderer!r}.")
        need(self.preview_every >= 0 and self.checkpoint_every >= 0, "preview/checkpoint intervals must be >= 0.")
        need(isinstance(self.texture, NeuralTextureConfig),
             f"texture must be a NeuralTextureConfig, got {type(self.texture).__name__}.")

    @property
    def effective_prompt(self) -> str:
        return self.prompt.strip() or edit_prompt(self.object_prompt, self.instruction)

    @property
    def uses_reference(self) -> bool:
        return self.mode_type in ("scene", "edit") and self.critic.reference_type == "inject"

    def renderer_of(self, views: str) -> str:
        """The renderer of the "local" or "global" views: the one asked for, or under "auto" the loop
        renderer where it was measured to agree (LOOP_AGREES)."""
        if self.renderer != "auto":
            return self.renderer
        return "loop" if LOOP_AGREES[views] else "path"

    def to_dict(self) -> dict:
        return asdict(self)

    def schedule(self) -> list[dict]:
        """Per stage, what one step of it does (what `scenefit adapt --dry-run` shows)."""
        return [{"fraction": s.fraction, "iterations": stage_iterations(self, i), "t_range": list(s.t_range),
                 "t_anneal": self.timestep_anneal_type, "render_size": s.render_size, "spp": s.spp,
                 "views_per_step": self.views_per_step,
                 "global_crops": self.global_crops if self.views_type == "local+global" else 0}
                for i, s in enumerate(self.stages)]


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


# Mode-specific settings from the appendix, applied before a preset's and the user's overrides.
MODE_SETTINGS: dict[str, dict] = {
    "scene": {},
    "generate": {"views": 72, "elevation_choices": (20.0, 30.0, 45.0), "fov_range": (0.6, 1.21),
                 "views_type": "local", "stages": GENERATE_STAGES,
                 "critic": CriticConfig(lambda_end=0.9, reference_type="none")},
    "edit": {"views_type": "local", "critic": CriticConfig(lambda_end=1.0, reference_type="inject")},
}


def stage_bounds(config: AdaptConfig) -> list[int]:
    """The first iteration of each stage, then `iterations`."""
    edges, edge = [0], 0.0
    for stage in config.stages:
        edge += stage.fraction
        edges.append(min(config.iterations, round(edge * config.iterations)))
    edges[-1] = config.iterations
    return edges


def stage_iterations(config: AdaptConfig, index: int) -> int:
    edges = stage_bounds(config)
    return edges[index + 1] - edges[index]


def stage_at(config: AdaptConfig, iteration: int) -> StageSpec:
    edges = stage_bounds(config)
    for stage, end in zip(config.stages, edges[1:]):
        if iteration < end:
            return stage
    return config.stages[-1]
