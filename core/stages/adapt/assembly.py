"""What AdaptSystem.build puts together: the working texture, the renderer's starting light, the prompts
embedded once, the critics (ε_φ with ε_ψ's LoRA and the reference injector; the inpainting critic for the
global views) and the photo's scene the global views place the asset in."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...guidance.critics import ScoreCritic
from ...guidance.injection import ReferenceInjector
from ...guidance.lora import LoraCritic
from ...guidance.models import GuidanceModels
from ...scene.camera import photo_camera_for
from ...texture.neural_texture import NeuralTexture
from .config import AdaptConfig
from .global_views import GlobalScene
from .sampling import view_azimuths
from .stage_data import AdaptInputs


@dataclass
class Critics:
    """What scores a step's views: the local critic (ε_φ, with ε_ψ's LoRA and the reference injector when the
    config asks for them) and the inpainting critic of the global views."""

    local: ScoreCritic
    glob: ScoreCritic | None
    lora: LoraCritic | None
    injector: ReferenceInjector | None


def global_scene_for(inputs: AdaptInputs, config: AdaptConfig, photo: np.ndarray, envmap: np.ndarray) -> GlobalScene:
    """The photo, its camera (the light stage's) and the asset placed in it, for the global views."""
    h, w = photo.shape[:2]
    camera = inputs.photo_camera or photo_camera_for({}, w, h)[0]
    azimuths = view_azimuths(config.views)  # sample_camera's choices
    assert inputs.placement is not None   # (AdaptInputs refuses global views without the placement)
    return GlobalScene(inputs.mesh, inputs.raster.resolution, photo, inputs.placement, camera, envmap, azimuths,
                       config.max_depth, config.shadow_type, config.shadow_spp, config.seed, config.renderer_of("global"))


def renderer_environment(inputs: AdaptInputs, config: AdaptConfig) -> np.ndarray:
    """The map the renderer starts with: the user's (light_type "envmap") or the constant ambient one."""
    if config.light_type == "envmap":
        return np.asarray(inputs.envmap, np.float32)
    return np.full((16, 32, 3), config.ambient, np.float32)


def embed_prompts(models: GuidanceModels, config: AdaptConfig) -> None:
    """Every prompt the run will use, embedded once; the text encoder is released afterwards."""
    prompt = config.effective_prompt
    prompts = ([f"{prompt}, {v}" for v in ("front view", "side view", "back view")]
               if config.mode_type == "generate" else [prompt])
    for p in prompts + [config.negative_prompt]:
        models.embed(p)
    models.release_text_encoder()


def working_texture(inputs: AdaptInputs, config: AdaptConfig) -> NeuralTexture:
    """A copy of the input texture (left as it was), or a fresh one for "generate"."""
    if inputs.texture is None:
        return NeuralTexture(replace(config.texture, resolution=inputs.raster.resolution[0]),
                             seed=config.seed)
    texture = NeuralTexture(inputs.texture.config, seed=None)
    texture.load_state_dict(inputs.texture.state_dict())
    texture.layout = inputs.layout if inputs.layout is not None else inputs.texture.layout
    return texture


def build_critics(models: GuidanceModels, config: AdaptConfig) -> Critics:
    lora = None
    if config.critic.critic_type == "vsd":
        lora = LoraCritic(models.unet, rank=config.lora_rank, lr=config.lr_lora,
                          condition_dropout=config.condition_dropout, seed=config.seed)
    injector = ReferenceInjector(models.unet, config.critic.injection_fraction) if config.uses_reference else None
    local = ScoreCritic(models.unet, models.scheduler, config.critic, lora=lora, injector=injector)
    glob = None
    if config.views_type == "local+global":
        glob = ScoreCritic(models.inpaint_unet, models.scheduler,
                           replace(config.critic, critic_type="sds", reference_type="none"))
    return Critics(local, glob, lora, injector)
