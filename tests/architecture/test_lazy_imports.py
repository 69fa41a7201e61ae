"""Imports in core/ sit at the top of their module; one inside a function is kept only where it puts
off a heavy or optional library (one that takes seconds to load, or that Blender may lack: the extension
registers without it and `operators.dependencies.missing_modules` names it), and says so in a comment."""
from __future__ import annotations

import ast
from pathlib import Path

from scenefit.core.base.source_graph import ROOT, project_modules

# Libraries worth putting off, by top-level name: heavy at import, or optional (in Blender, on a platform).
BOUNDARIES = frozenset({
    "torch", "diffusers", "transformers", "peft", "accelerate", "huggingface_hub",   # seconds to load
    "mitsuba", "drjit", "bpy", "ray", "pyoidn", "openai",
    "cv2", "OpenImageIO",   # the extension registers without them (missing_modules)
    "xatlas", "meshopt",    # wheels not on every platform
    "PIL",                  # Pillow: diffusers brings it; only glTF files with WebP or AVIF images need it
    "fcntl", "msvcrt", "resource",   # one operating system's
})


def _target(module: str, node: ast.Import | ast.ImportFrom, alias: ast.alias) -> str:
    """The dotted name an import statement in `module` loads ("core.data.imageio", "torch")."""
    if isinstance(node, ast.Import):
        return alias.name.removeprefix("scenefit.")
    if node.level:
        package = module.split(".")[:len(module.split(".")) - node.level]
        return ".".join(package + ([node.module] if node.module else []))
    return (node.module or "").removeprefix("scenefit.")


def _for_type_checkers(node: ast.AST) -> bool:
    """An `if TYPE_CHECKING:` block: what it imports is never loaded."""
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(module: str, path: Path) -> tuple[set[str], list[tuple[int, str]]]:
    """(what `module` imports at module level, [(line, target)] of the imports inside its functions)."""
    top: set[str] = set()
    inside: list[tuple[int, str]] = []
    # A package's __init__ resolves relative imports against the package itself.
    module = module + ".__init__" if path.name == "__init__.py" else module

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if _for_type_checkers(child):
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                for alias in child.names:
                    target = _target(module, child, alias)
                    (inside.append((child.lineno, target)) if in_function else top.add(target))
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(ast.parse(path.read_text(encoding="utf-8")), False)
    return top, inside


def _graph(root: Path) -> dict[str, tuple[Path, set[str], list[tuple[int, str]]]]:
    return {module: (path, *_imports(module, path)) for module, path in project_modules(root).items()}


def _boundaries_reached(start: str, graph: dict) -> set[str]:
    """The boundary libraries importing `start` loads through module-level imports (a project module's
    package __init__ included)."""
    seen, todo, found = set(), [start], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        if name.split(".")[0] in BOUNDARIES:
            found.add(name.split(".")[0])
            continue
        parts = name.split(".")
        todo += [".".join(parts[:k]) for k in range(1, len(parts))]
        if name in graph:
            todo += sorted(graph[name][1])
    return found


def _has_reason(lines: list[str], lineno: int) -> bool:
    """A comment on the import's line, or a comment line heading the block of imports it is in."""
    if "#" in lines[lineno - 1]:
        return True
    above = lineno - 2
    while above >= 0 and lines[above].strip().startswith(("import ", "from ")):
        above -= 1
    return above >= 0 and lines[above].strip().startswith("#")


def unjustified_imports(root: Path = ROOT) -> list[str]:
    """'path:line target (why)' for each import inside a core/ function that puts off no boundary library
    the module does not load anyway, or that gives no reason in a comment."""
    graph = _graph(root)
    bad = []
    for module, (path, _, inside) in sorted(graph.items()):
        relative = path.relative_to(root).as_posix()
        if not module.startswith("core"):
            continue
        already = _boundaries_reached(module, graph)
        lines = path.read_text(encoding="utf-8").splitlines()
        for lineno, target in inside:
            put_off = _boundaries_reached(target, graph) - already
            if not put_off:
                bad.append(f"{relative}:{lineno} {target} (puts off nothing heavy or optional: import it at the top)")
            elif not _has_reason(lines, lineno):
                bad.append(f"{relative}:{lineno} {target} (puts off {', '.join(sorted(put_off))}: say so in a comment)")
    return bad


