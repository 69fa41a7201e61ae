"""Resource limits checked before any work: a render or texture too large for memory is one sentence
up front, not a run that swaps for minutes and is killed (a 16384² map stack took 21 GB)."""
from __future__ import annotations

import os

from .errors import InputError

# The largest square render side. Mitsuba's symbolic path tracer keeps no per-sample state, so a
# render's memory is its film and the copies made of it (measured: about 80 bytes per pixel for
# `scenefit render`), and 8192² is 5 GB already; nothing SceneFit makes needs more.
MAX_RENDER_SIDE = 8192
# The composite is made at the photo's own size up to this long side (a 24 MP photo is halved), which keeps
# the compose stage's memory near 1.5 GB; the Compose button's Cycles render at a preset is capped alike (a
# preset may ask for less: core/pipeline/preset_tables.py).
COMPOSE_MAX_SIDE = 4096
RENDER_BYTES_PER_PIXEL = 80
# The loop renderer keeps a G-buffer per view: 16 sub-pixel samples (more on edges), each with its texel taps,
# weights, light terms at every roughness level, and numpy's working copies while it is traced (measured:
# 10.8 KB per pixel of peak memory between 128² and 384² views, benchmarks/FINDINGS.md).
LOOP_RENDER_BYTES_PER_PIXEL = 11_000
# A (H, W, 5) float32 map stack, with the copies alive while it is resampled, clipped and handed to
# Mitsuba as three bitmaps.
STACK_BYTES_PER_TEXEL = 5 * 4 * 4
# The share of the machine's memory one stack or render may take (the models, the mesh and Python
# need the rest).
MEMORY_SHARE = 0.5


def physical_memory() -> int | None:
    """This machine's memory in bytes (None where the OS does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        return None


def _gb(n: float) -> str:
    return f"{n / 2**30:.1f} GB" if n >= 2**30 else f"{n / 2**20:.0f} MB"


def check_render_size(width: int, height: int, option: str = "--size",
                      bytes_per_pixel: int = RENDER_BYTES_PER_PIXEL) -> None:
    """Refuse a render larger than MAX_RENDER_SIDE or than this machine's memory allows (at `bytes_per_pixel`:
    the path tracer's, or LOOP_RENDER_BYTES_PER_PIXEL for the loop renderer's)."""
    if max(width, height) > MAX_RENDER_SIDE:
        raise InputError(f"{option} {max(width, height)} is larger than {MAX_RENDER_SIDE} px, the most SceneFit "
                         f"renders (one view of {MAX_RENDER_SIDE}x{MAX_RENDER_SIDE} pixels already takes about "
                         f"{_gb(MAX_RENDER_SIDE ** 2 * RENDER_BYTES_PER_PIXEL)} of memory); give a smaller {option}.")
    _check_memory(width * height * bytes_per_pixel, f"Rendering {width}x{height} pixels",
                  f"give a smaller {option}")


def check_texture_size(height: int, width: int, what: str) -> None:
    """Refuse a map stack of (height, width) texels that would not fit in this machine's memory."""
    _check_memory(height * width * STACK_BYTES_PER_TEXEL, f"Rendering {what} at {width}x{height} texels",
                  "reduce the texture (4096 px is plenty for SceneFit) and try again")


def memory_needed_sentence(needed: int, doing: str) -> str | None:
    """"{doing} needs about N GB of memory, more than half of this machine's M GB" when it does, else None."""
    total = physical_memory()
    if total is not None and needed > MEMORY_SHARE * total:
        return f"{doing} needs about {_gb(needed)} of memory, more than half of this machine's {_gb(total)}"
    return None


def _check_memory(needed: int, doing: str, fix: str) -> None:
    too_much = memory_needed_sentence(needed, doing)
    if too_much:
        raise InputError(f"{too_much}; {fix}.")
