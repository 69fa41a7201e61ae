"""The light stage: photo + placement -> LDR panorama -> bright regions -> HDR scales -> HDR map.

    estimate_light(photo_srgb, placement_px, config) -> LightResult

Every run ends with an HDR map: the inverse-tone-mapping prior sets the scales, and a critic (the
reference critic against a known map, or a diffusion critic from core/guidance) refines them when
one is given. `write_light_outputs` writes light.exr (float32 EXR, linear), light_ldr.png,
light_preview.png (tone-mapped) and returns the report's fields.
"""
from __future__ import annotations


import math
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from ...base.decision import Decision
from ...base.errors import InputError, ModelMissingError
from ...guidance import models as model_loading   # called through the module, where tests stand in for them
from ...guidance.models import ModelConfig
from ...data.imageio import srgb_to_linear, write_image
from ...data.mesh import Mesh, normalize_to_unit_sphere
from ...data.primitives import uv_sphere
from ...base.progress import ProgressCallback, check_cancel, emit
from ...scene.camera import PhotoCamera, photo_camera_for
from .cues import build_cues
from .depth import estimate_ray_distance
from .diffusion_critic import DiffusionLightCritic
from .outpaint import outpaint_panorama
from .hdr import (SPHERE_PROMPT, ApparatusScene, Critic, OptimiseResult,
                  hdr_from_scales, is_dark_environment, light_prompt, optimise_scales, prior_scales, tonemap_preview)
from ...scene.floor import place_on_floor
from .panorama import Panorama, indoor_panorama, outdoor_panorama
from .regions import bright_regions
from .reference_critic import ReferenceCritic
from .scene_type import scene_type_cue
from .config import LightConfig

# The panorama is built (and its lights found) at least this tall, whatever map size is asked for; a
# smaller map is area-averaged from it, which keeps every light's energy. A lamp smaller than a texel
# survives at any height because a clipped highlight wins its texel in the splat (panorama.splat), so
# draft's 64 rows are built at 64: at 128 it did balanced's work for a coarser map (benchmarks: same
# seconds, same error). tests/core/stages/test_stability.py finds a 1.5 deg lamp and a 2 px 1e6 spot at every preset.
MIN_WORKING_HEIGHT = 64


@dataclass
class LightResult:
    ldr: np.ndarray                       # (H, 2H, 3) sRGB-encoded LDR panorama
    hdr: np.ndarray                       # (H, 2H, 3) linear HDR map, photo exposure units
    regions: dict[str, np.ndarray]
    scales: dict[str, float]
    prior_scales: dict[str, float]
    panorama: Panorama
    photo_camera: PhotoCamera
    decisions: dict = field(default_factory=dict)
    optimisation: OptimiseResult | None = None
    seconds: float = 0.0
    config: LightConfig | None = None     # set by the stage (lighting/stage.run_light), for its report
    photo_info: dict | None = None        # what load_photo found, for the report


def default_photo_camera(photo_info: dict, width: int, height: int) -> tuple[PhotoCamera, dict]:
    """The camera the light stage assumes for a photo when none is given: core/scene/camera.py's (the one
    definition of the frame and the defaults; the field of view from the photo's metadata where it has one)."""
    return photo_camera_for(photo_info, width, height)


def sun_direction(sun_deg: tuple[float, float] | None, camera: PhotoCamera) -> np.ndarray | None:
    """The world unit vector of LightConfig.sun_deg: azimuth from the camera's view, positive to its right."""
    if sun_deg is None:
        return None
    az, el = (math.radians(a) for a in sun_deg)
    yaw = math.radians(camera.yaw_deg) - az
    return np.array([math.cos(el) * math.cos(yaw), math.cos(el) * math.sin(yaw), math.sin(el)])


def default_object() -> tuple[Mesh, torch.Tensor]:
    """When no asset is given: a mid-grey, medium-rough sphere of the normalised radius."""
    maps = torch.cat([torch.full((8, 8, 3), 0.5), torch.full((8, 8, 1), 0.5), torch.zeros(8, 8, 1)], dim=-1)
    return uv_sphere(radius=0.5, segments=32, rings=16), maps


