"""A Sphinx directive that quotes a table of a generated benchmark page, so the docs never copy numbers.

    ```{results-table} benchmarks/results/trade_run.md
    :table: 1
    :columns: preset, seconds, peak MB
    ```

The path is the repository's; `:table:` counts the page's Markdown tables from 1; `:columns:` keeps
those columns, by their header. A missing file, table or column fails the build.
"""
from __future__ import annotations

from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util.docutils import SphinxDirective

from table_nodes import inline, table


def markdown_tables(text: str) -> list[list[list[str]]]:
    """Each pipe table of a Markdown text as rows of cells (the header first, the rule row left out)."""
    tables, current = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
            if not all(set(cell) <= set("-: ") for cell in cells):
                current.append(cells)
        elif current:
            tables.append(current)
            current = []
    return tables


class ResultsTable(SphinxDirective):
    required_arguments = 1
    option_spec = {"table": directives.positive_int, "columns": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        root = Path(self.env.srcdir).parent
        path = root / self.arguments[0]
        if not path.is_file():
            raise self.error(f"{self.arguments[0]} does not exist")
        self.env.note_dependency(str(path))
        tables = markdown_tables(path.read_text(encoding="utf-8"))
        number = self.options.get("table", 1)
        if number > len(tables):
            raise self.error(f"{self.arguments[0]} has {len(tables)} tables, not {number}")
        header, *rows = tables[number - 1]
        wanted = [c.strip() for c in self.options.get("columns", "").split(",") if c.strip()] or header
        missing = [c for c in wanted if c not in header]
        if missing:
            raise self.error(f"{self.arguments[0]}'s table {number} has no column {', '.join(missing)}")
        keep = [header.index(c) for c in wanted]
        body = [[row[i] if i < len(row) else "" for i in keep] for row in rows]
        source = inline(f"From `{self.arguments[0]}` (generated; its heading says the commit, machine and date).")
        return [table(wanted, body, literal_columns=()), source]


def setup(app):
    app.add_directive("results-table", ResultsTable)
    return {"version": "1", "parallel_read_safe": True}
