"""`scenefit` on the command line: the same pipeline the Blender operators run, headless.

It lives beside core/ rather than in it because reading .blend/glTF assets and making the bundled
example need Blender (bpy), which core/ never imports. One module per command, each with
`add_parser(subparsers)`; options shared by several commands are declared once in `options.py`.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import re
import sys
from pathlib import Path

from ..core.base.errors import Cancelled, SceneFitError
from ..core.base.os_errors import os_error_sentence, with_out_paths
from ..core.base.output_folder import finished_jobs, interrupted_message, kept_stages, kept_stages_sentence
from . import adapt, bake, camera, batch, compose, convert, demo, export, light, models, prompt, render, run

# The order `scenefit --help` lists them in.
COMMANDS = (convert, render, export, bake, camera, light, prompt, adapt, compose, run, batch, demo, models)


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a refused option is one sentence (`scenefit render: error: ...`), not the usage
    block first: the same shape as every other refusal. `--help` still shows the usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="scenefit", description=(
        "Restyle a textured 3D asset to fit a photo: neural PBR textures rendered by Mitsuba 3."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(_joined_negative_pairs(sys.argv[1:] if argv is None else list(argv)))
    except SystemExit as stop:  # argparse refused an option (exit 2) or printed --help (exit 0)
        return stop.code if isinstance(stop.code, int) else 2
    try:
        try:
            with _quiet_if_asked(args):
                _check_inputs(args)
                return args.func(args)
        except RuntimeError as error:   # Dr.Jit wraps a Ctrl-C inside a render in its own error
            if _interrupted(error):
                raise KeyboardInterrupt from error
            raise
    except (Cancelled, KeyboardInterrupt) as stop:
        print(f"\nscenefit: {interrupted_message(args.out, getattr(args, 'resumable', False), getattr(args, 'by_stage', False), kept_stages(stop), finished_jobs(stop))}"
              if getattr(args, "out", None) else "\nscenefit: interrupted.", file=sys.stderr)
        return 130
    except SceneFitError as error:   # a file written into the staging folder is named as in --out
        print(f"scenefit: error: {with_out_paths(str(error), getattr(args, 'out', None))}{_kept_words(args, error)}",
              file=sys.stderr)
        return 2
    except OSError as error:   # a full disk, a read-only folder, a file in the way: a sentence, not a traceback
        print(f"scenefit: error: {os_error_sentence(error, getattr(args, 'out', None))}{_kept_words(args, error)}",
              file=sys.stderr)
        return 2


# argparse reads "-30,45" as an option (only a plain number may start with "-"), so `--sun -30,45`, a sun
# on the left, was refused; an X,Y pair after an option that takes one is joined to it as --sun=-30,45.
_PAIR_OPTIONS = ("--sun",)
_NEGATIVE_PAIR = re.compile(r"-[^,\s]*,\S*")   # sun_angles judges the numbers


def _joined_negative_pairs(argv: list[str]) -> list[str]:
    out: list[str] = []
    for arg in argv:
        if out and out[-1] in _PAIR_OPTIONS and _NEGATIVE_PAIR.fullmatch(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def _kept_words(args, error: BaseException) -> str:
    """What a `scenefit run` stopped by bad input mid-way (a shadow point in the sky) kept for the next run."""
    if not getattr(args, "by_stage", False) or not getattr(args, "out", None):
        return ""
    return kept_stages_sentence(error, args.out)


def _check_inputs(args) -> None:
    """The asset path checked before a command loads torch or Blender (seconds), so a mistyped path is
    refused at once; the rest of each command's inputs are checked where they are read."""
    if getattr(args, "asset", None) and not getattr(args, "dry_run", False):
        from ..core.data.asset_io import check_asset_path, resolve_asset_path

        asset = resolve_asset_path(args.asset)
        if asset != Path(args.asset):   # a folder holding one glTF/FBX/...: that file, said once (not under --quiet)
            if not getattr(args, "quiet", False):
                print(f"scenefit: {args.asset} holds one asset file; using {asset.name}", file=sys.stderr)
            args.asset = str(asset)
        check_asset_path(args.asset)


def _quiet_if_asked(args):
    """--quiet: nothing on stdout (the per-material lines, the summary), unless the output itself was
    asked for (--json, --dry-run, batch's --events for a calling program, or a command whose output is
    its result: `prompt`, whose --quiet drops only the model's analysis); errors still go to stderr.
    One rule for every command."""
    asked = any(getattr(args, name, False) for name in ("json", "dry_run", "events")) or args.command == "prompt"
    if getattr(args, "quiet", False) and not asked:
        return contextlib.redirect_stdout(io.StringIO())
    return contextlib.nullcontext()


def _interrupted(error: BaseException | None) -> bool:
    while error is not None:
        if isinstance(error, KeyboardInterrupt):
            return True
        error = error.__cause__ or error.__context__
    return False