# -- the stage -------------------------------------------------------------------------------------
def estimate_light(photo_srgb: np.ndarray, placement_px: tuple[float, float], config: LightConfig = LightConfig(),
                   photo_camera: PhotoCamera | None = None, mesh: Mesh | None = None, maps: torch.Tensor | None = None,
                   critic: Critic | None = None, reference_envmap: np.ndarray | None = None,
                   photo_info: dict | None = None, progress: ProgressCallback | None = None,
                   cancel: threading.Event | None = None, on_iteration=None, models=None) -> LightResult:
    """Estimate an HDR environment map from a photo (sRGB-encoded float RGB) and the object's placement.

    photo_camera: the photo's orientation and FOV in the world (default: looking along +Y, the
    composition's azimuth 0, at the default pitch). mesh/maps: the object with its fixed
    appearance ((H, W, 5) base colour, roughness, metallic); default a grey sphere. critic: used when
    config.critic_type == "diffusion"; reference_envmap: the true map (photo exposure units) for "reference".
    models: where loaded diffusion models come from, `models.get(model_config, need_inpaint)` (a
    guidance.models.ModelCache, so a worker loads them once for all its jobs); default: loaded here.
    """
    t0 = time.perf_counter()
    # The diffusion models are found before any work (a missing one is a clear error).
    outpainting = _choose_completion(config)
    want_outpaint = outpainting.choice == "sd2"
    hedged = _hedge_unsure_scene(photo_srgb, placement_px, config, want_outpaint, photo_camera, photo_info, progress,
                                 cancel)
    if hedged is not None:
        return hedged
    model_paths = None
    if (config.critic_type == "diffusion" and critic is None) or want_outpaint:
        model_paths = _locate_light_models(config.models, want_outpaint)
    loaded: dict = {}

    def guidance_models():
        if "models" not in loaded:
            loaded["models"] = (models.get(config.models, want_outpaint) if models is not None else
                                model_loading.load_guidance_models(config.models, need_inpaint=want_outpaint,
                                                                   paths=model_paths))
        return loaded["models"]

    photo = np.clip(np.asarray(photo_srgb, np.float32)[..., :3], 0.0, 1.0)
    h, w = photo.shape[:2]
    info = dict(photo_info or {})
    decisions: dict = {}
    if photo_camera is None:
        photo_camera, decisions["fov"] = default_photo_camera(info, w, h)
    elif (photo_camera.width, photo_camera.height) != (w, h):
        photo_camera = replace(photo_camera, width=w, height=h)
    decisions["photo_camera"] = asdict(photo_camera)

    scene_type = _scene_type(photo, config, decisions)
    emit(progress, "light", 0, max(config.optimise.iterations, 1), f"{scene_type} panorama")

    work_height = max(config.map_height, MIN_WORKING_HEIGHT)
    pano = _panorama(photo, photo_camera, placement_px, scene_type, work_height, config, outpainting,
                     guidance_models, decisions)
    check_cancel(cancel)

    ldr, regions, prior, prompts = _prior(photo, pano, scene_type, photo_camera, config, decisions)

    # Optimise the scales with a critic, when there is one.
    scales, optimisation = _critic_scales(config, critic, reference_envmap, mesh, maps, photo, photo_camera,
                                          placement_px, ldr, regions, prior, prompts, guidance_models, decisions,
                                          progress, cancel, on_iteration)
    hdr = _shrink_to_flat(hdr_from_scales(ldr, regions, scales), photo, decisions, optimisation is None)
    if work_height > config.map_height:
        hdr, ldr = (_area_resize(m, config.map_height) for m in (hdr, ldr))
        regions = {name: _area_resize(mask.astype(np.float32), config.map_height) > 0 for name, mask in regions.items()}
    emit(progress, "light", max(config.optimise.iterations, 1), max(config.optimise.iterations, 1), "HDR map ready")
    return LightResult(ldr, hdr, regions, scales, prior, pano, photo_camera, decisions, optimisation,
                       time.perf_counter() - t0)


def _shrink_to_flat(hdr: np.ndarray, photo: np.ndarray, decisions: dict, prior_only: bool) -> np.ndarray:
    """Where the evidence is weak the map leans towards the flat environment (the photo's mean linear
    colour everywhere): hdr c + flat (1 - c), c the cues' confidence. Not after a critic: its scales
    are evidence of their own. On the corpus's real views this won 1 more of 48 on diffuse si-RMSE."""
    confidence = decisions.get("cues", {}).get("confidence")
    if not prior_only or confidence is None or confidence >= 1.0:
        return hdr
    flat = srgb_to_linear(photo).reshape(-1, 3).mean(axis=0).astype(np.float32)
    decisions["shrink"] = {"towards": "the flat environment (the photo's mean linear colour)",
                           "flat_rgb": np.round(flat, 5).tolist(), "weight": round(1.0 - confidence, 4)}
    return (confidence * hdr + (1.0 - confidence) * flat).astype(np.float32)


