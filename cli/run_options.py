"""`scenefit run`'s run settings, one option per key of the run table (core/pipeline/run_table.RUN_KEYS):
the same name (--guidance-type for guidance_type) and help as the jobs file's key, so a jobs file and the
command line say a run the same way. The camera is --fov, --pitch and --roll; stage settings are
--set stage.setting=value. What the options give is read back through the run table (run_config), as a
jobs file's [[job]] is."""
from __future__ import annotations

import argparse
import tomllib
from typing import Any

from .options import finite_float, positive_float, positive_int, sun_angles

# Older spellings of some options, still read (not shown) so that what people typed keeps working.
OLD_SPELLINGS = {"guidance_type": "--guidance", "shadow_type": "--shadow", "compose_spp": "--spp",
                 "sun_shadow": "--sun-from-shadow"}
CAMERA_OPTIONS = {"fov": ("--fov", "the photo's horizontal field of view, degrees (default: estimated)"),
                  "pitch": ("--pitch", "where the camera looks above the horizon, degrees; negative looks down "
                                       "(default: estimated)"),
                  "roll": ("--roll", "how far the camera is turned counter-clockwise about its view axis, degrees "
                                     "(default: estimated)")}


def option_name(key: str) -> str:
    return "--" + key.replace("_", "-")


def _kwargs(run_key: Any) -> dict[str, Any]:
    """argparse's spelling of a run key's value (each value given reaches the run table as that key)."""
    kind = run_key.kind
    if kind == "number":
        return {"type": positive_float if run_key.key == "object_size" else finite_float}
    if kind == "whole":
        return {"type": positive_int if run_key.key == "compose_spp" else int}
    if kind == "angles":
        return {"type": sun_angles, "metavar": "AZ,EL"}
    if kind == "points":
        return {"nargs": 3, "metavar": ("FOOT", "TOP", "TIP")}
    return {"choices": run_key.choices} if run_key.choices else {}


def add_run_options(p: argparse.ArgumentParser) -> None:
    """One option per run-table key but Blender's own; the camera as --fov/--pitch/--roll, overrides as --set."""
    from ..core.pipeline.run_table import RUN_KEYS

    for run_key in RUN_KEYS:
        dest = run_key.key   # (as the jobs file names it: fspy and depth_model are inputs --out may not hold)
        if run_key.kind == "blender":
            continue
        if run_key.kind == "camera":
            for name, (flag, words) in CAMERA_OPTIONS.items():
                p.add_argument(flag, dest=f"camera_{name}", type=positive_float if name == "fov" else finite_float, metavar="DEG",
                               help=words)
            continue
        if run_key.kind == "settings":
            p.add_argument("--set", dest=dest, action="append", default=[], metavar="STAGE.SETTING=VALUE",
                           help=f"{run_key.help} (the jobs file's {run_key.key}); repeat for more, e.g. --set "
                                "adapt.iterations=50 --set light.optimise.lr=0.02")
            continue
        kwargs = _kwargs(run_key)
        p.add_argument(option_name(run_key.key), dest=dest, help=run_key.help, **kwargs)
        if run_key.key in OLD_SPELLINGS:
            p.add_argument(OLD_SPELLINGS[run_key.key], dest=dest, help=argparse.SUPPRESS, **kwargs)


def run_table_of(args: argparse.Namespace) -> dict[str, Any]:
    """The run table the options give (the keys given only), as a jobs file's [[job]] would hold it."""
    from ..core.pipeline.run_table import RUN_KEYS

    table: dict[str, Any] = {}
    for run_key in RUN_KEYS:
        value = getattr(args, run_key.key, None)
        if run_key.kind == "camera":
            value = {name: getattr(args, f"camera_{name}") for name in CAMERA_OPTIONS
                     if getattr(args, f"camera_{name}", None) is not None} or None
        elif run_key.kind == "settings":
            value = settings_table(value or []) or None
        elif run_key.kind in ("angles", "points") and value is not None:
            value = list(value)
        if value is not None:
            table[run_key.key] = value
    return table


def settings_table(items: list[str]) -> dict[str, Any]:
    """--set stage.setting=value (a setting of a nested config: stage.group.setting=value) as the jobs file's
    overrides table; the value is read as TOML (a number, true/false, a quoted string, a list), else as text."""
    from ..core.base.errors import InputError

    table: dict[str, Any] = {}
    for item in items:
        path, equals, text = item.partition("=")
        names = path.strip().split(".")
        if not equals or len(names) < 2 or not all(names):
            raise InputError(f"--set takes stage.setting=value, e.g. --set adapt.iterations=50, got '{item}'.")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        place = table
        for name in names[:-1]:
            place = place.setdefault(name, {})
            if not isinstance(place, dict):
                raise InputError(f"--set gives '{path}' and a setting inside it; give one of them.")
        place[names[-1]] = value
    return table

