"""Structured data from elsewhere (a run folder's stage.json, a job's report read back, a cache entry,
a chat endpoint's answer) read one way: parsed with limits on size and nesting, numbers finite, then
checked against the typed shape the reader expects (pydantic). Every failure is one InputError
sentence naming the file and the field; nothing else escapes, whatever the bytes are."""
from __future__ import annotations

import json
import math
import stat
from pathlib import Path
from typing import Any, TypeVar, Union

from pydantic import BaseModel, ConfigDict, ValidationError
from typing_extensions import TypeAliasType

from .errors import InputError

MAX_JSON_BYTES = 16 * 2**20   # a report or stage.json is kilobytes; a chat answer tens of them
MAX_DEPTH = 64                # SceneFit's own files nest a few levels

Shape = TypeVar("Shape", bound=BaseModel)


class Record(BaseModel):
    """A shape read from elsewhere: the fields named are checked (no coercion of text to numbers);
    fields not named are kept as they are."""

    model_config = ConfigDict(extra="allow", strict=True)


def read_bytes(path: str | Path, max_bytes: int = MAX_JSON_BYTES, what: str = "file") -> bytes:
    """A regular file's bytes, at most `max_bytes` (a FIFO, device or folder is refused, never opened)."""
    path = Path(path)
    try:
        if not stat.S_ISREG(path.stat().st_mode):
            raise InputError(f"The {what} '{path}' is not a regular file; remove it or give a file.")
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as error:
        raise InputError(f"The {what} '{path}' cannot be read ({error.strerror or error}).") from None
    if len(data) > max_bytes:
        raise InputError(f"The {what} '{path}' is over {_size(max_bytes)}, more than such a file ever holds; "
                         "it is not read.")
    return data


def parse_json(data: bytes | str, where: str, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_DEPTH) -> Any:
    """JSON text from elsewhere as Python values: UTF-8, at most `max_bytes`, nested at most `max_depth`
    deep, every number finite. `where` names it in the sentence ("the report 'x/report.json'")."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else bytes(data)
    if len(raw) > max_bytes:
        raise InputError(f"{_cap(where)} is over {_size(max_bytes)}, more than it ever holds; it is not read.")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(f"{_cap(where)} is not UTF-8 text (byte {error.start} is not).") from None
    try:
        value = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except json.JSONDecodeError as error:
        raise InputError(f"{_cap(where)} is not valid JSON ({error.msg} at line {error.lineno}, "
                         f"column {error.colno}).") from None
    except RecursionError:   # (the decoder's own guard, far deeper than max_depth)
        raise InputError(f"{_cap(where)} nests deeper than the {max_depth} levels it may.") from None
    except ValueError as error:   # a non-finite number, an integer of thousands of digits
        reason = _first_line(error).split(";")[0]
        raise InputError(f"{_cap(where)} holds a number that is not usable ({_lower_first(reason)}).") from None
    if nesting_depth(value) > max_depth:
        raise InputError(f"{_cap(where)} nests deeper than the {max_depth} levels it may.")
    return value


def nesting_depth(value: Any) -> int:
    """How deep lists and dicts nest in `value` (walked without recursion)."""
    deepest, todo = 0, [(value, 1)]
    while todo:
        item, depth = todo.pop()
        if isinstance(item, (list, dict)):
            deepest = max(deepest, depth)
            todo += [(child, depth + 1) for child in (item.values() if isinstance(item, dict) else item)]
    return deepest


def checked(value: Any, shape: type[Shape], where: str) -> Shape:
    """`value` as `shape`, or one sentence naming `where` and the first field that does not fit."""
    try:
        return shape.model_validate(value)
    except ValidationError as error:
        first = error.errors(include_url=False)[0]
        field = ".".join(str(part) for part in first["loc"])
        place = f"field '{field}'" if field else "its top level"
        raise InputError(f"{_cap(where)} is not what SceneFit reads there: {place}: "
                         f"{_lower_first(_first_line(first['msg']).rstrip('.'))}.") from None


def read_json(path: str | Path, shape: type[Shape], what: str = "file", max_bytes: int = MAX_JSON_BYTES,
              max_depth: int = MAX_DEPTH) -> Shape:
    """A JSON file from elsewhere, parsed with limits and checked against `shape`."""
    where = f"the {what} '{path}'"
    return checked(parse_json(read_bytes(path, max_bytes, what), where, max_bytes, max_depth), shape, where)


def _no_constant(name: str):
    raise ValueError(f"{name} is not a number JSON holds")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text[:20]} is out of range")
    return value


def _first_line(error) -> str:
    lines = str(error).strip().splitlines()
    return " ".join(lines[0].split())[:160] if lines else type(error).__name__


def _lower_first(text: str) -> str:
    """A sentence's first word in lower case to go mid-sentence, but a name kept as written (NaN, JSON)."""
    first_word = text.split(" ", 1)[0]
    return text if any(c.isupper() for c in first_word[1:]) else text[:1].lower() + text[1:]


def _cap(text: str) -> str:
    return text[:1].upper() + text[1:]


def _size(n: int) -> str:
    return f"{n / 2**20:g} MiB" if n >= 2**20 else f"{n} bytes"


# -- the shapes SceneFit reads back from its own folders ---------------------------------------------

# A stage's outputs: paths (relative to its folder), a constant map's value, or a group of them.
Output = TypeAliasType("Output", "Union[str, float, None, dict[str, Output]]")


class StageReport(Record):
    outputs: dict[str, Output] = {}


class StageRecord(Record):
    """A run folder's <stage>/stage.json: the stage's key and its report."""

    key: str
    report: StageReport


def read_stage_record(path: str | Path) -> StageRecord:
    return read_json(path, StageRecord, "stage record")
