"""The game bake of `scenefit run` and of batch jobs: `scenefit bake` on the asset's own file, in a
child process (after Blender's glTF exporter has run, bpy cannot import another glTF in the same
process). core/ never imports Blender; the child does. Being a process of its own, the bake runs
while the run composes (core/pipeline/run.py); the pipeline waits for it, or stops it when the run fails or
is cancelled."""
from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Callable

from ...data.asset_io import is_asset_folder
from ...base.errors import InputError, SceneFitError
from ...base.untrusted import parse_json, read_bytes
from ...base.progress import check_cancel

CLI_MODULE = f"{__package__.rpartition('.core.')[0]}.cli"   # scenefit.cli, or the add-on's own package name
POLL_SECONDS = 0.2   # how often a wait looks at the cancel flag
STOP_SECONDS = 5.0   # how long a stop waits for each way of ending the bake


class BakeProcess:
    """A started `scenefit bake`: wait() for its report (raising its one sentence when it failed),
    or stop() it."""

    def __init__(self, command: list[str], asset: str | Path, glb: Path, report_file: Path,
                 cancel: threading.Event | None) -> None:
        self.asset, self.glb, self.report_file, self.cancel = asset, glb, report_file, cancel
        # its messages go to a file, never a pipe: a pipe nobody reads while compose runs fills and blocks it
        self.stderr = tempfile.TemporaryFile()
        self.process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=self.stderr)

    def wait(self) -> dict:
        try:
            while True:
                try:
                    returncode = self.process.wait(timeout=POLL_SECONDS)
                    break
                except subprocess.TimeoutExpired:
                    check_cancel(self.cancel)
        except BaseException:
            self.stop()
            raise
        self.stderr.seek(0)
        messages = self.stderr.read().decode(errors="replace")
        self.stderr.close()
        if returncode != 0:
            reason = (messages.strip().splitlines() or ["no message"])[-1].removeprefix("scenefit: error: ")
            raise SceneFitError(f"The game bake of '{self.asset}' failed: {reason}")
        try:
            report = parse_json(read_bytes(self.report_file, what="game bake's report"),
                                f"the game bake's report '{self.report_file}'")
        except InputError as error:
            raise SceneFitError(f"The game bake of '{self.asset}' wrote no usable report: {error}") from None
        if not isinstance(report, dict):
            raise SceneFitError(f"The game bake of '{self.asset}' wrote a report that is not a JSON object.")
        report["outputs"] = {"glb": str(self.glb), "report": str(self.report_file)}
        return report

    def stop(self) -> None:
        """End the bake (its output is staged and moved into place only when whole, so nothing half-written stays)."""
        # Ctrl-C first: the command line then removes its staged files; a kill if it does not end soon
        for ask in (lambda: self.process.send_signal(signal.SIGINT), self.process.terminate, self.process.kill):
            if self.process.poll() is not None:
                break
            ask()
            try:
                self.process.wait(timeout=STOP_SECONDS)
            except subprocess.TimeoutExpired:
                pass
        self.stderr.close()


# bake(texture.pt, stage folder, cancel) -> the started bake (core/pipeline/run.py's GameBake).
GameBake = Callable[[Path, Path, "threading.Event | None"], BakeProcess]


def asset_file_bake(asset: str | Path, object_name: str | None = None,
                    target: str = "as-imported") -> tuple[GameBake | None, str]:
    """(bake function or None, why not): a SceneFit asset folder has no file of its own to rewrite.
    `target`: the engine the file is for (`scenefit bake --target`)."""
    if is_asset_folder(asset):
        return None, ("the asset is a SceneFit asset folder; the game bake rewrites an asset's own file "
                      "(.glb, .gltf, .obj, .fbx, .blend)")

    def bake(texture: Path, folder: Path, cancel: threading.Event | None = None) -> BakeProcess:
        folder.mkdir(parents=True, exist_ok=True)
        glb, report_file = folder / f"{Path(asset).stem}.glb", folder / "bake.json"
        command = [sys.executable, "-m", CLI_MODULE, "bake", str(asset), "--texture", str(texture),
                   "--out", str(glb), "--report", str(report_file), "--quiet",
                   "--replace"]   # the stage's own folder: a stage redone replaces its own earlier bake
        if object_name:
            command += ["--object", object_name]
        if target != "as-imported":
            command += ["--target", target]
        return BakeProcess(command, asset, glb, report_file, cancel)

    return bake, ""
