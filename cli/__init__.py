"""`scenefit` on the command line: the same pipeline the Blender operators run, headless.

It lives beside core/ rather than in it because reading .blend/glTF assets and making the bundled
example need Blender (bpy), which core/ never imports. One module per command, each with
`add_parser(subparsers)`; options shared by several commands are declared once in `options.py`.
"""
from __future__ import annotations

import argparse
import sys

from ..core.errors import Cancelled, SceneFitError
from . import adapt, bake, convert, demo, export, light, prompt, render

# The order `scenefit --help` lists them in.
COMMANDS = (convert, render, export, bake, light, prompt, adapt, demo)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="scenefit", description=(
        "Restyle a textured 3D asset to fit a photo: neural PBR textures rendered by Mitsuba 3."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except Cancelled as error:
        print(f"\nscenefit: {error}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("\nscenefit: interrupted; outputs already written are complete, nothing half-written remains.",
              file=sys.stderr)
        return 130
    except SceneFitError as error:
        print(f"scenefit: error: {error}", file=sys.stderr)
        return 2
