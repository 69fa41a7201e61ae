"""Whether a finished stage's float outputs (the light map, a linear composite, a neural texture's
tensors) hold only finite numbers: a stage folder from elsewhere (--reuse-from, a worker, someone's run
folder) is data, and a light.exr or texture.pt of NaN reused as it is would carry NaN into every later
render."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from .imageio import read_image

# The outputs stored as floats; 8- and 16-bit images cannot hold a non-finite number.
FLOAT_IMAGE_SUFFIXES = (".exr", ".hdr")
TENSOR_SUFFIXES = (".pt",)


def finite_outputs(paths: Sequence[str | Path]) -> bool:
    """True when every float image and tensor file among `paths` reads and holds only finite values."""
    for path in paths:
        suffix = Path(path).suffix.lower()
        try:
            if suffix in FLOAT_IMAGE_SUFFIXES and not np.isfinite(read_image(path)).all():
                return False
            if suffix in TENSOR_SUFFIXES and not _finite_tensors(path):
                return False
        except InputError:
            return False
    return True


def _finite_tensors(path: str | Path) -> bool:
    import torch  # lazy: seconds to import, and only a reused stage with a texture needs it

    try:   # (weights_only: the restricted unpickler, which runs no code from the file)
        saved = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:   # any damage: not a finished stage, it runs again
        return False
    pending = [saved]
    while pending:
        value = pending.pop()
        if isinstance(value, torch.Tensor):
            if value.is_floating_point() and not bool(torch.isfinite(value).all()):
                return False
        elif isinstance(value, dict):
            pending.extend(value.values())
        elif isinstance(value, (list, tuple)):
            pending.extend(value)
    return True
