"""Each object's stable identity for SceneFit's jobs (main thread): an id property set on first use, which a
rename keeps and which finds the object again when a job ends. A duplicate (Shift+D copies id properties)
is told apart and gets a fresh id and an empty run history, so it never shares the original's run folders."""
from __future__ import annotations

import uuid

import bpy

ID_PROPERTY = "scenefit_id"
# id -> the session_uid of the object that holds it in this session: the first holder keeps it, a later copy
# (Shift+D, Ctrl+C/V) is the duplicate. Not saved: after reopening, the earliest name keeps the id.
_holders: dict[str, int] = {}


def _linked_id(obj) -> str:
    """An object of a library that is not overridden cannot hold a property: its identity is its library's."""
    return f"linked:{obj.library.filepath}:{obj.name}"


def object_id(obj) -> str:
    """`obj`'s id, given one on first use; a duplicate of an object with the same id gets a fresh one (and an
    empty run history where it is an asset's root)."""
    if obj.library is not None:
        return _linked_id(obj)
    value = obj.get(ID_PROPERTY)
    if not isinstance(value, str) or not value:
        return _fresh(obj)
    holder = _holders.get(value)
    if holder == obj.session_uid:
        return value
    others = [o for o in bpy.data.objects if o is not obj and o.library is None and o.get(ID_PROPERTY) == value]
    keeper = next((o for o in others if o.session_uid == holder), None)
    if keeper is None and others and min(o.name for o in others) < obj.name:
        keeper = min(others, key=lambda o: o.name)   # (a file reopened with a copy in it: the earliest name)
    if keeper is not None:
        _holders[value] = keeper.session_uid
        runs = getattr(getattr(obj, "scenefit_asset", None), "runs", None)
        if runs is not None:
            runs.clear()   # the copy's history would name the original's folders
        return _fresh(obj)
    _holders[value] = obj.session_uid
    return value


def _fresh(obj) -> str:
    value = uuid.uuid4().hex
    obj[ID_PROPERTY] = value
    _holders[value] = obj.session_uid
    return value


def object_by_id(value: str):
    """The object holding id `value` now (whatever its name), or None when it was deleted."""
    if value.startswith("linked:"):
        return next((o for o in bpy.data.objects if o.library is not None and _linked_id(o) == value), None)
    found = [o for o in bpy.data.objects if o.library is None and o.get(ID_PROPERTY) == value]
    if len(found) > 1:   # a duplicate not yet told apart: the holder, else the earliest name
        held = [o for o in found if o.session_uid == _holders.get(value)]
        return held[0] if held else min(found, key=lambda o: o.name)
    return found[0] if found else None
