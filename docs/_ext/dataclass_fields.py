"""A Sphinx directive that documents a dataclass's fields from the code: name, type, default, meaning.

    ```{dataclass-fields} scenefit.workers.jobs.Job
    :exclude: models, camera_source
    ```

The meaning of a field is, in this order: a string literal right after it (an attribute docstring), its
comment on the same line (with the comment lines under it aligned with it), the comment block right
above it, a sentence of the class's docstring that starts with its name (`views: number of azimuths ...`,
`a / b: ...`), or else the comment of its line in an example in the module's docstring (`key = value  #
meaning`, as a TOML example writes it). Any dataclass can be pointed at; nothing here knows SceneFit's
classes.
"""
from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import re
import textwrap

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util.docutils import SphinxDirective

from table_nodes import inline, table


def field_docs(cls: type) -> dict[str, str]:
    """Each annotated field's meaning, read from the class's source (see the module's docstring)."""
    lines, _ = inspect.getsourcelines(cls)
    source = textwrap.dedent("".join(lines))
    lines = source.splitlines()
    body = ast.parse(source).body[0].body
    docs: dict[str, str] = {}
    for i, statement in enumerate(body):
        if not (isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)):
            continue
        after = body[i + 1] if i + 1 < len(body) else None
        if isinstance(after, ast.Expr) and isinstance(getattr(after, "value", None), ast.Constant) \
                and isinstance(after.value.value, str):
            docs[statement.target.id] = " ".join(after.value.value.split())
            continue
        docs[statement.target.id] = _trailing_comment(lines, statement.end_lineno - 1) or \
            _comment_above(lines, statement.lineno - 2)
    described = _docstring_sentences(inspect.getdoc(cls) or "", set(docs))
    example = _example_comments(inspect.getdoc(inspect.getmodule(cls)) or "")
    return {name: doc or described.get(name) or example.get(name, "") for name, doc in docs.items()}


_NAMED = re.compile(r"(?:^|(?<=[.:;]\s))([a-z_][a-z0-9_]*(?:\s*/\s*[a-z_][a-z0-9_]*)*):\s")


def _docstring_sentences(text: str, fields: set[str]) -> dict[str, str]:
    """`name: meaning` (or `a / b: meaning`) runs of a docstring, for names that are fields; each runs to the
    next such name."""
    text = " ".join(text.split())
    starts = [m for m in _NAMED.finditer(text) if set(re.split(r"\s*/\s*", m.group(1))) <= fields]
    found: dict[str, str] = {}
    for match, after in zip(starts, starts[1:] + [None]):
        meaning = text[match.end():after.start() if after else len(text)].strip()
        for name in re.split(r"\s*/\s*", match.group(1)):
            found.setdefault(name, meaning)
    return found


_EXAMPLE_LINE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=.*?\s#\s*(.+)$")


def _example_comments(text: str) -> dict[str, str]:
    """`key = value  # meaning` lines of a docstring's example, first one per key."""
    found: dict[str, str] = {}
    for line in text.splitlines():
        match = _EXAMPLE_LINE.match(line)
        if match:
            found.setdefault(match.group(1), match.group(2).strip())
    return found


def _comment_column(line: str) -> int | None:
    """Where a line's comment starts (a '#' outside strings), or None."""
    quote = None
    for column, char in enumerate(line):
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char == "#":
            return column
    return None


def _trailing_comment(lines: list[str], index: int) -> str:
    column = _comment_column(lines[index])
    if column is None or not lines[index][:column].strip():
        return ""
    parts = [lines[index][column + 1:].strip()]
    for line in lines[index + 1:]:   # comment-only lines aligned with it continue it
        if line.strip().startswith("#") and _comment_column(line) == column:
            parts.append(line[column + 1:].strip())
        else:
            break
    return " ".join(parts)


def _comment_above(lines: list[str], index: int) -> str:
    """The comment lines right above line `index + 1` at its indentation (a deeper one continues the
    comment of the field before)."""
    field_line = lines[index + 1]
    indent = len(field_line) - len(field_line.lstrip())
    parts: list[str] = []
    while index >= 0 and lines[index].strip().startswith("#") and lines[index].index("#") == indent:
        parts.insert(0, lines[index].strip().lstrip("#:").strip())
        index -= 1
    return " ".join(parts)


def _default(field: dataclasses.Field) -> str:
    if field.default is not dataclasses.MISSING:
        return _shown(field.default)
    if field.default_factory is not dataclasses.MISSING:
        return _shown(field.default_factory())
    return "required"


def _shown(value) -> str:
    """A default as written: a config held in a config shows only what differs from its own defaults."""
    if not (dataclasses.is_dataclass(value) and not isinstance(value, type)):
        return repr(value)
    try:
        plain = type(value)()
    except Exception:   # a config whose fields are required, or that refuses its own defaults
        return repr(value)
    changed = [f"{f.name}={getattr(value, f.name)!r}" for f in dataclasses.fields(value)
               if getattr(value, f.name) != getattr(plain, f.name)]
    return f"{type(value).__name__}({', '.join(changed)})"


def _type(annotation) -> str:
    """A field's type as written (a string under `from __future__ import annotations`, else the object)."""
    if isinstance(annotation, str):
        return annotation
    return annotation.__name__ if isinstance(annotation, type) else str(annotation).replace("typing.", "")


def dataclass_rows(cls: type, exclude: set[str] = frozenset(), keys=None) -> list[list[str]]:
    """[name, type, default, meaning] per field of dataclass `cls`, in declaration order; with `keys` (items
    with `.key` and `.field`: a table's spelling of the fields), one row per key, named as the table names it."""
    docs = field_docs(cls)
    by_name = {f.name: f for f in dataclasses.fields(cls)}
    if keys is not None:
        return [[k.key, _type(by_name[k.field].type), _default(by_name[k.field]), docs.get(k.field, "")]
                for k in keys]
    return [[f.name, _type(f.type), _default(f), docs.get(f.name, "")]
            for f in dataclasses.fields(cls) if f.name not in exclude]


def import_object(path: str):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


class DataclassFields(SphinxDirective):
    required_arguments = 1
    option_spec = {"exclude": directives.unchanged, "keys": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        cls = import_object(self.arguments[0])
        if not dataclasses.is_dataclass(cls):
            raise self.error(f"{self.arguments[0]} is not a dataclass")
        self.env.note_dependency(inspect.getsourcefile(cls))
        exclude = {name.strip() for name in self.options.get("exclude", "").split(",") if name.strip()}
        unknown = exclude - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise self.error(f"{self.arguments[0]} has no field {', '.join(sorted(unknown))} to exclude")
        keys = import_object(self.options["keys"]) if "keys" in self.options else None
        missing = [k.field for k in keys or () if k.field not in {f.name for f in dataclasses.fields(cls)}]
        if missing:
            raise self.error(f"{self.arguments[0]} has no field {', '.join(missing)} that its keys name")
        paragraphs = (inspect.getdoc(cls) or "").split("\n\n")
        result: list[nodes.Node] = [inline(" ".join(p.split())) for p in paragraphs if p.strip()]
        return result + [table(["key", "type", "default", "meaning"], dataclass_rows(cls, exclude, keys),
                               widths=[2, 2, 2, 6], literal_columns=(0, 1, 2))]


def setup(app):
    app.add_directive("dataclass-fields", DataclassFields)
    return {"version": "1", "parallel_read_safe": True}
