"""docutils tables for the generated references (a cell's `code` spans become literals)."""
from __future__ import annotations

import re

from docutils import nodes

_CODE = re.compile(r"`([^`]+)`")


def inline(text: str) -> nodes.paragraph:
    """A paragraph of `text`, its backquoted spans as literals."""
    paragraph = nodes.paragraph()
    for i, part in enumerate(_CODE.split(text)):
        if part:
            paragraph += nodes.literal(part, part) if i % 2 else nodes.Text(part)
    return paragraph


def table(headers: list[str], rows: list[list[str]], widths: list[int] | None = None,
          literal_columns: tuple[int, ...] = (0,)) -> nodes.table:
    """A table with a header row; the cells of `literal_columns` are set as code."""
    widths = widths or [1] * len(headers)
    group = nodes.tgroup(cols=len(headers))
    for width in widths:
        group += nodes.colspec(colwidth=width)
    group += nodes.thead("", _row(headers, ()))
    group += nodes.tbody("", *(_row(row, literal_columns) for row in rows))
    return nodes.table("", group)


def _row(cells: list[str], literal_columns: tuple[int, ...]) -> nodes.row:
    row = nodes.row()
    for i, cell in enumerate(cells):
        content = nodes.paragraph("", "", nodes.literal(cell, cell)) if i in literal_columns and cell else inline(cell)
        row += nodes.entry("", content)
    return row
