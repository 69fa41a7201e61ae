"""The linter (ruff) over the shipped code and the type checker (mypy) over core/, workers/ and cli/, both
configured in pyproject.toml and pinned in requirements.txt; each test fails with the tool's report."""
from __future__ import annotations

import hashlib
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from conftest import ROOT

CONFIG = ROOT / "pyproject.toml"


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def _package_root() -> Path:
    """A folder holding `scenefit` -> this checkout (the repository root is the package, and mypy finds
    packages by folder name). One per checkout, so mypy's cache beside it stays valid between runs."""
    folder = Path(tempfile.gettempdir()) / f"scenefit-mypy-{hashlib.sha1(str(ROOT).encode()).hexdigest()[:12]}"
    folder.mkdir(exist_ok=True)
    link = folder / "scenefit"
    if not (link.is_symlink() and link.resolve() == ROOT):
        link.unlink(missing_ok=True)
        link.symlink_to(ROOT, target_is_directory=True)
    return folder


def _mypy(cwd: Path, *targets: str) -> subprocess.CompletedProcess:
    cache = _package_root() / ".mypy_cache"
    return _run(["mypy", "--config-file", str(CONFIG), "--cache-dir", str(cache), *targets], cwd)


def test_ruff_passes_on_the_shipped_code():
    proc = _run(["ruff", "check", "--no-cache", "--config", str(CONFIG), "."], ROOT)
    if proc.returncode != 0:
        pytest.fail(f"ruff check found problems:\n{proc.stdout[-8000:]}{proc.stderr[-2000:]}")


def test_mypy_passes_on_core_workers_and_cli():
    proc = _mypy(_package_root(), "-p", "scenefit.core", "-p", "scenefit.workers", "-p", "scenefit.cli")
    if proc.returncode != 0:
        pytest.fail(f"mypy found problems:\n{proc.stdout[-8000:]}{proc.stderr[-2000:]}")


def test_both_tools_report_a_planted_bug_under_the_project_settings(tmp_path):
    """So the two tests above can fail: an unused import, an undefined name and an eval of a file's text
    for ruff, a wrong type in an unannotated function for mypy (its bodies are checked too)."""
    package = tmp_path / "planted"
    package.mkdir()
    (package / "__init__.py").write_text("import os\n\n\ndef f(text):\n    size: int = 'a'\n    return size + missing\n"
                                         "\n\ndef g(text: str):\n    return eval(text)\n")
    ruff = _run(["ruff", "check", "--no-cache", "--config", str(CONFIG), "--output-format", "concise", "."], tmp_path)
    found = ruff.stdout + ruff.stderr
    assert ruff.returncode == 1 and all(code in found for code in ("F401", "F821", "S307")), found
    mypy = _mypy(tmp_path, "-p", "planted")
    assert mypy.returncode == 1 and "[assignment]" in mypy.stdout, mypy.stdout + mypy.stderr
