"""A model folder is data from elsewhere (a download, a copy, the artist's own folder): checked before
diffusers or transformers read it. Every file a loader opens is a regular file (a named pipe in a
config's place would hang the loader), each config is JSON within the untrusted reader's limits, and
the model a config describes is built on torch's meta device (no memory) to learn its size, which
must fit this machine's memory before the real load allocates it."""
from __future__ import annotations

import stat
from pathlib import Path
from typing import Any

from ..base.errors import InputError, ModelMissingError
from ..base.limits import memory_needed_sentence
from ..base.untrusted import parse_json, read_bytes

MAX_CONFIG_BYTES = 4 * 2**20   # a model's config is kilobytes; a tokenizer's vocabulary about 1 MB
_READ = ("*.json", "*.txt", "*.safetensors", "*.model")   # what the loaders open
# Bounds no published network's config comes near (SD2's widest is 1280 channels, its longest list 4
# blocks), so the constructors' loops over a config's counts stay short even on the meta device.
MAX_CONFIG_INTEGER = 2**20
MAX_CONFIG_LIST = 64
MAX_LAYERS = 1024


def check_model_files(folder: Path, what: str) -> None:
    """Every file the loaders would open in `folder` (and its subfolders) is a regular file, and every
    JSON among them reads within the limits as an object."""
    for pattern in _READ:
        for path in sorted(folder.rglob(pattern)):
            try:
                mode = path.stat().st_mode
            except OSError as error:
                raise ModelMissingError(f"The {what} file '{path}' cannot be read ({error.strerror or error}); "
                                        "give a complete model folder.") from None
            if stat.S_ISDIR(mode):
                continue
            if not stat.S_ISREG(mode):
                raise ModelMissingError(f"The {what} file '{path}' is not a regular file (a pipe, socket or "
                                        "device); the model is not read. Give a model folder of plain files.")
            if path.suffix == ".json":
                read_config(path, what, bounded=False)


def read_config(path: Path, what: str, bounded: bool = True) -> dict[str, Any]:
    """One config file as a JSON object, or one sentence naming it; `bounded`: a network's config, whose
    counts and lists are held to what a network has (a tokenizer's may say 1e30 for "no limit")."""
    try:
        value = parse_json(read_bytes(path, MAX_CONFIG_BYTES, f"{what} file"), f"the {what} file '{path}'",
                           MAX_CONFIG_BYTES)
    except InputError as error:
        raise ModelMissingError(str(error)) from None
    if not isinstance(value, dict):
        raise ModelMissingError(f"The {what} file '{path}' holds {type(value).__name__} where a config holds "
                                "an object; the model is not read.")
    for key, item in _items(value) if bounded else ():
        limit = MAX_LAYERS if "layers" in key else MAX_CONFIG_INTEGER
        if isinstance(item, list) and len(item) > MAX_CONFIG_LIST or \
                isinstance(item, (int, float)) and not isinstance(item, bool) and abs(item) > limit:
            shown = f"a list of {len(item)} values" if isinstance(item, list) else repr(item)
            raise ModelMissingError(f"The {what} file '{path}' gives '{key}' as {shown}, beyond what any model "
                                    "SceneFit reads has; the model is not read.")
    return value


def _items(value: Any, key: str = ""):
    """(key, value) of every entry, nested ones named by their innermost key."""
    todo = [(key, value)]
    while todo:
        name, item = todo.pop()
        yield name, item
        if isinstance(item, dict):
            todo += [(str(k), v) for k, v in item.items()]
        elif isinstance(item, list):
            todo += [(name, v) for v in item]


def check_model_memory(build, where: Path, what: str, bytes_per_parameter: int) -> None:
    """The model `build()` makes from a config, built on the meta device (shapes only), must fit this
    machine's memory; a config a constructor cannot build from is refused in one sentence."""
    import torch  # lazy: torch takes seconds to load

    try:
        with torch.device("meta"):
            model = build()
        parameters = sum(p.numel() for p in model.parameters())
    except Exception as error:   # the library's constructors raise anything on values of the wrong type or sign
        reason = str(error).strip().splitlines()[0][:160] if str(error).strip() else type(error).__name__
        raise ModelMissingError(f"The {what} config in '{where}' does not describe a model SceneFit can build "
                                f"({type(error).__name__}: {reason}).") from None
    too_much = memory_needed_sentence(parameters * bytes_per_parameter,
                                      f"The {what} in '{where}' ({parameters:,} parameters)")
    if too_much:
        raise ModelMissingError(f"{too_much}; its config asks for more than any model SceneFit reads.")