def _scene_type(photo: np.ndarray, config: LightConfig, decisions: dict) -> str:
    """Indoor or outdoor: the user's, else the automatic call (an unsure one says so)."""
    cue = scene_type_cue(photo)
    scene_type = cue["scene_type"] if config.scene_type == "auto" else config.scene_type
    decisions["scene_type"] = {"chosen": scene_type, "by": "auto" if config.scene_type == "auto" else "user", "auto": cue}
    if config.scene_type == "auto" and cue["unsure"]:
        decisions["scene_type"]["note"] = (f"unsure (score {cue['score']:.2f}, near 1): chose {scene_type}; "
                                           "--scene indoor|outdoor decides")
    return scene_type


def _panorama(photo: np.ndarray, photo_camera: PhotoCamera, placement_px: tuple[float, float], scene_type: str,
              work_height: int, config: LightConfig, outpainting: Decision, guidance_models,
              decisions: dict) -> Panorama:
    """The LDR panorama at the working height: the photo unwrapped around the object (indoors, with
    depth) or warped into the sky and completed (outdoors)."""
    decisions["map_height"] = {"output": config.map_height, "working": work_height, "why": (
        "lights are found at the working size and the map is area-averaged to the output size (energy kept)"
        if work_height > config.map_height else "built at the output size")}
    placement = place_on_floor(photo_camera, placement_px)
    decisions["placement"] = {"pixel": list(placement.pixel), "object_position": np.round(placement.object_position, 4).tolist(),
                              "lifted_below_horizon": placement.clamped}
    if scene_type == "indoor":
        depth = estimate_ray_distance(photo, photo_camera, placement, config.depth)
        decisions["depth"] = {"method": depth.method, **depth.detail}
        pano = indoor_panorama(photo, depth.ray_distance, photo_camera, placement, work_height)
    else:
        outpaint = None
        if outpainting.choice == "sd2":
            def outpaint(ldr, seen):
                return outpaint_panorama(ldr, seen, guidance_models(), config.outpaint)
        pano = outdoor_panorama(photo, photo_camera, work_height, outpaint=outpaint)
        decisions["outpainting"] = {"asked": config.outpaint.completion_type, "used": outpainting.choice == "sd2",
                                    "why": outpainting.reason, "completion": pano.decisions["completion"]}
    decisions["panorama"] = pano.decisions
    return pano


def _prior(photo: np.ndarray, pano: Panorama, scene_type: str, photo_camera: PhotoCamera, config: LightConfig,
           decisions: dict) -> tuple[np.ndarray, dict, dict, tuple[str, ...]]:
    """Bright regions, their prior scales (the cues or the inverse tone curve) and the critic's prompts."""
    ldr = pano.ldr
    regions = bright_regions(ldr, pano.distance, scene_type, config.thresholds)
    if config.sun_deg is not None:
        decisions["sun"] = {"deg": list(config.sun_deg), "used": config.prior_type == "cues",
                            "uncertainty_deg": round(config.sun_uncertainty_deg, 2),
                            "frame": "azimuth from the photo's view, positive to its right; elevation up"}
    if config.prior_type == "cues":
        cues = build_cues(photo, ldr, pano.unseen, regions, config.thresholds, config.cues, camera=photo_camera,
                          sun=sun_direction(config.sun_deg, photo_camera), painted_unseen=pano.painted,
                          sun_uncertainty_deg=config.sun_uncertainty_deg)
        ldr, regions, prior = cues.ldr, cues.regions, cues.scales
        decisions["cues"] = cues.report
    else:
        prior = prior_scales(ldr, regions, config.l_white)
    decisions["regions"] = {name: round(float(mask.mean()), 5) for name, mask in regions.items()}
    decisions["prior"] = {"type": config.prior_type, "l_white": config.l_white,
                          "scales": {k: round(v, 5) for k, v in prior.items()}}
    prior_hdr = hdr_from_scales(ldr, regions, prior)
    dark, dark_info = is_dark_environment(prior_hdr, regions)
    prompts = tuple(light_prompt(config.object_prompt, dark, config.tint) for _ in config.apparatus.object_azimuths) \
        + (light_prompt(SPHERE_PROMPT, dark, config.tint),)
    decisions["prompt"] = {"dark_environment": dark_info, "sphere": prompts[-1], "object": prompts[0],
                           "evaluated_on": "the prior's HDR map"}

    return ldr, regions, prior, prompts


