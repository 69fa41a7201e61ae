"""Which files on disk an asset file is made of (the file, its buffers and images, its material
library): the files an output must never overwrite. Read as data (JSON and text lines), never run."""
from __future__ import annotations

import os
import stat
from pathlib import Path
from urllib.parse import unquote

from ..base.errors import InputError
from ..base.output_folder import LOCK_TEXT, MARKER
from .glb import gltf_json


def asset_files(path: str | os.PathLike, resolve: bool = True) -> list[Path]:
    """The asset file and the files it refers to that exist, resolved (a folder: every file in it).
    resolve False (a file): absolute and normalised as named (`as_named`: links kept under their own
    names), for laying the files out elsewhere as the asset names them."""
    path = Path(path)
    if path.is_dir():
        return sorted(p.resolve() for p in folder_files(path))
    found = [path]
    suffix = path.suffix.lower()
    if suffix in (".gltf", ".glb"):
        found += [path.parent / unquote(uri) for uri in _gltf_uris(path)]
    elif suffix == ".obj":
        named, same_name = obj_material_libraries(path)
        for library in dict.fromkeys(named + [same_name]):
            found.append(library)
            found += _mtl_maps(library)
    for listed in found:   # a FIFO named as a map would hang Blender's importer, and any reader of it
        kind = _special_kind(listed)
        if kind and not kind.startswith("a link"):
            raise InputError(f"'{path.name}' names '{listed}', which is {kind}, not a file; SceneFit reads only "
                             "regular files, so put the file itself there.")
    return sorted({p.resolve() if resolve else as_named(p) for p in found if p.is_file()})


def folder_files(folder: Path) -> list[Path]:
    """The regular files of an asset folder, as named below it, SceneFit's own output beside them left out
    (a run or batch folder written inside it, its staging and lock files): what an asset folder is made of,
    for a job's payload and its digest alike, so a batch whose --out lies inside the folder does not
    change the asset it reads (the folder itself may be one of SceneFit's: a convert's texture folder is read
    whole). One sentence for a FIFO, socket, device or link to nothing in it."""
    refuse_special_files(folder)
    runs = [marker.parent for marker in folder.rglob(MARKER) if marker.is_file() and marker.parent != folder]
    return sorted(p for p in folder.rglob("*") if p.is_file() and not any(run in p.parents for run in runs)
                  and not (p.name.startswith(".") and p.name.endswith(".lock") and _starts_with(p, LOCK_TEXT)))


def _starts_with(path: Path, head: bytes) -> bool:
    with open(path, "rb") as handle:
        return handle.read(len(head)) == head


def refuse_special_files(folder: Path) -> None:
    """One sentence for the first entry below `folder` that is neither a regular file, a folder, nor a link
    to one: a FIFO (reading it waits for ever), a socket, a device, or a link to nothing."""
    for entry in folder.rglob("*"):
        kind = _special_kind(entry)
        if kind:
            raise InputError(f"The asset folder '{folder}' holds '{entry.relative_to(folder)}', which is {kind}; "
                             "SceneFit reads and sends only regular files and folders, so remove it or put the "
                             "file itself there.")


def _special_kind(path: Path) -> str:
    """What `path` is when it exists and is not a regular file or folder (followed through links), else ''."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return f"a link to nothing ('{os.readlink(path)}')" if path.is_symlink() else ""
    except OSError as error:   # a link loop, a name too long
        return f"unreadable ({error.strerror})"
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return ""
    return ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "not a regular file")


def as_named(path: str | os.PathLike) -> Path:
    """`path` absolute and normalised ('..' folded) as named: links are not followed."""
    return Path(os.path.normpath(os.path.abspath(path)))


def _gltf_uris(path: Path) -> list[str]:
    document = gltf_json(path)
    entries = [*document.get("buffers", []), *document.get("images", [])]
    return [e["uri"] for e in entries
            if isinstance(e, dict) and isinstance(e.get("uri"), str) and not e["uri"].startswith("data:")]


def obj_material_libraries(path: Path) -> tuple[list[Path], Path]:
    """(the libraries the .obj's `mtllib` lines name, `<its name>.mtl` beside it), whether or not they
    exist, as Blender's OBJ importer reads them: a line's rest is one name (quotes stripped; joined to the
    .obj's folder even when absolute, as Blender joins it), and the same-named .mtl is read as well."""
    named = []
    with open(path, errors="replace") as f:
        for line in f:
            words = line.split(maxsplit=1)
            if len(words) == 2 and words[0] == "mtllib":
                name = words[1].strip().strip('"').lstrip("/\\")
                if name:
                    named.append(path.parent / name)
    return named, path.with_suffix(".mtl")


# MTL map options and how many values each takes (numbers, up to three; or one word: -clamp on).
_NUMERIC_OPTIONS = ("-o", "-s", "-t", "-mm", "-bm", "-boost", "-texres")
# The lines that name a map: Blender's OBJ importer reads map_* (map_Kd, map_Pm, map_refl, ...), refl (older
# exporters' metallic) and bump; disp and norm are listed too, so nothing a reader may take goes unlisted.
MTL_MAP_PREFIX, MTL_MAP_KEYWORDS = "map_", ("refl", "bump", "disp", "norm")


def is_mtl_map(keyword: str) -> bool:
    return keyword.startswith(MTL_MAP_PREFIX) or keyword in MTL_MAP_KEYWORDS


def _mtl_maps(library: Path) -> list[Path]:
    """The maps an MTL names (is_mtl_map): each line's rest after its options, spaces kept."""
    if not library.is_file():
        return []
    maps = []
    with open(library, errors="replace") as f:
        for line in f:
            words = line.split()
            if words and is_mtl_map(words[0]):
                name = _map_name(words[1:]).strip('"')
                if name:   # as named, and its base name beside the library, where Blender looks next
                    maps += [library.parent / name, library.parent / name.replace("\\", "/").rsplit("/", 1)[-1]]
    return maps


def _map_name(words: list[str]) -> str:
    i = 0
    while i < len(words) and words[i].startswith("-") and not _is_number(words[i]):
        option, i = words[i], i + 1
        if option in _NUMERIC_OPTIONS:
            while i < len(words) and _is_number(words[i]):
                i += 1
        else:
            i += 1
    return " ".join(words[i:])


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def refuse_overwriting(targets: list[Path], protected: list[Path], what: str = "the output") -> None:
    """One sentence, before anything is written, when a file about to be written is one of `protected`
    (compared by resolved path and by inode, so links and other spellings of the same file count)."""
    keys = {_identity(p) for p in protected} - {None}
    names = {Path(p).resolve() for p in protected}
    for target in targets:
        target = Path(target)
        if target.resolve() in names or _identity(target) in keys:
            raise InputError(f"Writing {what} would overwrite '{target}', which is one of the inputs; choose "
                             "another output path or folder (SceneFit never writes over its inputs).")


def refuse_replacing(targets: list[Path], option: str = "--replace") -> None:
    """One sentence when a file about to be written already exists: an earlier run's output (or
    anything else the user keeps there) is replaced only when asked for with `option`."""
    existing = [Path(t) for t in targets if Path(t).exists()]
    if existing:
        more = f" (and {len(existing) - 1} more file{'s' if len(existing) > 2 else ''} it would write)" if len(existing) > 1 else ""
        raise InputError(f"'{existing[0]}' already exists{more}; give {option} to write over it, or choose another "
                         "output path.")


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return stat.st_dev, stat.st_ino
