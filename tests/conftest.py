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
GLTF_TRANSFORM_VERSION = "4.5.1"


def threads_per_worker(cores: int, workers: int) -> int:
    """The cores each of `workers` test workers may use. Every torch (OpenMP) in a worker and in the
    processes it starts takes all the cores by default; with two workers on two cores that is twice
    as many threads as cores, and OpenMP's threads spin while they wait for each other: measured on
    four test files, 142 s of CPU for 78 s against 90 s for 51 s with one thread per worker."""
    return max(1, cores // max(1, workers))


# Set before torch is imported (here or in a process a test starts, which inherits it). A value the
# caller set stays.
_WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
if _WORKERS > 1:
    os.environ.setdefault("OMP_NUM_THREADS", str(threads_per_worker(os.cpu_count() or 1, _WORKERS)))


def run_python(code: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter of this environment; fails the test with its output."""
    full_env = dict(os.environ, **(env or {}))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          env=full_env, timeout=timeout, cwd=ROOT)
    if proc.returncode != 0:
        pytest.fail(f"subprocess failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    return proc


def printed_json(proc: subprocess.CompletedProcess) -> dict:
    """What a test's script printed as its result: the JSON after "JSON" on its last such line of stdout;
    a script that printed none fails the test with its output."""
    lines = [line for line in proc.stdout.splitlines() if line.startswith("JSON")]
    if not lines:
        pytest.fail(f"the script printed no JSON line:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    try:
        return json.loads(lines[-1][4:])
    except ValueError as error:
        pytest.fail(f"the script's JSON line does not parse ({error}):\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")


def takes_ctrl_c() -> None:
    """preexec_fn of a child a test sends Ctrl-C (SIGINT): SIGINT as a terminal gives it. A suite started in
    the background (`nohup`, `&` in a script) hands its children SIGINT ignored, and Python then installs
    no KeyboardInterrupt, so the child would run on as a background job should."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def scenefit_process(*args, env: dict | None = None) -> subprocess.CompletedProcess:
    """`scenefit ARGS` as a user runs it: a process of its own (a fresh bpy), its output captured."""
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=ROOT, env=dict(os.environ, **(env or {})))


def scenefit_side_by_side(*commands, env: dict | None = None, timeout: float = 900) -> list[tuple[int, str]]:
    """(exit code, stderr) of `scenefit ARGS` for each ARGS in `commands`: each a process of its own, as the
    command runs, all started at once (independent commands: a file's bakes, or its converts)."""
    procs = [subprocess.Popen([sys.executable, "-m", "scenefit.cli", *map(str, args)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True, cwd=ROOT, env=dict(os.environ, **(env or {})))
             for args in commands]
    errors = [proc.communicate(timeout=timeout)[1] for proc in procs]
    return [(proc.returncode, err) for proc, err in zip(procs, errors)]


def built_and_converted(build: str, folder: Path, name: str) -> tuple[Path, Path]:
    """(folder/name, its texture.pt): the asset written by the Blender script `build` (FOLDER in it names
    `folder`), then `scenefit convert --preset draft --resolution 64` of it into folder/convert."""
    run_python(build.replace("FOLDER", repr(str(folder))))
    proc = scenefit_process("convert", folder / name, "--out", folder / "convert", "--preset", "draft",
                            "--resolution", "64", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    return folder / name, folder / "convert" / "maps" / "texture.pt"


def scenefit_here(*args) -> subprocess.CompletedProcess:
    """`scenefit ARGS` run in this process (scenefit.cli.main) with its output captured, shaped like the
    finished process it stands for: for the commands on asset folders, which need no Blender. One that
    would import bpy fails the test (bpy is one Blender per process: those run as processes of their own)."""
    import contextlib
    import io

    from scenefit.cli import main

    had_bpy = "bpy" in sys.modules
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    assert had_bpy or "bpy" not in sys.modules, f"scenefit {args[0]} imported bpy into the test process"
    return subprocess.CompletedProcess(["scenefit", *map(str, args)], code, out.getvalue(), err.getvalue())


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


def _npm_module(package: str, version: str, folder: str) -> Path | None:
    """An npm package at `version`, installed once into a cache folder (needs node and npm)."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        return None
    cache = Path(os.environ.get("SCENEFIT_CACHE", Path.home() / ".cache" / "scenefit")) / folder
    module = cache / "node_modules" / package
    if not (module / "package.json").is_file() or \
            json.loads((module / "package.json").read_text()).get("version") != version:
        cache.mkdir(parents=True, exist_ok=True)
        proc = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--prefix", str(cache),
                               f"{package}@{version}"], capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            return None
    return module


def _validator_module() -> Path | None:
    """The gltf-validator npm package, installed once into a cache folder (needs node and npm)."""
    return _npm_module("gltf-validator", VALIDATOR_VERSION, "gltf-validator")


@pytest.fixture(scope="session")
def gltf_transform():
    """run(*args) of glTF-Transform's command line (npm @gltf-transform/cli), e.g. run("webp", a, b): the
    tool that writes test inputs in other texture formats (skips without node and npm)."""
    module = _npm_module("@gltf-transform/cli", GLTF_TRANSFORM_VERSION, "gltf-transform")
    if module is None:
        pytest.skip("glTF-Transform needs node and npm (npm install @gltf-transform/cli failed or no npm)")

    def run(*args) -> None:
        proc = subprocess.run(["node", str(module / "bin" / "cli.js"), *map(str, args)], capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]

    return run


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


_TINY_PAIR: tuple[Path, Path] | None = None


def shared_tiny_pair() -> tuple[Path, Path]:
    """The tiny random-weight (base, inpaint) model folders, built once per test process (4 s each time) and
    only ever read by the tests that share them."""
    global _TINY_PAIR
    if _TINY_PAIR is None:
        import atexit
        import shutil
        import tempfile

        from scenefit.devtools.tiny_models import build_tiny_pair

        folder = Path(tempfile.mkdtemp(prefix="scenefit-tiny-pair-"))
        atexit.register(shutil.rmtree, folder, True)
        _TINY_PAIR = build_tiny_pair(folder)
    return _TINY_PAIR


def extension_and_models(tmp: Path) -> tuple[Path, Path, Path]:
    """The extension zip (no wheels) and an empty Blender user folder in `tmp`, and the tiny models' folder."""
    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension

    zip_path = build_extension.build_without_wheels(tmp / "scenefit.zip")
    user = tmp / "blender_user"
    user.mkdir()
    return zip_path, shared_tiny_pair()[0].parent, user


def fill_in(script: str, tmp: Path, zip_path: Path, tiny: Path) -> str:
    """TMP, ZIP and TINY in `script` replaced by those paths."""
    return (script.replace("TMP", repr(str(tmp))).replace("ZIP", repr(str(zip_path)))
            .replace("TINY", repr(str(tiny))))


def run_installed_extension(tmp: Path, script: str, timeout: float = 900) -> tuple[dict, Path]:
    """Build the extension zip (no wheels) and the tiny model pair into `tmp`, then run `script` in a
    fresh bpy with its own user folder; TMP, ZIP and TINY in the script name them. Returns the dict
    the script printed after "JSON", and the user folder the extension was installed into."""
    zip_path, tiny, user = extension_and_models(tmp)
    proc = run_python(fill_in(script, tmp, zip_path, tiny), env={"BLENDER_USER_RESOURCES": str(user)},
                      timeout=timeout)
    result = printed_json(proc)
    (tmp / "out.json").write_text(json.dumps(result))  # for a look after a failure
    return result, user


_MARK = "@@scenefit-session@@"
_SESSION_LOOP = r"""
import json, sys, traceback
MARK = "@@scenefit-session@@"
_reply = sys.stdout
namespace = {"__name__": "__session__"}
for _line in sys.stdin:
    namespace["out"] = {}
    try:
        exec(compile(json.loads(_line), "<session step>", "exec"), namespace)
        _message = {"out": namespace["out"]}
    except BaseException:
        _message = {"error": traceback.format_exc()}
    _reply.write("\n" + MARK + json.dumps(_message, default=str) + "\n")
    _reply.flush()
"""


class PythonSession:
    """One interpreter of this environment kept open for a group of tests (bpy starts once per process
    and costs seconds): run(code) executes `code` in the session's one namespace, so later steps see
    what earlier ones defined, and returns the dict `out` the code filled. An exception in a step
    fails only the test that ran it, with the session's traceback; the session carries on."""

    def __init__(self, env: dict | None = None):
        import queue
        import tempfile
        import threading

        self._stderr = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen([sys.executable, "-u", "-c", _SESSION_LOOP], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self._stderr, text=True, cwd=ROOT,
                                     env=dict(os.environ, **(env or {})))
        self._lines: queue.Queue = queue.Queue()
        self.output: list[str] = []   # everything the session printed besides its replies

        def read():
            for line in self.proc.stdout:
                self._lines.put(line)
            self._lines.put(None)

        threading.Thread(target=read, daemon=True).start()

    def _tail(self) -> str:
        self._stderr.seek(0)
        return "".join(self.output)[-4000:] + "\n" + self._stderr.read()[-4000:]

    def run(self, code: str, timeout: float = 600) -> dict:
        import queue
        import time

        if self.proc.poll() is not None:
            pytest.fail(f"the session had already ended ({self.proc.returncode}):\n{self._tail()}")
        self.proc.stdin.write(json.dumps(textwrap.dedent(code)) + "\n")
        self.proc.stdin.flush()
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self._lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                self.close()
                pytest.fail(f"a session step ran over {timeout} s:\n{self._tail()}")
            if line is None:
                pytest.fail(f"the session ended ({self.proc.wait()}) during a step:\n{self._tail()}")
            if line.startswith(_MARK):
                reply = json.loads(line[len(_MARK):])
                if "error" in reply:
                    pytest.fail(f"the session step raised:\n{reply['error']}", pytrace=False)
                return reply["out"]
            self.output.append(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._stderr.close()