def _critic_scales(config: LightConfig, critic, reference_envmap, mesh, maps, photo: np.ndarray,
                   photo_camera: PhotoCamera, placement_px: tuple[float, float], ldr: np.ndarray, regions: dict,
                   prior: dict, prompts: tuple[str, ...], guidance_models, decisions: dict, progress, cancel,
                   on_iteration) -> tuple[dict, OptimiseResult | None]:
    """The scales: the prior's, or optimised by rendering the apparatus for the chosen critic."""
    scales, optimisation = dict(prior), None
    use_critic, chosen = _choose_critic(config, critic, reference_envmap, regions)
    decisions["critic"] = {"type": config.critic_type, "used": chosen.choice != "none", "why": chosen.reason}
    if chosen.choice != "none":
        if mesh is None or maps is None:
            mesh, maps = default_object()
            decisions["object"] = "default grey sphere (no asset given)"
        else:
            mesh, _ = normalize_to_unit_sphere(mesh)
            decisions["object"] = f"the asset '{mesh.name}' with its own maps"
        scene = ApparatusScene(mesh, maps, ldr.shape[:2], config.apparatus,  # type: ignore[arg-type]
                               photo_azimuth_deg=photo_camera.yaw_deg - 90.0)
        if config.critic_type == "reference":
            use_critic = ReferenceCritic.from_true_map(scene, _fit_map(reference_envmap, ldr.shape[:2]))  # type: ignore[arg-type]
        elif use_critic is None:   # diffusion, with the models located above

            models = guidance_models()
            # Where the object stands in the photo: its foot at the placement, `object_size` of the photo tall.
            side = config.diffusion.object_size * photo.shape[0]
            object_box = (placement_px[0] - side / 2, placement_px[1] - side, side)
            use_critic = DiffusionLightCritic(models, scene.cameras, prompts, config.diffusion, photo=photo,
                                              squares=scene.photo_squares(object_box))
            models.release_text_encoder()
            decisions["critic"].update({"models": {k: str(v) for k, v in models.paths.items()},
                                        "device": str(models.device), "dtype": str(models.dtype).replace("torch.", ""),
                                        **{k: v for k, v in asdict(config.diffusion).items()}})
        optimisation = optimise_scales(scene, ldr, regions, prior, use_critic, prompts, config.optimise,
                                       progress=progress, cancel=cancel, on_iteration=on_iteration)
        scales = {k: math.exp(v) for k, v in optimisation.log_scales.items()}
        decisions["optimisation"] = {"iterations": config.optimise.iterations, "lr": config.optimise.lr,
                                     "final_loss": optimisation.loss_history[-1] if optimisation.loss_history else None,
                                     "seconds": round(optimisation.seconds, 3)}
    return scales, optimisation


def _hedge_unsure_scene(photo_srgb: np.ndarray, placement_px: tuple[float, float], config: LightConfig,
                        want_outpaint: bool, photo_camera: PhotoCamera | None, photo_info: dict | None,
                        progress: ProgressCallback | None, cancel: threading.Event | None) -> LightResult | None:
    """An unsure automatic indoor/outdoor call is handled as unsure: both maps are built and averaged
    (on real views a wrong call cost more than the average of both does). Only where both are cheap:
    no critic and no outpainting model (their scales and completions belong to one scene type)."""
    if config.scene_type != "auto" or config.critic_type != "none" or want_outpaint:
        return None
    cue = scene_type_cue(np.clip(np.asarray(photo_srgb, np.float32)[..., :3], 0.0, 1.0))
    if not cue["unsure"]:
        return None
    t0 = time.perf_counter()
    both = {kind: estimate_light(photo_srgb, placement_px, replace(config, scene_type=kind), photo_camera=photo_camera,
                                 photo_info=photo_info, progress=progress, cancel=cancel)
            for kind in ("indoor", "outdoor")}
    result = both[cue["scene_type"]]
    result.hdr = (0.5 * (both["indoor"].hdr + both["outdoor"].hdr)).astype(np.float32)
    result.decisions.setdefault("depth", both["indoor"].decisions.get("depth"))
    result.decisions["scene_type"] = {
        "chosen": cue["scene_type"], "unsure": True, "by": "auto", "auto": cue,
        "note": f"unsure (score {cue['score']:.2f}): the map is the mean of the indoor and outdoor estimates; "
                f"--scene indoor|outdoor decides", "scales": {k: r.scales for k, r in both.items()}}
    if "cues" in result.decisions:
        # Half the map rests on a scene type that is likely wrong.
        result.decisions["cues"]["confidence"] = round(0.5 * (result.decisions["cues"].get("confidence") or 1.0), 3)
    result.seconds = time.perf_counter() - t0
    return result


