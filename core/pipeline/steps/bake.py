"""The game bake's work: the final texture written into the asset's own file by a child `scenefit bake`
process (core/stages/bake/process.py: it needs Blender, which core/ never imports), begun once the texture
is final and waited for when the run ends."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from ..run import PipelineRun


def configure(run: PipelineRun) -> None:
    return None   # (its key is the texture's and the asset's)


def begin(run: PipelineRun, config: None, folder: Path) -> Callable[[], dict[str, Any]]:
    texture = run.output("texture")
    assert texture is not None and run.bake is not None   # (begun once the texture is final)
    process = run.bake(texture, folder, run.cancel)
    run.background.append(process)
    return process.wait
