"""Where the object goes in the photo: the one placement every stage reads.

`--at X,Y` on every command and the Blender panel's placement mean the object's centre in the
photo, as fractions of its width and height (values above 1 are read as pixels); `--object-size` is
the fraction of the photo's height the asset spans. The light stage casts its floor ray through the
centre (core/scene/floor.py `place_on_floor`); the compose stage stands the asset on the floor
there (core/scene/asset_pose.py `place_asset`), and the adapt stage's global views are that composite
(core/stages/adapt/global_views.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..base.errors import InputError


# The one default of every entry point (the command line, the Blender panel, batch jobs, adapt's
# global views): where the asset stands, and its height as a fraction of the photo's height.
DEFAULT_AT = (0.5, 0.6)


DEFAULT_OBJECT_SIZE = 0.3


@dataclass(frozen=True)
class Placement:
    """center: (x, y) fractions of the photo's width and height; size: the asset's height / photo height."""

    center: tuple[float, float] = DEFAULT_AT
    size: float = DEFAULT_OBJECT_SIZE

    def __post_init__(self) -> None:
        x, y = self.center
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            raise InputError(f"The placement {self.center} lies outside the photo; give fractions in [0, 1].")
        if not 0.0 < self.size <= 1.0:
            raise InputError(f"The object's size must be a fraction of the photo's height in (0, 1], got {self.size}.")
        object.__setattr__(self, "center", (float(x), float(y)))

    @classmethod
    def parse(cls, at: str | tuple[float, float], photo_wh: tuple[int, int], size: float = DEFAULT_OBJECT_SIZE,
              what: str = "--at") -> "Placement":
        """From `X,Y` (or a pair): fractions of the width and height when both are <= 1, pixels of the
        photo as stored (photo_wh, upright) when both are > 1. `what` names the point in errors."""
        x, y = parse_point(at, what)
        width, height = photo_wh
        if x > 1.0:
            if not (x <= width and y <= height):
                said = "The placement" if what == "--at" else what
                raise InputError(f"{said} ({x:g}, {y:g}) lies outside the {width}x{height} photo.")
            x, y = x / width, y / height
        return cls((x, y), size)

    def pixel(self, photo_hw: tuple[int, int]) -> tuple[float, float]:
        """The centre in photo pixels (x right, y down)."""
        h, w = photo_hw
        return self.center[0] * w, self.center[1] * h


def parse_point(at: str | tuple[float, float], what: str = "--at") -> tuple[float, float]:
    """`--at X,Y` checked on its own (the photo's size checks the rest): two finite, non-negative numbers,
    both fractions (<= 1) or both pixels (> 1). A mix such as 1.5,0.5 is a typo more often than a
    pixel on the photo's top edge, so it is refused rather than guessed."""
    try:
        x, y = (float(v) for v in (at.split(",") if isinstance(at, str) else at))
    except (TypeError, ValueError):
        raise InputError(f"{what} takes X,Y (fractions of the photo's width and height, e.g. 0.5,0.7, or pixels), "
                         f"got {at!r}.") from None
    if not (math.isfinite(x) and math.isfinite(y) and x >= 0.0 and y >= 0.0):
        raise InputError(f"{what} takes two finite, non-negative numbers, got {at!r}.")
    if (x <= 1.0) != (y <= 1.0):
        raise InputError(f"{what} {x:g},{y:g} mixes a fraction and a pixel position; give both as fractions of the "
                         f"photo's width and height (0 to 1) or both in pixels.")
    return x, y
