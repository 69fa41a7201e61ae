"""`scenefit run` says a run as a jobs file does: an option of the same name and help for every key of the run
table (core/pipeline/run_table.RUN_KEYS) but Blender's own, the camera as --fov/--pitch/--roll and the stage
overrides as --set stage.setting=value; what they give reaches the same RunConfig a jobs file's job gives."""
from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from scenefit.cli import build_parser
from scenefit.cli.run import run_config
from scenefit.cli.run_options import option_name, settings_table
from scenefit.core.base.errors import InputError
from scenefit.core.pipeline.registry import names
from scenefit.core.pipeline.run_table import RUN_KEYS, run_config as config_of_table


def _run_parser() -> argparse.ArgumentParser:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["run"]


def _shown_options() -> dict[str, str]:
    """Each option `scenefit run --help` shows, with its help."""
    return {flag: action.help or "" for action in _run_parser()._actions if action.help != argparse.SUPPRESS
            for flag in action.option_strings}


def test_every_run_table_key_has_its_option_with_its_help():
    shown = _shown_options()
    expected = {}
    for key in RUN_KEYS:
        if key.kind == "blender":
            assert key.key in ("camera_source", "camera_why")
        elif key.kind == "camera":
            expected.update({flag: "" for flag in ("--fov", "--pitch", "--roll")})
        elif key.kind == "settings":
            expected["--set"] = key.help
        else:
            expected[option_name(key.key)] = key.help
    assert len(expected) == len(RUN_KEYS) - 2 + 2   # (camera is three options, Blender's own two none)
    missing = sorted(flag for flag in expected if flag not in shown)
    assert missing == []
    assert [flag for flag, words in expected.items() if words not in shown[flag]] == []
    # The help says them too (what a person reads).
    text = subprocess.run([sys.executable, "-m", "scenefit.cli", "run", "--help"], capture_output=True, text=True,
                          check=True).stdout
    assert all(flag in text for flag in expected) and "--guidance " not in text   # (old spellings are not shown)


def _config(*argv: str):
    args = _run_parser().parse_args(["ball", "--photo", "room.png", "--at", "0.5,0.7", "--out", "o", "--offline",
                                     *argv])
    return run_config(args)[0]


def test_the_options_reach_the_same_config_a_jobs_file_gives():
    given = _config("--preset", "draft", "--mode", "edit", "--object-prompt", "a sofa", "--instruction", "add dust",
                    "--negative-prompt", "blurry", "--seed", "7", "--guidance-type", "none", "--object-size", "0.4",
                    "--shadow-type", "paper", "--compose-spp", "16", "--fov", "50", "--pitch", "-12", "--roll", "2",
                    "--turn", "30", "--sun", "20,40", "--sun-uncertainty", "5", "--scene", "indoor",
                    "--set", "adapt.iterations=50", "--set", "light.optimise.lr=0.02")
    table = {"preset": "draft", "mode": "edit", "object_prompt": "a sofa", "instruction": "add dust",
             "negative_prompt": "blurry", "seed": 7, "guidance_type": "none", "object_size": 0.4,
             "shadow_type": "paper", "compose_spp": 16, "camera": {"fov": 50, "pitch": -12, "roll": 2}, "turn": 30,
             "sun": [20, 40], "sun_uncertainty": 5, "scene": "indoor",
             "overrides": {"adapt": {"iterations": 50}, "light": {"optimise": {"lr": 0.02}}}}
    assert given == config_of_table(table, "jobs.toml", names().STAGES, models=given.models)


def test_old_spellings_still_reach_the_run():
    old = _config("--guidance", "none", "--shadow", "paper", "--spp", "8", "--sun-from-shadow", "0.4,0.8", "0.4,0.5",
                  "0.6,0.85")
    assert (old.guidance_type, old.shadow_type, old.compose_spp) == ("none", "paper", 8)
    assert old.sun_shadow == ("0.4,0.8", "0.4,0.5", "0.6,0.85")


@pytest.mark.parametrize("argv, words", [(("--set", "adapt=50"), "stage.setting=value"),
                                         (("--set", "nowhere.iterations=5"), "unknown stage 'nowhere'"),
                                         (("--set", "adapt.iterationz=5"), "iterationz"),
                                         (("--seed", "-1"), "seed")])
def test_a_bad_run_option_is_one_sentence(argv, words):
    with pytest.raises(InputError, match=words) as caught:
        _config(*argv)
    assert "\n" not in str(caught.value)


def test_set_reads_toml_values_and_text():
    assert settings_table(["adapt.iterations=50", "light.outpaint.completion_type=prior", "adapt.prompt=\"a b\""]) == \
        {"adapt": {"iterations": 50, "prompt": "a b"}, "light": {"outpaint": {"completion_type": "prior"}}}
