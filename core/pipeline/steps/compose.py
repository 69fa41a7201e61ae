"""The compose stage's work: the texture in the photo under the estimated light, with its shadow
(core/stages/compose.py), through the camera stage's camera."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...data.photo import load_photo
from ...render.environment import load_environment
from ...scene.asset_pose import place_asset
from ...stages.compose import ComposeConfig, ComposeInputs, compose_to_folder
from ...texture.bake import load_neural_texture
from ...texture.surface_layout import texture_view
from .. import stage_configs

if TYPE_CHECKING:
    from ..run import PipelineRun


def configure(run: PipelineRun) -> ComposeConfig:
    return stage_configs.compose_config(run.config)


def check(run: PipelineRun) -> None:
    """An asset that cannot stand where it was put (a ground plane reaching behind the camera) is one sentence."""
    place_asset(run.normalized, run.photo_camera()[0], run.placement_px, configure(run).size, run.config.turn_deg)


def work(run: PipelineRun, config: ComposeConfig, folder: Path) -> dict[str, Any]:
    texture_path, light_path, photo_path = run.output("texture"), run.output("light"), run.photo_path
    assert texture_path is not None and light_path is not None and photo_path is not None   # (compose is last)
    texture = load_neural_texture(texture_path)
    view = texture_view(texture, run.mesh)   # adaptation's new UV layout, when it made one
    full, _ = load_photo(photo_path, max_side=config.max_side)   # at the photo's size, up to max_side
    fh, fw = full.shape[:2]
    camera, camera_from = run.stage_camera(fw, fh)[0], "the camera stage (camera/camera.json)"
    inputs = ComposeInputs(view.mesh, view.stack(texture), full, run.placement.pixel((fh, fw)),
                           load_environment(light_path), camera, turn_deg=run.config.turn_deg)
    extra = {"inputs": {"texture": str(texture_path), "light": str(light_path), "camera_from": camera_from,
                        "uv_layout": view.report["uv_layout"]}}
    return compose_to_folder(inputs, config, folder, extra, progress=run.progress, cancel=run.cancel)
