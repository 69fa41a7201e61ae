"""The Python modules the stages import, looked up once per session: one sentence when the build lacks them."""
from __future__ import annotations

import importlib.util

from ..core.base.errors import InputError


# Python modules the stages import, by the name the artist would install.
REQUIRED_MODULES = {"torch": "torch", "mitsuba": "mitsuba", "drjit": "drjit", "cv2": "OpenCV",
                    "OpenImageIO": "OpenImageIO", "diffusers": "diffusers", "transformers": "transformers",
                    "peft": "peft"}
_missing: list[str] | None = None


def missing_modules() -> list[str]:
    """The required modules this Blender cannot import (looked up once per session)."""
    global _missing
    if _missing is None:
        _missing = [label for name, label in REQUIRED_MODULES.items() if importlib.util.find_spec(name) is None]
    return _missing


def dependency_sentence() -> str:
    missing = missing_modules()
    if not missing:
        return ""
    return (f"Missing Python modules: {', '.join(missing)}; install the SceneFit build for your platform "
            "(it bundles them).")


def check_dependencies() -> None:
    """One sentence (InputError) instead of an ImportError traceback when the zip lacks its wheels."""
    sentence = dependency_sentence()
    if sentence:
        raise InputError(sentence)
