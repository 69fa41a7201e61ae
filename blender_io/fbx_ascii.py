"""ASCII FBX files, which Blender's FBX importer refuses ("ASCII FBX files are not supported"), read
by writing the same node tree as a binary FBX first, with Blender's own FBX writer (io_scene_fbx's
encode_bin, the module its exporter writes with).

An ASCII FBX 7.x file is the binary format's tree written as text: `Name: value, value {children}`,
arrays as `*N { a: v,v,... }`, object names as "Class::Name" (binary: b"Name\\x00\\x01Class"). The
text does not say which binary type a number had, so each is typed here as the importer reads it:
object ids and connection ends are int64, a `P:` property's numbers follow its declared type (int,
bool and enum int32; KTime int64; everything else, vectors and colours included, float64), the
geometry's index arrays int32 and its coordinates float64, animation key times int64 and values
float32. Files older than FBX 7 (a different text layout) are refused in one sentence.
"""
from __future__ import annotations

import base64
import math
import re
from collections import deque
from pathlib import Path

import numpy as np

from ..core.base.errors import InputError

BINARY_MAGIC = b"Kaydara FBX Binary  \x00"
_TOKEN = re.compile(r"""
    \s*(?:
      (?P<comment>;[^\n]*)
    | (?P<string>"[^"]*")
    | (?P<key>[A-Za-z_][\w|]*)\s*:
    | (?P<array>\*\d+\s*\{[^}]*\})
    | (?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)
    | (?P<brace>[{},])
    | (?P<word>[A-Za-z_]\w*)
    )""", re.VERBOSE)
_OBJECT_NAME = re.compile(r"^(\w+)::(.*)$", re.DOTALL)
_ARRAY = re.compile(r"\*(\d+)\s*\{\s*(?:a\s*:(.*?))?\s*\}", re.DOTALL)

# A P: property's value types by its declared type (the P's second field); the rest are float64.
_P_INT32 = {"int", "Integer", "enum", "Enum", "bool", "Bool"}
_P_INT64 = {"KTime", "ULongLong", "LongLong"}
_INT32_ARRAYS = {"PolygonVertexIndex", "Edges", "UVIndex", "ColorIndex", "NormalsIndex", "NormalIndex",
                 "BinormalsIndex", "TangentsIndex", "Materials", "Smoothing", "Indexes", "KeyAttrFlags",
                 "KeyAttrRefCount", "Visibility", "VisibilityIndex", "TextureId", "EdgeCrease", "Hole"}
_INT64_ARRAYS = {"KeyTime"}
_FLOAT32_ARRAYS = {"KeyValueFloat", "KeyAttrDataFloat"}
_INT64_SCALARS = {"LocalTime", "ReferenceTime", "Node"}   # KTime spans, a bind pose's node id


def is_ascii_fbx(path: Path) -> bool:
    """An .fbx file that is not binary (binary FBX starts with its magic)."""
    if path.suffix.lower() != ".fbx":
        return False
    with open(path, "rb") as handle:
        return handle.read(len(BINARY_MAGIC)) != BINARY_MAGIC


def parse_ascii_fbx(text: str) -> list[tuple]:
    """The file's top-level nodes, each (name, [(kind, value)], [children])."""
    tokens = _tokens(text)
    nodes, end = _nodes(tokens, 0)
    if end != len(tokens):
        raise ValueError(f"an unexpected '{tokens[end][1]}' at the top level")
    return nodes


def _tokens(text: str) -> list[tuple[str, str]]:
    out, at = [], 0
    text = text.rstrip()
    while at < len(text):
        match = _TOKEN.match(text, at)
        if match is None or match.end() == at:
            raise ValueError(f"unreadable text at character {at}: {text[at:at + 30]!r}")
        at = match.end()
        kind = match.lastgroup
        if kind != "comment":
            out.append((kind, match.group(kind)))
    return out


MAX_DEPTH = 200   # FBX files nest a dozen levels; a brace thousands deep is not one


def _nodes(tokens: list, at: int, depth: int = 0) -> tuple[list, int]:
    if depth > MAX_DEPTH:
        raise ValueError(f"nodes nest more than {MAX_DEPTH} deep")
    nodes = []
    while at < len(tokens) and tokens[at] != ("brace", "}"):
        kind, name = tokens[at]
        if kind != "key":
            raise ValueError(f"expected a node name, found '{name}'")
        props, at = _values(tokens, at + 1)
        children = []
        if at < len(tokens) and tokens[at] == ("brace", "{"):
            children, at = _nodes(tokens, at + 1, depth + 1)
            if at >= len(tokens):
                raise ValueError(f"node '{name}' is not closed")
            at += 1
        nodes.append((name, props, children))
    return nodes, at


