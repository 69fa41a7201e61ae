"""The light stage's settings (LightConfig and the settings it holds: the critic's apparatus and optimisation,
the diffusion critic, the outdoor completion): data a preset resolves and a run keys, without torch (the
modules beside it compute with them)."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...base.errors import InputError, check_choice
from ...base.names import SCENE_TYPES as NAMED_SCENE_TYPES
from ...guidance.models import ModelConfig
from .cues import CueConfig
from .depth import DepthConfig
from .regions import RegionThresholds

DEFAULT_L_WHITE = 64.0
VIEWS_TYPES = ("composited", "apparatus")
COMPLETION_TYPES = ("auto", "sd2", "prior")   # auto: SD2 inpainting when on this machine, else the prior
DEFAULT_OUTDOOR_PROMPT = "a 360 degree equirectangular panorama of an outdoor scene, sky, natural daylight"
SCENE_TYPES = NAMED_SCENE_TYPES   # (core/base/names.py)
CRITIC_TYPES = ("none", "reference", "diffusion")
PRIOR_TYPES = ("cues", "inverse_tonemap")   # cues: cues.py (default); inverse_tonemap: the paper's prior


@dataclass(frozen=True)
class ApparatusConfig:
    """Views of the object and of the white diffuse sphere beside it (appendix: 3 object views, 1 sphere).

    Object views look at the object from the photo's direction (azimuth offset 0) and from either side;
    lambda_FOV = 1.65 keeps the full shadow on the floor in view. Weights are the appendix's {1/6,1/6,1/6,1/2}.
    """

    object_azimuths: tuple[float, ...] = (-35.0, 0.0, 35.0)
    elevation_deg: float = 15.0
    fov_multiplier: float = 1.65
    view_weights: tuple[float, ...] = (1 / 6, 1 / 6, 1 / 6, 1 / 2)
    sphere_radius: float = 0.25
    sphere_offset: tuple[float, float] = (0.9, 0.0)   # beside the object, x (right) and y (depth)
    floor: bool = True
    render_size: int = 64
    spp: int = 8
    max_depth: int = 3

    def __post_init__(self) -> None:
        if len(self.view_weights) != len(self.object_azimuths) + 1:
            raise InputError("view_weights needs one weight per object view plus one for the sphere.")
        if any(w < 0 for w in self.view_weights) or sum(self.view_weights) <= 0:
            raise InputError("view_weights must be non-negative with a positive sum.")


@dataclass(frozen=True)
class OptimiseConfig:
    iterations: int = 2000
    lr: float = 0.01
    lr_final_factor: float = 0.1    # linearly annealed to 0.1 x lr
    t_range: tuple[int, int] = (750, 990)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.iterations < 0:
            raise InputError(f"iterations must be >= 0, got {self.iterations}.")
        if not self.lr > 0 or not 0 < self.lr_final_factor <= 1:
            raise InputError("lr must be positive and lr_final_factor in (0, 1].")
        if not 0 <= self.t_range[0] <= self.t_range[1] < 1000:
            raise InputError(f"t_range must lie in [0, 999] and be ordered, got {self.t_range}.")


@dataclass(frozen=True)
class DiffusionCriticConfig:
    """The paper's light-critic settings: VSD with λ = 1, CFG 7.5, LoRA lr 1e-4 annealed to 0.1 x."""

    guidance_scale: float = 7.5
    lambda_vsd: float = 1.0
    lora_rank: int = 4
    lr_lora: float = 1e-4
    lr_lora_final_factor: float = 0.1
    condition_dropout: float = 0.1
    model_resolution: int = 0               # the model's image side (0: its own config's)
    l_white: float = DEFAULT_L_WHITE        # the tone curve applied to renders before encoding
    negative_prompt: str = ""
    views_type: str = "composited"          # the paper's two global views in the photo; "apparatus": the renders
    object_size: float = 0.3                # composited: the object spans this fraction of the photo's height
    shadow_threshold: float = 0.9           # composited: the paper's shadow threshold (x the floor's mean)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.views_type not in VIEWS_TYPES:
            raise InputError(f"views_type must be one of {', '.join(VIEWS_TYPES)}, got {self.views_type!r}.")
        if not 0.0 < self.object_size <= 2.0 or not 0.0 < self.shadow_threshold <= 1.0:
            raise InputError("object_size must be in (0, 2] and shadow_threshold in (0, 1].")
        if self.guidance_scale < 0:
            raise InputError(f"guidance_scale must not be negative, got {self.guidance_scale}.")
        if not 0.0 <= self.lambda_vsd <= 1.0:
            raise InputError(f"lambda_vsd must be in [0, 1], got {self.lambda_vsd}.")
        if self.lora_rank < 1 or not self.lr_lora > 0 or not 0 < self.lr_lora_final_factor <= 1:
            raise InputError("lora_rank must be >= 1, lr_lora positive and lr_lora_final_factor in (0, 1].")
        if not 0.0 <= self.condition_dropout < 1.0:
            raise InputError(f"condition_dropout must be in [0, 1), got {self.condition_dropout}.")
        if self.model_resolution and (self.model_resolution < 8 or self.model_resolution % 8):
            raise InputError(f"model_resolution must be 0 (the model's own) or a multiple of 8 (>= 8), "
                             f"got {self.model_resolution}.")
        if not self.l_white > 1.0:
            raise InputError(f"l_white must be above 1, got {self.l_white}.")


