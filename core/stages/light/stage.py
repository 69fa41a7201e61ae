"""The light stage from a photo file, as `scenefit light`, a batch job, Blender's Estimate Light and
the pipeline run it: one reading of the photo, the placement and the photo's camera, and one writing of
the stage's files and report.

    inputs = light_inputs(photo_path, at, fspy, camera_overrides)   # photo, pixel, camera, its record
    result = run_light(inputs, config, progress, cancel)             # estimate_light on them
    report = write_light(result, folder)                             # light.exr, previews, report.json

(A batch job's light stage once lit every photo through the default camera while `scenefit light`
used the photo's own: the copies had drifted.)
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...base.report import write_report
from ...scene.camera import PhotoCamera
from ...scene.placement import Placement
from ...base.progress import ProgressCallback
from ...data.photo import load_photo
from ..camera import photo_camera_estimate
from .cues import SUN_UNSURE_ADVICE, sun_is_unsure
from .estimate import LightConfig, LightResult, estimate_light, light_report, write_light_outputs


@dataclass(frozen=True)
class LightInputs:
    photo: np.ndarray          # (h, w, 3) sRGB in [0, 1], the light stage's working copy
    info: dict                 # what load_photo found: the stored size, orientation, metadata
    pixel: tuple[float, float]  # the placement in the working copy's pixels
    camera: PhotoCamera        # the photo's camera at the working copy's size
    camera_record: dict        # where each of its values came from (the report's decisions.camera)


def light_inputs(photo_path: str | Path, at, fspy: str | Path | None = None,
                 camera_overrides: dict | None = None, camera_source: str = "user",
                 camera_why: str = "given by the user") -> LightInputs:
    """The photo read once, the placement `at` ("X,Y" or a pair: fractions, or pixels of the photo as
    stored) and the photo's camera as `scenefit camera` finds it, with `camera_overrides` (from
    `camera_source`, said as `camera_why`) over it."""
    photo, info = load_photo(photo_path)
    h, w = photo.shape[:2]
    pixel = Placement.parse(at, tuple(info["size"])).pixel((h, w))
    estimate = photo_camera_estimate(photo_path, fspy, camera_overrides, camera_source, camera_why)
    return LightInputs(photo, info, pixel, estimate.photo_camera(width=w, height=h), estimate.to_dict())


def run_light(inputs: LightInputs, config: LightConfig, progress: ProgressCallback | None = None,
              cancel: threading.Event | None = None, models=None, asset: dict | None = None) -> LightResult:
    """The light stage: estimate_light on the inputs' photo, placement and camera. models: where loaded
    diffusion models come from (estimate_light); asset: {"mesh", "maps"} for the diffusion critic to
    render the asset itself (default: a grey sphere)."""
    result = estimate_light(inputs.photo, inputs.pixel, config, photo_camera=inputs.camera, photo_info=inputs.info,
                            progress=progress, cancel=cancel, models=models, **(asset or {}))
    result.decisions["camera"] = inputs.camera_record
    result.config, result.photo_info = config, inputs.info
    return result


def write_light(result: LightResult, folder: str | Path, extra: dict | None = None) -> dict:
    """light.exr and its previews in `folder`, and report.json (the photo's facts, `extra` over it)."""
    assert result.config is not None   # (run_light sets it)
    report = light_report(result, result.config, write_light_outputs(result, folder))
    report["photo"] = result.photo_info
    report.update(extra or {})
    write_report(Path(folder) / "report.json", report)
    return report


def sun_words(decisions: dict, setter: str) -> str:
    """The light's direction in a few words for a summary: the artist's sun as given, or a guess that
    `setter` (the flags or buttons that set it) would make truer (benchmarks/FINDINGS.md: 22-30% lower matte error)."""
    sun = decisions.get("sun")
    if not sun:
        return f"light direction guessed ({setter} sets it)"
    spread = sun.get("uncertainty_deg") or 0.0
    sure = "" if spread < 0.5 else f" (±{spread:.0f}°: {SUN_UNSURE_ADVICE})" if sun_is_unsure(spread) else \
        f" (±{spread:.0f}°)"
    given = f"sun {sun['deg'][0]:.4g},{sun['deg'][1]:.4g} as given{sure}"
    return given + ("" if sun.get("used", True) else " (unused by this prior)")
