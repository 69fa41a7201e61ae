"""The commands a missing model's message tells the user to run exist as written: each `scenefit ...` in it
names a command, options that command has and values those options take; the Blender words name a setting
and a choice the panel shows. (A hint that drifted from the program was `scenefit adapt --guidance none`.)"""
from __future__ import annotations

import ast
import re
import shlex

import pytest

from scenefit.cli import build_parser
from scenefit.core.base.errors import ModelMissingError
from scenefit.core.guidance.models import WITHOUT_GUIDANCE, DepthEstimator, ModelConfig, locate_models

from conftest import ROOT


def _subparsers() -> dict:
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return action.choices


def command_problems(command: str) -> list[str]:
    """What in `command` (a `scenefit ...` line) the parser would not take: an unknown command, option or value."""
    words = shlex.split(command)
    assert words[0] == "scenefit", command
    commands = _subparsers()
    if len(words) < 2 or words[1] not in commands:
        return [f"no command {words[1:2]}"]
    parser = commands[words[1]]
    options = parser._option_string_actions
    positionals = [a for a in parser._actions if not a.option_strings]
    problems, i, slot = [], 2, 0
    while i < len(words):
        word = words[i]
        if word == "...":
            i += 1
            continue
        if word.startswith("--"):
            action = options.get(word.split("=")[0])
            if action is None:
                problems.append(f"{words[1]} has no option {word}")
            elif action.nargs != 0:
                value = word.split("=", 1)[1] if "=" in word else (words[i + 1] if i + 1 < len(words) else None)
                if action.choices is not None and value not in action.choices and value != "...":
                    problems.append(f"{word} does not take {value!r}")
                i += 0 if "=" in word else 1
        elif slot < len(positionals):
            action = positionals[slot]
            if action.choices is not None and word not in action.choices:
                problems.append(f"{words[1]} does not take {word!r} as {action.dest}")
            slot += 0 if action.nargs in ("*", "+") else 1
        i += 1
    return problems


def scenefit_commands(message: str) -> list[str]:
    return [c for c in re.findall(r"`([^`]+)`", message) if c.startswith("scenefit ")]


def test_the_checker_refuses_what_argparse_refuses():
    assert command_problems("scenefit run --guidance none") == []
    assert command_problems("scenefit models download depth") == []
    assert command_problems("scenefit adapt --guidance none")      # the old hint: adapt has no --guidance
    assert command_problems("scenefit run --guidance maybe")
    assert command_problems("scenefit models fetch")


def test_missing_model_messages_name_commands_that_parse(tmp_path):
    empty = tmp_path / "empty-cache"
    empty.mkdir()
    messages = []
    for config in (ModelConfig(cache_dir=str(empty)), ModelConfig(base_model=str(tmp_path / "no-folder"))):
        with pytest.raises(ModelMissingError) as info:
            locate_models(config, need_inpaint=True)
        messages.append(str(info.value))
    with pytest.raises(ModelMissingError) as info:
        DepthEstimator("depth-anything/Depth-Anything-V2-Small-hf", cache_dir=str(empty))
    messages.append(str(info.value))
    commands = [c for m in messages for c in scenefit_commands(m)]
    assert {"scenefit models download", "scenefit run --guidance-type none", "scenefit models download depth"} <= set(commands)
    for command in commands:
        assert command_problems(command) == [], command


def test_the_blender_words_name_the_panels_setting_and_choice():
    """"Run All with Adaptation: None": the Run section's setting and the choice it shows."""
    source = (ROOT / "operators" / "properties.py").read_text()
    tree = ast.parse(source)
    guidance = next(node.value for node in ast.walk(tree) if isinstance(node, ast.Assign)
                    and any(getattr(t, "id", None) == "GUIDANCE" for t in node.targets))
    labels = {item.elts[0].value: item.elts[1].value for item in guidance.elts}
    setting = re.search(r'guidance: EnumProperty\(name="([^"]+)"', source).group(1)
    words = re.search(r"Run All with (\w+): (\w+)", WITHOUT_GUIDANCE)
    assert words and words.group(1) == setting and words.group(2) == labels["none"]