def _area_resize(image: np.ndarray, height: int) -> np.ndarray:
    """Area-average a latitude-longitude map down to `height` rows (the mean radiance per texel is kept)."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    return cv2.resize(np.ascontiguousarray(image, np.float32), (2 * height, height), interpolation=cv2.INTER_AREA)


def _fit_map(envmap: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    envmap = np.ascontiguousarray(envmap[..., :3], np.float32)
    if envmap.shape[:2] != tuple(shape):
        envmap = cv2.resize(envmap, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    return envmap


def _choose_critic(config: LightConfig, critic, reference_envmap, regions) -> tuple[Critic | None, Decision]:
    """Which critic optimises the scales: "none", "reference" or "diffusion" (a given critic counts as diffusion)."""
    if not regions:
        return None, Decision("none", "no bright region, so no scale to optimise")
    if config.critic_type == "none":
        return None, Decision("none", f"critic_type 'none': the {config.prior_type} prior sets the scales")
    if config.critic_type == "reference":
        if reference_envmap is None:
            raise InputError("critic_type 'reference' needs the true map (reference_envmap).")
        return None, Decision("reference", "pixel loss against renders under the true map")
    if critic is None:
        return None, Decision("diffusion", "diffusion critic (VSD with Stable Diffusion 2 base, core/guidance)")
    return critic, Decision("diffusion", "diffusion critic (given by the caller)")


def _locate_light_models(models: ModelConfig, need_inpaint: bool) -> dict:
    try:
        return model_loading.locate_models(models, need_inpaint=need_inpaint)
    except ModelMissingError as error:
        raise ModelMissingError(f"{error} For light estimation, `scenefit light --critic none` (critic_type "
                                f"'none') sets the scales by the inverse-tone-mapping prior instead, and "
                                f"`--outpaint prior` completes an outdoor map without the model.") from None


def _choose_completion(config: LightConfig) -> Decision:
    """How an outdoor map's unseen part is completed: "sd2" (inpainting model) or "prior", before any work."""
    kind = config.outpaint.completion_type
    if config.scene_type == "indoor":
        return Decision("prior", "indoor scene: no outpainting")
    if kind == "prior":
        return Decision("prior", "completion_type 'prior': the sky/ground prior completes the map")
    if kind == "sd2":
        return Decision("sd2", "completion_type 'sd2'")

    found, where = model_loading.models_available(config.models, need_inpaint=True)
    if found:
        return Decision("sd2", f"auto: Stable Diffusion 2 inpainting found ({where})")
    return Decision("prior", "auto: Stable Diffusion 2 inpainting is not on this machine, so the sky/ground prior "
                             "completes the map")


def write_light_outputs(result: LightResult, out_dir: str | Path) -> dict[str, str]:
    """light.exr (float32 linear HDR), light_ldr.png (the LDR panorama), light_preview.png (tone-mapped)."""
    out = Path(out_dir)
    paths = {
        "hdr_exr": write_image(out / "light.exr", result.hdr, dtype="float"),
        "ldr_png": write_image(out / "light_ldr.png", result.ldr),
        "preview_png": write_image(out / "light_preview.png", tonemap_preview(result.hdr)),
    }
    return {k: str(v) for k, v in paths.items()}


def _json_safe(value):
    """inf/nan as strings, so report.json stays strict JSON."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def light_report(result: LightResult, config: LightConfig, outputs: dict[str, str]) -> dict:
    return _json_safe({
        "stage": "light",
        "config": asdict(config),
        "decisions": result.decisions,
        "scales": {k: round(v, 6) for k, v in result.scales.items()},
        "prior_scales": {k: round(v, 6) for k, v in result.prior_scales.items()},
        "map_size": [int(result.hdr.shape[1]), int(result.hdr.shape[0])],
        "hdr_max": float(result.hdr.max()),
        # 0..1: how much of the map rests on evidence rather than on the flat environment it shrank to.
        "confidence": result.decisions.get("cues", {}).get("confidence"),
        "seconds": round(result.seconds, 3),
        "outputs": outputs,
        "convention": "latitude-longitude, Blender's equirectangular Environment Texture (top row = +Z, "
                      "u = 0.5 - atan2(y, x) / 2pi, centre column +X); load with blender_io.world.world_from_hdr",
    })
