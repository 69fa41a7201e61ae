"""The layers (docs/architecture.md), read from the source: every import, at module or function level."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("core", "cli", "blender_io", "operators", "panels", "workers")
# What core/ may never import, at any level: Blender, what talks to Blender, and the layers above it.
ABOVE_CORE = ("bpy", "bmesh", "mathutils", "addon_utils", "blender_io", "operators", "panels", "cli", "workers")


def modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            found[name] = path
    return found


def imports(name: str, path: Path, known: dict[str, Path]) -> set[str]:
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


def test_core_never_imports_blender_or_the_layers_above_it():
    known = modules()
    bad = sorted((name, target) for name, path in known.items() if name.startswith("core")
                 for target in imports(name, path, known) if target.split(".")[0] in ABOVE_CORE)
    assert bad == []


def test_the_import_graph_finds_known_edges():
    """So the tests above and below can fail: the graph sees a module-level and a function-level import."""
    known = modules()
    assert "core.output_folder" in imports("workers.batch", known["workers.batch"], known)
    assert "blender_io.asset_file" in imports("workers.batch", known["workers.batch"], known)   # in a function


def test_no_import_circle_anywhere():
    """core.compose <-> lighting <-> guidance was one (the photo camera now lives in core/photo.py), and
    core.presets <-> convert / adapt.config another (the tables are data in core/preset_tables.py)."""
    known = modules()
    graph = {name: {t for t in imports(name, path, known) if t in known and not name.startswith(t + ".")}
             for name, path in known.items()}

    def reaches(start: str, goal: str) -> bool:
        seen, todo = set(), [start]
        while todo:
            node = todo.pop()
            for nxt in graph.get(node, ()):
                if nxt == goal:
                    return True
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return False

    circles = sorted(name for name in graph if reaches(name, name))
    assert circles == []


# Issue 19's bound on a function in core/: longer ones are split into named steps.
MAX_FUNCTION_LINES = 80


def long_functions(path: Path, limit: int) -> list[str]:
    return [f"{path.relative_to(ROOT)}:{node.name} ({node.end_lineno - node.lineno + 1} lines)"
            for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > limit]


def test_no_function_in_core_is_over_80_lines():
    assert [f for path in sorted((ROOT / "core").rglob("*.py")) for f in long_functions(path, MAX_FUNCTION_LINES)] == []


def test_the_length_check_sees_a_long_function():
    # run_pipeline is well over ten lines, so a limit of ten must flag it.
    assert any("run_pipeline" in f for f in long_functions(ROOT / "core" / "run.py", 10))
