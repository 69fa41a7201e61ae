"""Where the object goes in the photo: the one placement every stage reads.

`--at X,Y` on every command and the Blender panel's placement mean the object's centre in the
photo, as fractions of its width and height (values above 1 are read as pixels); `--size` is the
fraction of the photo's height the asset spans. The light stage casts its floor ray through the
centre (core/lighting/panorama.py `place_on_floor`); the compose stage stands the asset on the floor
there (core/compose.py `place_asset`), and the adapt stage's global views are that composite
(core/adapt/global_views.py). `box` is the square the light stage's critic views are cut around.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import InputError

DEFAULT_AT = (0.5, 0.6)
DEFAULT_SIZE = 0.4


@dataclass(frozen=True)
class Placement:
    """center: (x, y) fractions of the photo's width and height; size: the square's side / photo height."""

    center: tuple[float, float] = DEFAULT_AT
    size: float = DEFAULT_SIZE

    def __post_init__(self) -> None:
        x, y = self.center
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            raise InputError(f"The placement {self.center} lies outside the photo; give fractions in [0, 1].")
        if not 0.0 < self.size <= 1.0:
            raise InputError(f"The object's size must be a fraction of the photo's height in (0, 1], got {self.size}.")
        object.__setattr__(self, "center", (float(x), float(y)))

    @classmethod
    def parse(cls, at: str | tuple[float, float], photo_wh: tuple[int, int], size: float = DEFAULT_SIZE) -> "Placement":
        """From `X,Y` (or a pair): fractions of the width and height when both are <= 1, else pixels."""
        if isinstance(at, str):
            try:
                x, y = (float(v) for v in at.split(","))
            except ValueError:
                raise InputError(f"--at takes X,Y (fractions of the photo's width and height, or pixels), "
                                 f"got {at!r}.") from None
        else:
            x, y = (float(v) for v in at)
        width, height = photo_wh
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            if not (0.0 <= x <= width and 0.0 <= y <= height):
                raise InputError(f"The placement ({x:g}, {y:g}) lies outside the {width}x{height} photo.")
            x, y = x / width, y / height
        return cls((x, y), size)

    def pixel(self, photo_hw: tuple[int, int]) -> tuple[float, float]:
        """The centre in photo pixels (x right, y down)."""
        h, w = photo_hw
        return self.center[0] * w, self.center[1] * h

    def box(self, photo_hw: tuple[int, int]) -> tuple[float, float, float]:
        """(x0, y0, side) of the object's square in photo pixels."""
        h, w = photo_hw
        side = self.size * h
        return self.center[0] * w - side / 2, self.center[1] * h - side / 2, side
