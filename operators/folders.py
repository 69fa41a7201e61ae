"""Where an operator's results go (main thread): the Output folder, a new run folder per run, the last
finished run beside it, images kept with an unsaved file, paths relative to the .blend."""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import bpy

from ..core.base.errors import InputError
from .prefs import ADDON_PACKAGE


def _forbidden_roots() -> list[Path]:
    """Blender deletes its temp dir on exit; the add-on folder is replaced on every update."""
    roots = [Path(__file__).resolve().parent.parent]
    if bpy.app.tempdir:
        roots.append(Path(bpy.app.tempdir).resolve())
    return roots


def _unsaved_root() -> Path:
    """Where an unsaved file's runs go (its images are also packed into the .blend)."""
    try:
        return Path(bpy.utils.extension_path_user(ADDON_PACKAGE, path="unsaved", create=True))
    except (ValueError, KeyError):  # not installed as an extension
        return Path(tempfile.gettempdir()) / "scenefit-unsaved"


def output_root(context) -> Path:
    """The panel's Output folder resolved against the .blend ('//'), or the unsaved-file folder."""
    text = context.scene.scenefit.output_dir or "//scenefit/"
    if text.startswith("//") and not bpy.data.is_saved:
        return _unsaved_root()
    return Path(bpy.path.abspath(text))


def run_folder(context, stage: str, name: str = "") -> Path:
    """A NEW folder for one run of `stage` (never an earlier run's): <output>/<name>/<stage>-<time>[-n].

    Only its path: the run writes beside it and swaps it in whole (core.output_folder), so a
    cancelled or failed run leaves no folder behind."""
    from ..core.base.output_folder import check_output_folder, staging_path

    root = output_root(context).resolve()
    for forbidden in _forbidden_roots():
        if root == forbidden or forbidden in root.parents:
            raise InputError(f"SceneFit does not write into '{root}' (Blender's temporary or the add-on's own "
                             "folder); set the Output folder in the SceneFit panel.")
    parent = root / bpy.path.clean_name(name) if name else root
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in range(1, 1000):
        folder = parent / (f"{stage}-{stamp}" if n == 1 else f"{stage}-{stamp}-{n}")
        if not folder.exists() and not staging_path(folder).exists():
            try:
                return check_output_folder(folder)
            except InputError:  # the command line's wording names --out; the panel names its field
                raise InputError(f"Cannot write into '{parent}'; choose another Output folder in the SceneFit "
                                 "panel.") from None
    raise InputError(f"Too many runs in '{parent}' this second; try again.")


def last_finished_run(folder: Path) -> Path | None:
    """The latest finished run beside the new run `folder` (run_folder's <output>/<name>/<stage>-<time>): the
    one whose report.json was written last; its stages with the new run's keys are reused (copied in)."""
    stage = folder.name.split("-", 1)[0]
    finished = [d for d in folder.parent.glob(f"{stage}-*") if d != folder and (d / "report.json").is_file()]
    return max(finished, key=lambda d: (d / "report.json").stat().st_mtime_ns, default=None)


def keep_image(image) -> None:
    """An unsaved file cannot refer to files next to it: pack the image into the .blend instead."""
    if not bpy.data.is_saved and image.packed_file is None:
        image.pack()


def relative_if_saved(path: str | os.PathLike) -> str:
    """'//…' relative to the .blend when it is saved (the file and its run folders move together)."""
    path = str(path)
    if bpy.data.is_saved:
        try:
            return bpy.path.relpath(path)
        except ValueError:  # another drive on Windows
            return path
    return path