def _values(tokens: list, at: int) -> tuple[list, int]:
    """A node's values: an array (`*N {a: ...}`) or a comma-separated list (possibly empty)."""
    if at < len(tokens) and tokens[at][0] == "array":
        # One token for the whole array, split in C: a mesh's millions of numbers never pass the tokenizer.
        array = _ARRAY.fullmatch(tokens[at][1])
        if array is None:
            raise ValueError(f"an array not written as '*N {{a: values}}': {tokens[at][1][:30]!r}")
        count, body = array.groups()
        numbers = [number.strip() for number in body.split(",")] if body and body.strip() else []
        if numbers and not numbers[-1]:   # a trailing comma, as Asset Forge writes
            numbers.pop()
        if len(numbers) != int(count):
            raise ValueError(f"an array of {count} values holds {len(numbers)}")
        return [("array", numbers)], at + 1
    values = []
    while at < len(tokens) and tokens[at][0] in ("string", "number", "word"):
        kind, raw = tokens[at]
        values.append((kind, raw[1:-1].replace("&quot;", '"') if kind == "string" else raw))
        at += 1
        if at < len(tokens) and tokens[at] == ("brace", ","):
            at += 1
        else:
            break
    return values, at


def binary_copy(source: Path, out: Path) -> Path:
    """`out`: the ASCII FBX `source` written as a binary FBX of the same version. InputError (one
    sentence) for text that is not an FBX 7 file, or holds a value its field cannot take."""
    version, typed = read_text_fbx(source)
    from io_scene_fbx import encode_bin   # Blender's add-on, on the path once bpy is imported

    root = encode_bin.FBXElem(b"")
    for node in typed:
        _element(encode_bin, root, node)
    root.elems.append(_with(encode_bin.FBXElem(b"FileId"), "add_bytes", b"\0" * 16))
    root.elems.append(_with(encode_bin.FBXElem(b"CreationTime"), "add_string", b"1970-01-01 10:00:00:000"))
    encode_bin.write(str(out), root, version)
    return out


def read_text_fbx(source: Path) -> tuple[int, list[tuple]]:
    """(FBX version, typed_tree) of the ASCII FBX `source`; InputError (one sentence) for text that is not
    an FBX 7 file or holds a value its field cannot take. Everything of the file is read here: what the
    binary writer is handed after it has its types."""
    try:
        nodes = parse_ascii_fbx(Path(source).read_text(encoding="utf-8", errors="replace"))
        version = _version(nodes)
        # The binary writer stamps its own file id and creation time, which must be of its types.
        typed = typed_tree([node for node in nodes if node[0] not in ("FileId", "CreationTime")])
        check_polygon_indices(typed)
    except (ValueError, IndexError, OverflowError) as error:   # (binascii.Error is a ValueError)
        raise InputError(f"Asset file '{source}' is an ASCII FBX file that cannot be read ({_short(error)}); check "
                         "that it is a valid FBX file.") from None
    if version < 7000:
        raise InputError(f"Asset file '{source}' is an FBX {version / 1000:g} text file; Blender reads FBX 7 and "
                         "later, so save it from its application as a binary FBX (2011 or later) or as glTF.")
    return version, typed


def _short(error: Exception) -> str:
    text = " ".join(str(error).split())
    return text if len(text) <= 120 else text[:119] + "…"


def _with(element, method: str, value):
    getattr(element, method)(value)
    return element


def _version(nodes: list) -> int:
    for name, props, children in nodes:
        if name == "FBXHeaderExtension":
            for child_name, child_props, _ in children:
                if child_name == "FBXVersion" and child_props:
                    return _integer(child_props[0][1], _INT32, "FBXVersion")
    return 0


def typed_tree(nodes: list, parent: str = "") -> list[tuple]:
    """The parsed nodes with each value as the binary writer takes it: (name, [(writer method, value)],
    [children]). ValueError naming the field for a value its type cannot hold (a word in a number
    array, a number out of its integer range, text that is not base64)."""
    typed: list[tuple] = []
    todo = [(nodes, parent, typed)]
    while todo:   # (no recursion: a hostile file may nest its braces thousands deep)
        level, above, into = todo.pop()
        for name, props, children in level:
            declared = props[1][1] if name == "P" and len(props) > 1 else None
            label = f"property '{props[0][1]}'" if declared is not None else name   # (what the sentence names)
            values = [_typed(name, above, index, kind, value, declared, label)
                      for index, (kind, value) in enumerate(props)]
            node = (name, values, [])
            into.append(node)
            todo.append((children, name, node[2]))
    return typed


