"""The names a run is spoken in (its presets and modes) are listed once, in core/base/names.py, its stages once,
in the stage registry (core/pipeline/registry.py), and everything imports them: no other shipped module lists them again. (Guidance and scene types share words with
other choices, "auto" and "none", so a search for their lists would find those too.)"""
from __future__ import annotations

import ast
from pathlib import Path

from scenefit.core.base import names
from scenefit.core.base.source_graph import ROOT
from scenefit.core.pipeline.registry import BUILT_IN

SHIPPED = ("core", "workers", "cli", "operators", "panels", "blender_io")
# (a group, and how many of its names in one literal make a list of them: "scene" and "edit" together are a
# mode's property, all three are the list)
GROUPS = {"stages": (set(BUILT_IN.STAGES), 2), "presets": (set(names.PRESETS), 2), "modes": (set(names.MODES), 3)}


def listed_names(path: Path) -> list[tuple[int, str, list[str]]]:
    """Each tuple, list or set literal in `path` that lists names of a group."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            words = [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
            for group, (members, enough) in GROUPS.items():
                if len(set(words) & members) >= enough and len(words) >= 2:
                    found.append((node.lineno, group, words))
    return found


def test_the_names_are_listed_only_in_the_names_module():
    homes = (ROOT / "core" / "base" / "names.py", ROOT / "core" / "pipeline" / "registry.py")
    copies = [(str(path.relative_to(ROOT)), *hit) for folder in SHIPPED for path in sorted((ROOT / folder).rglob("*.py"))
              if path not in homes for hit in listed_names(path)]
    assert copies == []
    assert len(listed_names(homes[0])) >= 2 and len(listed_names(homes[1])) >= 2   # (so the check can fail: it finds the lists where they are)


def test_the_check_finds_a_copy(tmp_path):
    (tmp_path / "copy.py").write_text('STAGES = ("convert", "light", "adapt")\nMODES = ["scene", "edit"]\n'
                                      'PRESETS = {"draft": 1, "final": 2}\nASKED = ("draft", "final")\n')
    assert [(line, group) for line, group, _ in listed_names(tmp_path / "copy.py")] == [(1, "stages"),
                                                                                        (4, "presets")]
