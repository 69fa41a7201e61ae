"""The convert stage's work: the asset's maps fitted into a neural texture (core/stages/convert.py)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...data.materials import AssetMaterials
from ...stages.convert import convert_and_bake
from ...stages.convert_config import ConvertConfig
from .. import stage_configs

if TYPE_CHECKING:
    from ..run import PipelineRun


def configure(run: PipelineRun) -> ConvertConfig:
    # Only what the scene needs: no more texels than the composite shows of the asset (the photo's stored
    # height, not the light stage's working copy, is what the composite is made at).
    screen_px = None if run.photo_path is None else max(1, round(run.config.size * run.photo_info["size"][1]))
    return stage_configs.convert_config(run.config, screen_px)


def work(run: PipelineRun, config: ConvertConfig, folder: Path) -> dict[str, Any]:
    asset = run.asset
    assert asset is not None   # (the run refused convert without an asset)
    per_material = isinstance(asset, AssetMaterials)
    return convert_and_bake(asset, None if per_material else run.maps, folder / "maps", config,
                            progress=run.progress, cancel=run.cancel)[1]
