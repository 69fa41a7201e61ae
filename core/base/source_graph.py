"""The project's own import graph, read from the source (module- and function-level imports alike).

Two users: tests/architecture/test_layout.py checks the layers and that no import circle exists; the run folder's
copy of Blender's read of an asset (core/data/asset_read_cache.py) is keyed by every source file the reader
can reach, so the key follows the code as it grows instead of a hand-kept list.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]   # the repository (core/base/ is two below it)
PACKAGES = ("core", "cli", "blender_io", "operators", "panels", "workers")


def project_modules(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the project's packages by dotted name ("core.scene.camera"; a package's
    __init__.py under the package's own name)."""
    found = {}
    for package in PACKAGES:
        for path in (root / package).rglob("*.py"):
            found[".".join(path.relative_to(root).with_suffix("").parts).removesuffix(".__init__")] = path
    return found


def module_imports(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """Every project module (or outside top-level name) that `name` imports, relative imports resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.removeprefix("scenefit.") for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = (node.module or "").removeprefix("scenefit.")
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in known]
            out |= set(subs) if subs else {target}
    return {m for m in out if m}


@functools.lru_cache(maxsize=8)
def reachable_sources(*start: str, root: Path = ROOT) -> tuple[Path, ...]:
    """The source files of `start` and of every project module they import, directly or through
    others (a package's import also reaches its __init__), sorted."""
    known = project_modules(root)
    seen, todo = set(), [name for name in start if name in known]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        parents = [".".join(name.split(".")[:k]) for k in range(1, name.count(".") + 1)]
        todo += [m for m in module_imports(name, known[name], known) | set(parents) if m in known and m not in seen]
    return tuple(sorted(known[name] for name in seen))
