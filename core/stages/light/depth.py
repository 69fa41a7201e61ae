"""Per-pixel distance for the indoor panorama: a transformers depth model, or the geometric room.

Models: any transformers depth-estimation checkpoint (Depth Anything V2 small by default; DPT/MiDaS
work the same way) from a hub id or a local folder. Relative models predict inverse depth
(disparity) up to an unknown scale; metric ones (config.depth_estimation_type == "metric") predict
depth in metres. Either way the prediction is turned into distances along the camera rays in the
camera-height unit by one scale, chosen so the distance at the placement pixel equals the
distance to the floor there (the object stands on the floor; see `align_to_floor`).

Offline rules (the same as for the diffusion models): with HF_HUB_OFFLINE=1 or
`local_files_only=True` nothing is downloaded; a hub id is then looked up in the cache
(`cache_dir` or HF_HOME's hub folder). A model that cannot be found raises ModelMissingError
naming the model, where it was looked for and how to provide it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...base.errors import InputError, ModelMissingError
from ...guidance.model_store import FOUND, depth_spec, model_state
from ...guidance.models import DEFAULT_DEPTH_MODEL, hub_cache, load_depth_estimator
from ...scene.camera import CAMERA_HEIGHT, PhotoCamera
from ...scene.floor import FloorPoint, geometric_ray_distance

DEPTH_TYPES = ("auto", "model", "geometric")


@dataclass(frozen=True)
class DepthConfig:
    """depth_type: "auto" (model when found, else geometric), "model" (error when missing), "geometric"."""

    depth_type: str = "auto"
    model: str = DEFAULT_DEPTH_MODEL
    cache_dir: str | None = None
    local_files_only: bool | None = None  # None: follow HF_HUB_OFFLINE
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.depth_type not in DEPTH_TYPES:
            raise InputError(f"depth_type must be one of {', '.join(DEPTH_TYPES)}, got {self.depth_type!r}.")


def depth_config_for(models, depth_type: str = "auto", model: str | None = None) -> DepthConfig:
    """The depth model looked for where the diffusion models are (`models`, a ModelConfig): the same cache,
    offline switch and device, so every entry point finds it alike."""
    return DepthConfig(depth_type=depth_type, model=model or DEFAULT_DEPTH_MODEL, cache_dir=models.cache_dir,
                       local_files_only=True if models.local_files_only else None,
                       device=models.device_type if models.device_type in ("cuda", "mps") else "cpu")


@dataclass
class DepthResult:
    ray_distance: np.ndarray      # (h, w) distance along each pixel's ray, camera height = 1
    method: str                   # "model" or "geometric"
    detail: dict


# depth_type "auto" decides once per model folder that a model cannot be loaded (importing transformers to
# find out cost about 3 s per indoor photo): the ModelMissingError is kept here and raised again. A model
# downloaded later (the Preferences' Models, `scenefit models download`) is a new folder, looked at anew.
_ABSENT: dict[tuple, ModelMissingError] = {}


def load_depth_model(config: DepthConfig):
    """The configured model through core/guidance/models.py (loaded once per process); depth_type
    "auto" looks only on this machine (the model manager's file system look, no import)."""
    local_only = True if config.depth_type == "auto" else config.local_files_only
    key: tuple[str | None, ...] = (config.model, config.cache_dir, config.device)
    if config.depth_type == "auto":
        is_folder = Path(config.model).expanduser().exists() or config.model.startswith((".", "/", "~"))
        if not is_folder:
            state = model_state(depth_spec(config.model), hub_cache(config.cache_dir))
            if state.state != FOUND:
                raise ModelMissingError(
                    f"The depth model '{config.model}' is not in the Hugging Face cache {state.cache}; download it "
                    f"(`scenefit models download depth`, Download in SceneFit's Preferences, or `hf download "
                    f"{config.model}`) or pass a local folder (--depth-model PATH).")
            key += (state.where,)
        if key in _ABSENT:
            raise _ABSENT[key]
    try:
        return load_depth_estimator(config.model, config.cache_dir, local_only, config.device)
    except ModelMissingError as error:
        if config.depth_type == "auto":
            _ABSENT[key] = error
        raise


def align_to_floor(prediction: np.ndarray, kind: str, camera: PhotoCamera, placement: FloorPoint,
                   height: float = CAMERA_HEIGHT) -> tuple[np.ndarray, dict]:
    """Distances along rays from a relative prediction, scaled so the placement pixel lies on the floor.

    disparity: z = s / disparity (clipped at 1/1000 of its maximum); depth: z = s * depth; z is depth along the optical axis, turned into
    distance along each ray by dividing by cos(angle to the axis). s is the ratio of the floor's z at the
    placement to the median prediction in a small window around it (robust to a noisy pixel).
    """
    h, w = prediction.shape
    dirs = camera.ray_directions()
    forward = camera.basis()[0]
    cos_axis = np.maximum(dirs @ forward, 1e-3)
    pred = prediction.astype(np.float64)
    if kind == "disparity":
        # Negative disparity is noise; clip at 1/1000 of the largest so "infinitely far" stays finite.
        disparity = np.maximum(pred, 0.0)
        relative_z = 1.0 / np.maximum(disparity, max(1e-3 * float(disparity.max()), 1e-9))
    else:
        relative_z = np.maximum(pred, 1e-6)
    x, y = placement.pixel
    cx = int(np.clip(x / camera.width * w, 0, w - 1))
    cy = int(np.clip(y / camera.height * h, 0, h - 1))
    r = max(1, min(h, w) // 40)
    window = relative_z[max(0, cy - r):cy + r + 1, max(0, cx - r):cx + r + 1]
    target = placement.object_position - np.array([0.0, 0.0, height])
    target_z = float(target @ forward)
    scale = target_z / max(float(np.median(window)), 1e-9)
    distance = (scale * relative_z / cos_axis).astype(np.float32)
    if not np.isfinite(distance).all():
        raise InputError("The depth model produced non-finite depth for this photo.")
    return distance, {"scale": round(scale, 6), "prediction_kind": kind, "placement_axis_depth": round(target_z, 4)}


def estimate_ray_distance(photo_srgb: np.ndarray, camera: PhotoCamera, placement: FloorPoint,
                          config: DepthConfig = DepthConfig()) -> DepthResult:
    """Distances along the photo's rays: from the depth model, or the geometric room when there is none."""
    geometric_reason = "depth_type='geometric' was asked for"
    if config.depth_type in ("auto", "model"):
        try:
            model = load_depth_model(config)
        except ModelMissingError as error:
            if config.depth_type == "model":
                raise
            geometric_reason = f"no depth model: {error}"
        else:
            distance, detail = align_to_floor(model.predict(photo_srgb), model.kind, camera, placement)
            return DepthResult(distance, "model", {"model": model.name, **detail})
    distance = geometric_ray_distance(camera, placement)
    return DepthResult(distance, "geometric", {
        "room": "floor plane at the camera height below the camera, cylindrical wall at 3x the object's distance",
        "why": geometric_reason})
