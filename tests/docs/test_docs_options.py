"""Every `--option` the hand-written docs and the README name is one `scenefit` has (or another tool's,
listed here): an option renamed or removed in cli/ fails this until the docs follow."""
from __future__ import annotations

import argparse
import re

from conftest import ROOT

# Options of other tools the docs quote (torchrun, Blender, pip, pytest, the benchmarks).
OTHER_TOOLS = {"--nproc_per_node", "--python-expr", "--no-deps", "--dist", "--real", "--heldout", "--ceiling",
               "--no-draft", "--quick", "--inverse", "--light-study"}
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9_-]*[a-z0-9]")


def scenefit_options() -> set[str]:
    from scenefit.cli import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    return {option for command in commands.values() for action in command._actions for option in action.option_strings}


def test_every_option_the_docs_name_exists():
    known = scenefit_options() | OTHER_TOOLS
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    unknown = sorted({(page.relative_to(ROOT).as_posix(), option) for page in pages
                      for option in OPTION.findall(page.read_text(encoding="utf-8")) if option not in known})
    assert not unknown, f"the docs name options scenefit does not have: {unknown}"


def test_the_check_sees_an_unknown_option():
    assert "--no-such-option" not in scenefit_options() | OTHER_TOOLS
    assert OPTION.findall("run `scenefit run --at 0.5,0.5 --no-such-option` and --x") == ["--at", "--no-such-option"]