def test_imports_inside_core_functions_only_put_off_heavy_or_optional_libraries():
    assert unjustified_imports() == []


def test_the_check_sees_each_kind_of_unjustified_import(tmp_path):
    files = {
        "core/__init__.py": "",
        "core/base/__init__.py": "",
        "core/base/light.py": "import json\n",
        "core/base/heavy.py": "import torch\n",
        "core/base/user.py": (
            "import numpy\n\n\n"
            "def a():\n    import json\n\n\n"                          # stdlib: nothing put off
            "def b():\n    from .light import x\n\n\n"                 # a light project module
            "def c():\n    import torch\n\n\n"                         # heavy, but no reason given
            "def d():\n    from .heavy import y  # torch: seconds to load\n\n\n"   # fine
            "def e():\n    # cv2: Blender may lack it\n    import cv2\n"),         # fine
        "core/base/torch_user.py": "import torch\n\n\ndef f():\n    from .heavy import y  # already loaded\n",
        "core/base/block.py": "def h():\n    # mitsuba: seconds to load\n    import drjit\n    import mitsuba\n",   # fine
        # What only a type checker reads is not loaded: torch is still put off, and needs its comment.
        "core/base/typed.py": ("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    import torch\n\n\n"
                               "def g():\n    import torch\n"),
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    for package in ("cli", "blender_io", "operators", "panels", "workers"):
        (tmp_path / package).mkdir()
    found = unjustified_imports(tmp_path)
    assert [line.split(" (")[0] for line in found] == [
        "core/base/torch_user.py:5 core.base.heavy", "core/base/typed.py:8 torch", "core/base/user.py:5 json",
        "core/base/user.py:9 core.base.light", "core/base/user.py:13 torch"], found
    assert "(puts off torch: say so in a comment)" in found[1], found[1]


def test_what_an_operators_prepare_builds_loads_no_torch():
    """A job's inputs are gathered on Blender's main thread: the RunConfig, the planned maps and the job
    functions they are handed to import no torch (a second or more the first time)."""
    import subprocess
    import sys

    code = ("import sys\nimport scenefit.core.pipeline.run_config, scenefit.core.data.map_plan, "
            "scenefit.workers.blender_jobs\nprint(sorted(m for m in ('torch', 'mitsuba', 'diffusers') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]", done.stdout


def test_registering_the_add_on_loads_no_torch():
    """Blender registers the add-on at every start: its operators, panels and their modules load no torch,
    Mitsuba, OpenCV or diffusers (a second or more each start); a job imports them when it runs."""
    import subprocess
    import sys

    code = ("import sys, bpy, scenefit\nscenefit.register()\n"
            "print(sorted(m for m in ('torch', 'mitsuba', 'cv2', 'diffusers') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout


def project_imports_inside_functions(prefix: str, root: Path = ROOT) -> list[str]:
    """'module:line target' for each import of a project module inside a function of a module under `prefix`."""
    graph = _graph(root)
    return [f"{module}:{lineno} {target}" for module, (_, _, inside) in sorted(graph.items())
            if module == prefix or module.startswith(prefix + ".")
            for lineno, target in inside if target in graph or target.rsplit(".", 1)[0] in graph]


def test_the_pipeline_imports_no_project_module_inside_a_function():
    """The stage configs load no torch (core/stages/*config*.py), so the registry, presets, run table and
    RunConfig import them at the top; a stage's work module is loaded by its registry record when it runs."""
    assert project_imports_inside_functions("core.pipeline") == []


def test_the_check_sees_a_project_import_inside_a_function(tmp_path):
    files = {"core/__init__.py": "", "core/pipeline/__init__.py": "", "core/stages/__init__.py": "",
             "core/stages/convert.py": "import json\n",
             "core/pipeline/presets.py": "import json\n\n\ndef f():\n    from ..stages.convert import Config\n"}
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert project_imports_inside_functions("core.pipeline", tmp_path) == ["core.pipeline.presets:5 core.stages.convert"]
