"""Whether a finished stage's float images (the light map, a linear composite) hold only finite
numbers: a stage folder from elsewhere (--reuse-from, a worker, someone's run folder) is data, and a
light.exr of NaN reused as it is would light every later render with NaN."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.errors import InputError
from .imageio import read_image

# The outputs stored as floats; 8- and 16-bit images cannot hold a non-finite number.
FLOAT_IMAGE_SUFFIXES = (".exr", ".hdr")


def finite_images(paths: list[str | Path]) -> bool:
    """True when every float image among `paths` reads and holds only finite values."""
    for path in paths:
        if Path(path).suffix.lower() not in FLOAT_IMAGE_SUFFIXES:
            continue
        try:
            if not np.isfinite(read_image(path)).all():
                return False
        except InputError:
            return False
    return True
