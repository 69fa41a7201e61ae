"""Shared fixtures. Blender-touching work runs in subprocesses (bpy is one global Blender per
process, and its user folder must be chosen before it is imported)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VALIDATOR_VERSION = "2.0.0-dev.3.10"


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


def _validator_module() -> Path | None:
    """The gltf-validator npm package, installed once into a cache folder (needs node and npm)."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        return None
    cache = Path(os.environ.get("SCENEFIT_CACHE", Path.home() / ".cache" / "scenefit")) / "gltf-validator"
    module = cache / "node_modules" / "gltf-validator"
    if not (module / "package.json").is_file() or \
            json.loads((module / "package.json").read_text()).get("version") != VALIDATOR_VERSION:
        cache.mkdir(parents=True, exist_ok=True)
        proc = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--prefix", str(cache),
                               f"gltf-validator@{VALIDATOR_VERSION}"], capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            return None
    return module


@pytest.fixture(scope="session")
def validator():
    """validate(path) -> the Khronos glTF-Validator's report of a .glb/.gltf (skips without node and npm)."""
    module = _validator_module()
    if module is None:
        pytest.skip("the Khronos glTF-Validator needs node and npm (npm install gltf-validator failed or no npm)")

    def validate(path: str) -> dict:
        proc = subprocess.run(["node", str(ROOT / "tools" / "gltf_validate.js"), str(module), path],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout)

    return validate


def run_installed_extension(tmp: Path, script: str, timeout: float = 900) -> tuple[dict, Path]:
    """Build the extension zip (no wheels) and the tiny model pair into `tmp`, then run `script` in a
    fresh bpy with its own user folder; TMP, ZIP and TINY in the script name them. Returns the dict
    the script printed after "JSON", and the user folder the extension was installed into."""
    import json

    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension
    from scenefit.devtools.tiny_models import build_tiny_pair

    zip_path = build_extension.build_without_wheels(tmp / "scenefit.zip")
    build_tiny_pair(tmp / "tiny")
    user = tmp / "blender_user"
    user.mkdir()
    code = (script.replace("TMP", repr(str(tmp))).replace("ZIP", repr(str(zip_path)))
            .replace("TINY", repr(str(tmp / "tiny"))))
    proc = run_python(code, env={"BLENDER_USER_RESOURCES": str(user)}, timeout=timeout)
    line = next(l for l in proc.stdout.splitlines() if l.startswith("JSON"))
    (tmp / "out.json").write_text(line[4:])  # for a look after a failure
    return json.loads(line[4:]), user