def check_polygon_indices(typed: list[tuple]) -> None:
    """Every polygon of every geometry names one of its vertices (an index past them crashed the importer).
    PolygonVertexIndex marks each polygon's last corner as -(i + 1); ValueError naming the first stray one."""
    todo = list(typed)
    while todo:
        name, values, children = todo.pop()
        todo += children
        if name != "Geometry":
            continue
        arrays = {child[0]: child[1][0][1] for child in children
                  if child[1] and isinstance(child[1][0][1], np.ndarray)}
        if "Vertices" not in arrays or "PolygonVertexIndex" not in arrays:
            continue
        count = len(arrays["Vertices"]) // 3
        corners = arrays["PolygonVertexIndex"].astype(np.int64)
        corners = np.where(corners < 0, -corners - 1, corners)
        stray = corners[corners >= count]
        if len(stray):
            raise ValueError(f"PolygonVertexIndex names vertex {int(stray[0])} of {count}")


def _element(encode_bin, parent_element, node: tuple) -> None:
    todo = deque([(parent_element, node)])
    while todo:
        above, (name, values, children) = todo.popleft()
        element = encode_bin.FBXElem(name.encode())
        above.elems.append(element)
        for method, value in values:
            getattr(element, method)(value)
        todo += [(element, child) for child in children]


_INT32, _INT64 = (-2**31, 2**31), (-2**63, 2**63)


def _integer(text: str, bounds: tuple[int, int], field: str) -> int:
    number = float(text)
    whole = int(text) if re.fullmatch(r"[-+]?\d+", text) else int(number) if math.isfinite(number) else None
    if whole is None or not bounds[0] <= whole < bounds[1]:
        raise ValueError(f"{field} holds {text[:30]!r}, not an integer it can take")
    return whole


def _typed(name: str, parent: str, index: int, kind: str, value, declared: str | None,
           label: str) -> tuple[str, object]:
    if kind == "array":
        try:
            numbers = np.array(value, dtype=np.float64)   # exact for the integers an FBX holds (< 2^53)
        except ValueError:
            word = next(v for v in value if not _is_number(v))
            raise ValueError(f"{name} holds {word[:30]!r} among its numbers") from None
        if name in _INT32_ARRAYS or name in _INT64_ARRAYS:
            bounds = _INT32 if name in _INT32_ARRAYS else _INT64
            if numbers.size and not (np.isfinite(numbers).all() and bounds[0] <= numbers.min()
                                     and numbers.max() < bounds[1]):
                raise ValueError(f"{name} holds numbers that are not integers it can take")
            return ("add_int32_array", numbers.astype(np.int32)) if name in _INT32_ARRAYS else \
                ("add_int64_array", numbers.astype(np.int64))
        if name in _FLOAT32_ARRAYS:
            return "add_float32_array", numbers.astype(np.float32)
        return "add_float64_array", numbers
    if kind == "string":
        if name == "Content":   # embedded media, base64 in text
            return "add_bytes", base64.b64decode(value) if value else b""
        named = _OBJECT_NAME.match(value)
        raw = (named.group(2) + "\x00\x01" + named.group(1)) if named else value
        return "add_string", raw.encode("utf-8", "replace")
    if kind == "word":
        return "add_char", value[:1].encode()
    if declared is not None:   # a P: property's value
        if declared in _P_INT32:
            return "add_int32", _integer(value, _INT32, label)
        if declared in _P_INT64:
            return "add_int64", _integer(value, _INT64, label)
        return "add_float64", _finite(value, label)
    if parent == "Objects" and index == 0 or name == "C" or name in _INT64_SCALARS:
        return "add_int64", _integer(value, _INT64, name)
    if re.fullmatch(r"[-+]?\d+", value):
        number = _integer(value, _INT64, name)
        return ("add_int32", number) if _INT32[0] <= number < _INT32[1] else ("add_int64", number)
    return "add_float64", _finite(value, name)


def _finite(text: str, field: str) -> float:
    number = float(text)
    if not math.isfinite(number):
        raise ValueError(f"{field} holds {text[:30]!r}, out of range")
    return number


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
