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

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, ModelMissingError
from ..photo import PhotoCamera
from .panorama import CAMERA_HEIGHT, Placement, geometric_ray_distance

DEFAULT_DEPTH_MODEL = "depth-anything/Depth-Anything-V2-Small-hf"
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


@dataclass
class DepthResult:
    ray_distance: np.ndarray      # (h, w) distance along each pixel's ray, camera height = 1
    method: str                   # "model" or "geometric"
    detail: dict


def _first_sentence(error: Exception) -> str:
    """The library's own reason, without its advice to the library's users (URLs, local directories)."""
    lines = str(error).strip().splitlines()
    return (lines[0].split(". ")[0] if lines else type(error).__name__)[:200]


def offline(local_files_only: bool | None) -> bool:
    if local_files_only is not None:
        return bool(local_files_only)
    return os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on")


def _where_looked(model: str, cache_dir: str | None) -> str:
    if Path(model).expanduser().exists() or model.startswith((".", "/", "~")):
        return f"the folder {Path(model).expanduser()}"
    hub = cache_dir or os.environ.get("HF_HUB_CACHE") or os.path.join(
        os.environ.get("HF_HOME", os.path.expanduser("~/.cache/huggingface")), "hub")
    return f"the Hugging Face cache {hub}"


class DepthModel:
    """A loaded transformers depth estimator: `predict(photo_srgb) -> (h, w) raw prediction`."""

    def __init__(self, model: str, cache_dir: str | None = None, local_files_only: bool | None = None,
                 device: str = "cpu") -> None:
        try:
            from transformers import AutoImageProcessor, AutoModelForDepthEstimation
        except ImportError as error:  # pragma: no cover - transformers is pinned
            raise ModelMissingError(f"transformers is not installed, so the depth model '{model}' cannot be "
                                    f"loaded ({error}).") from error
        only_local = offline(local_files_only)
        source = str(Path(model).expanduser()) if Path(model).expanduser().exists() else model
        try:
            self.processor = AutoImageProcessor.from_pretrained(source, cache_dir=cache_dir,
                                                                local_files_only=only_local)
            self.model = AutoModelForDepthEstimation.from_pretrained(source, cache_dir=cache_dir,
                                                                     local_files_only=only_local)
        except (OSError, ValueError) as error:
            raise ModelMissingError(
                f"The depth model '{model}' was not found in {_where_looked(model, cache_dir)}"
                f"{' (offline: downloads are off)' if only_local else ''}. Provide it by downloading it on a "
                f"connected machine (`huggingface-cli download {model}`) into that cache, or pass a local folder "
                f"holding config.json, the weights and preprocessor_config.json (--depth-model PATH); or use "
                f"the geometric fallback (--depth geometric). Cause: {_first_sentence(error)}") from error
        self.model.eval().to(device)
        self.device = device
        self.name = model
        kind = getattr(self.model.config, "depth_estimation_type", None)
        self.kind = "depth" if kind == "metric" or "zoedepth" in self.model.config.model_type else "disparity"

    def predict(self, photo_srgb: np.ndarray) -> np.ndarray:
        """Raw prediction resized to the photo: disparity (relative models) or depth (metric ones)."""
        import torch
        import torch.nn.functional as F

        image = np.clip(np.round(photo_srgb[..., :3] * 255.0), 0, 255).astype(np.uint8)
        inputs = self.processor(images=image, return_tensors="pt")
        with torch.no_grad():
            pred = self.model(**{k: v.to(self.device) for k, v in inputs.items()}).predicted_depth
        pred = F.interpolate(pred[:, None].float(), size=image.shape[:2], mode="bilinear", align_corners=False)
        return pred[0, 0].cpu().numpy().astype(np.float32)


_CACHE: dict[tuple, DepthModel] = {}


def load_depth_model(config: DepthConfig) -> DepthModel:
    """The configured model, loaded once per process. depth_type "auto" looks only on this machine."""
    local_only = True if config.depth_type == "auto" else config.local_files_only
    key = (config.model, config.cache_dir, offline(local_only), config.device)
    if key not in _CACHE:
        _CACHE[key] = DepthModel(config.model, config.cache_dir, local_only, config.device)
    return _CACHE[key]


def align_to_floor(prediction: np.ndarray, kind: str, camera: PhotoCamera, placement: Placement,
                   height: float = CAMERA_HEIGHT) -> tuple[np.ndarray, dict]:
    """Distances along rays from a relative prediction, scaled so the placement pixel lies on the floor.

    disparity: z = s / disparity (clipped at 1/1000 of its maximum); depth: z = s * depth; z is depth along the optical axis, turned into
    distance along each ray by dividing by cos(angle to the axis). s is the ratio of the floor's z at the
    placement to the median prediction in a small window around it (robust to a noisy pixel).
    """
    h, w = prediction.shape
    dirs = camera.ray_directions()
    yaw, pitch = np.radians(camera.yaw_deg), np.radians(camera.pitch_deg)
    forward = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
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


def estimate_ray_distance(photo_srgb: np.ndarray, camera: PhotoCamera, placement: Placement,
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