@dataclass(frozen=True)
class OutpaintConfig:
    completion_type: str = "auto"
    prompt: str = DEFAULT_OUTDOOR_PROMPT
    negative_prompt: str = ""
    steps: int = 25
    guidance_scale: float = 7.5
    resolution: int = 512              # working height; the model paints resolution x 2 resolution
    seam_band_fraction: float = 0.125  # width of the band re-painted across the wrap seam (of the map width)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.completion_type not in COMPLETION_TYPES:
            raise InputError(f"completion_type must be one of {', '.join(COMPLETION_TYPES)}, got {self.completion_type!r}.")
        if not 1 <= self.steps <= 1000:
            raise InputError(f"steps must be between 1 and 1000, got {self.steps}.")
        if self.guidance_scale < 0:
            raise InputError(f"guidance_scale must not be negative, got {self.guidance_scale}.")
        if self.resolution < 16 or self.resolution % 16:
            raise InputError(f"resolution must be a multiple of 16 (>= 16), got {self.resolution}.")
        if not 0.0 <= self.seam_band_fraction <= 0.5:
            raise InputError(f"seam_band_fraction must be in [0, 0.5], got {self.seam_band_fraction}.")


@dataclass(frozen=True)
class LightConfig:
    """The light stage's settings. Defaults are the balanced preset's (map size, apparatus renders),
    except the critic's optimisation, which keeps the paper's 2000 iterations at lr 0.01 (it runs only
    with a critic, i.e. with the SD2 weights; core/pipeline/preset_tables.py has shorter ones)."""

    scene_type: str = "auto"
    # (The photo's camera is not a light setting: it is the camera stage's, a PhotoCamera given to estimate_light.)
    # The artist's dominant light (--sun AZ,EL), degrees: azimuth from the photo's view direction,
    # positive to the camera's right (clockwise seen from above), elevation above the horizon.
    sun_deg: tuple[float, float] | None = None
    # How far off that direction may be (degrees): 0 as typed or taken from a Sun light; a shadow's three
    # clicks give their own (shadow_hint.sun_uncertainty_deg). The unseen light's lobe widens with it.
    sun_uncertainty_deg: float = 0.0
    map_height: int = 128                     # the map is map_height x 2 map_height
    depth: DepthConfig = DepthConfig()        # the monocular depth model that lifts an indoor photo to 3D
    thresholds: RegionThresholds = RegionThresholds()   # the paper's bright-region thresholds
    prior_type: str = "cues"                  # cues (weight-free, cues.py) | inverse_tonemap (the paper's prior)
    cues: CueConfig = CueConfig()             # the weight-free cues' settings
    l_white: float = DEFAULT_L_WHITE          # inverse_tonemap: the extended Reinhard white point
    critic_type: str = "none"                 # none | diffusion (SD2, the paper's) | reference (the true map)
    apparatus: ApparatusConfig = ApparatusConfig()   # the critic's renders of the object and sphere
    optimise: OptimiseConfig = OptimiseConfig()      # the critic's optimisation of the region scales
    object_prompt: str = "a 3D object"        # the diffusion critic's words for the object
    tint: str | None = None                   # e.g. "in blue tint", appended to both prompts
    models: ModelConfig = ModelConfig()       # SD2 for critic_type "diffusion" (core/guidance/models.py)
    diffusion: DiffusionCriticConfig = DiffusionCriticConfig()   # the diffusion critic's settings
    outpaint: OutpaintConfig = OutpaintConfig()   # outdoor completion: SD2 inpainting or the sky/ground prior

    def __post_init__(self) -> None:
        check_choice("scene_type", self.scene_type, SCENE_TYPES)
        check_choice("critic_type", self.critic_type, CRITIC_TYPES)
        check_choice("prior_type", self.prior_type, PRIOR_TYPES)
        if self.sun_deg is not None and (len(self.sun_deg) != 2 or not all(map(math.isfinite, self.sun_deg))
                                         or not -90.0 <= self.sun_deg[1] <= 90.0):
            raise InputError(f"The sun direction must be two finite angles AZ,EL with the elevation within +-90 "
                             f"degrees, got {self.sun_deg}; give it as --sun 30,45.")
        if not (math.isfinite(self.sun_uncertainty_deg) and 0.0 <= self.sun_uncertainty_deg <= 180.0):
            raise InputError(f"sun_uncertainty_deg must be within 0 and 180 degrees, got {self.sun_uncertainty_deg}.")
        if not 8 <= self.map_height <= 4096:
            raise InputError(f"map_height must be between 8 and 4096, got {self.map_height}.")
        if not self.l_white > 1.0:
            raise InputError(f"l_white must be above 1, got {self.l_white}.")
