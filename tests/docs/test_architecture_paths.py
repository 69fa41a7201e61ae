"""docs/architecture.md names the code as it is: every module path it cites exists, and every name it
cites after a module (`core/stages/camera.py:estimate_photo_camera`, `core.pipeline.run.run_pipeline`)
is defined there."""
from __future__ import annotations

import re

from conftest import ROOT

ARCHITECTURE = ROOT / "docs" / "architecture.md"
PACKAGES = ("core", "workers", "blender_io", "operators", "panels", "cli")
# A cited path or dotted module: core/stages/light/stage.py, core/base/errors, core.pipeline.run.guidance_found,
# operators/asset.AssetLayout.artists, core/render/renderer.py:material_shapes; not a test's folder
# (tests/core/base/...), which is no module.
CITED = re.compile(r"(?<![\w/])((?:%s)(?:[/.][A-Za-z_][A-Za-z0-9_]*)+(?:\.py)?(?::[A-Za-z_][A-Za-z0-9_]*)?/?)"
                   % "|".join(PACKAGES))


def cited_names(text: str) -> list[str]:
    return sorted(set(CITED.findall(text)))


def resolve(cited: str) -> tuple[str | None, list[str]]:
    """(the file or folder a citation names, relative to the root, and the names cited inside it), or
    (None, []) when no such module exists."""
    path, _, attribute = cited.rstrip("/").partition(":")
    parts = re.split(r"[/.]", path.removesuffix(".py"))
    for split in range(len(parts), 0, -1):
        stem = "/".join(parts[:split])
        names = parts[split:] + ([attribute] if attribute else [])
        if (ROOT / f"{stem}.py").is_file():
            return f"{stem}.py", names
        if (ROOT / stem / "__init__.py").is_file() and names:   # a name in a package's __init__
            return f"{stem}/__init__.py", names
        if (ROOT / stem).is_dir() and not names:   # a package, named whole
            return stem, []
    return None, []


def defined_in(source: str, name: str) -> bool:
    return re.search(rf"^\s*(?:def|class|async def)\s+{name}\b|^\s*{name}\s*[:=]|\bself\.{name}\b|^\s*{name}\s*\(",
                     source, re.MULTILINE) is not None or re.search(rf"^\s+{name}\s*:", source, re.MULTILINE) is not None


def stale(cited: str) -> str | None:
    """Why a citation no longer matches the code, or None."""
    found, names = resolve(cited)
    if found is None:
        return f"{cited} (no such module)"
    if found.endswith(".py") and names and not defined_in((ROOT / found).read_text(encoding="utf-8"), names[0]):
        return f"{cited} ({names[0]} is not defined in {found})"
    return None


def test_every_module_and_name_architecture_cites_exists():
    cited = cited_names(ARCHITECTURE.read_text(encoding="utf-8"))
    assert len(cited) > 50, "the pattern no longer finds the architecture's citations"
    wrong = [why for why in map(stale, cited) if why]
    assert not wrong, f"docs/architecture.md names what the code does not have: {wrong}"


def test_architecture_names_no_file_missing_from_the_repository():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    for name in re.findall(r"\b([A-Z][A-Z_]+\.md)\b", text):
        assert list(ROOT.rglob(name)), f"docs/architecture.md names {name}, which is not in the repository"
    for path in re.findall(r"`((?:docs|tests|benchmarks|tools|devtools)/[\w./-]+\.(?:md|py|sh))`", text):
        assert (ROOT / path).is_file() or list(ROOT.rglob(path.rpartition("/")[2])), \
            f"docs/architecture.md names {path}, which is not in the repository"


def test_the_check_catches_stale_citations():
    for old in ("core/errors", "core/mesh", "core.compose", "core.presets", "core/workers/", "workers/batch.is_done"):
        assert stale(old), old
    for current in ("core/base/errors.py", "core.pipeline.run.run_pipeline", "cli.main", "core/scene/",
                    "core/stages/camera.py:estimate_photo_camera"):
        assert stale(current) is None, current
