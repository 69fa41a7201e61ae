"""Shared fixtures. Blender-touching work runs in subprocesses (bpy is one global Blender per
process, and its user folder must be chosen before it is imported)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def run_python(code: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter of this environment; fails the test with its output."""
    full_env = dict(os.environ, **(env or {}))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          env=full_env, timeout=timeout, cwd=ROOT)
    if proc.returncode != 0:
        pytest.fail(f"subprocess failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    return proc


@pytest.fixture(scope="session")
def run_py():
    return run_python


@pytest.fixture(scope="session")
def example_asset(tmp_path_factory) -> Path:
    """The bundled example made once by Blender (make_example_asset) into a temp folder."""
    out = tmp_path_factory.mktemp("example_asset")
    run_python(f"""
        from scenefit.devtools.example_asset import make_example_asset
        make_example_asset({str(out)!r})
    """)
    return out
