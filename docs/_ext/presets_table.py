"""A Sphinx directive that writes the presets table from core/pipeline/preset_tables.py.

    ```{presets-table}
    ```

One table per stage: each setting a preset changes, and its value at draft / balanced / final. A value
the preset leaves to the stage's config default is shown resolved through `presets.stage_config` and
marked "(default)".
"""
from __future__ import annotations

import importlib

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

from table_nodes import table

TABLES_MODULE = "scenefit.core.pipeline.preset_tables"
PRESETS_MODULE = "scenefit.core.pipeline.presets"


def _paths(values: dict, prefix: str = "") -> list[str]:
    out = []
    for key, value in values.items():
        out += _paths(value, f"{prefix}{key}.") if isinstance(value, dict) else [f"{prefix}{key}"]
    return out


def _lookup(values, path: str):
    for key in path.split("."):
        values = values[key] if isinstance(values, dict) else getattr(values, key)
    return values


def stage_rows(stage: str) -> list[list[str]]:
    tables = importlib.import_module(TABLES_MODULE)
    presets = importlib.import_module(PRESETS_MODULE)
    paths: list[str] = []
    for name in tables.PRESET_NAMES:
        paths += [p for p in _paths(tables.TABLES[stage][name]) if p not in paths]
    rows = []
    for path in paths:
        row = [path]
        for name in tables.PRESET_NAMES:
            try:
                row.append(str(_lookup(tables.TABLES[stage][name], path)))
            except KeyError:
                try:
                    row.append(f"{_lookup(_resolved(presets, stage, name), path)} (default)")
                except AttributeError:   # a table-only knob (a scale applied while resolving)
                    row.append("1.0 (default)" if path.endswith("_scale") else "(default)")
        rows.append(row)
    return rows


def _resolved(presets, stage: str, name: str):
    """The stage's config at preset `name`; adapt's needs a prompt to exist, which no preset sets."""
    return presets.stage_config(stage, name, **({"prompt": "any"} if stage == "adapt" else {}))


class PresetsTable(SphinxDirective):
    def run(self) -> list[nodes.Node]:
        tables = importlib.import_module(TABLES_MODULE)
        self.env.note_dependency(tables.__file__)
        result: list[nodes.Node] = [table(["preset", "what it is for"],
                                          [[n, tables.PRESET_DESCRIPTIONS[n]] for n in tables.PRESET_NAMES])]
        for stage in tables.TABLES:   # (the neural texture's table, then each configured stage's)
            section_title = nodes.rubric(text=f"{stage}")
            result += [section_title, table(["setting", *tables.PRESET_NAMES], stage_rows(stage),
                                            widths=[3, 2, 2, 2], literal_columns=(0,))]
        return result


def setup(app):
    app.add_directive("presets-table", PresetsTable)
    return {"version": "1", "parallel_read_safe": True}
