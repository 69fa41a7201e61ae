"""The game bake of `scenefit run` and of batch jobs: `scenefit bake` on the asset's own file, in a
child process (after Blender's glTF exporter has run, bpy cannot import another glTF in the same
process). core/ never imports Blender; the child does."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Callable

from .asset_io import is_asset_folder
from .errors import SceneFitError

# bake(texture.pt, stage folder) -> the bake's report with "outputs" (core/run.py's GameBake).
GameBake = Callable[[Path, Path], dict]
CLI_MODULE = f"{__package__.rsplit('.', 1)[0]}.cli"   # scenefit.cli, or the add-on's own package name


def asset_file_bake(asset: str | Path, object_name: str | None = None) -> tuple[GameBake | None, str]:
    """(bake function or None, why not): a SceneFit asset folder has no file of its own to rewrite."""
    if is_asset_folder(asset):
        return None, ("the asset is a SceneFit asset folder; the game bake rewrites an asset's own file "
                      "(.glb, .gltf, .obj, .fbx, .blend)")

    def bake(texture: Path, folder: Path) -> dict:
        folder.mkdir(parents=True, exist_ok=True)
        glb, report_file = folder / f"{Path(asset).stem}.glb", folder / "bake.json"
        command = [sys.executable, "-m", CLI_MODULE, "bake", str(asset), "--texture", str(texture),
                   "--out", str(glb), "--report", str(report_file), "--quiet",
                   "--replace"]   # the stage's own folder: a stage redone replaces its own earlier bake
        if object_name:
            command += ["--object", object_name]
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            reason = (done.stderr.strip().splitlines() or ["no message"])[-1].removeprefix("scenefit: error: ")
            raise SceneFitError(f"The game bake of '{asset}' failed: {reason}")
        report = json.loads(report_file.read_text())
        report["outputs"] = {"glb": str(glb), "report": str(report_file)}
        return report

    return bake, ""
