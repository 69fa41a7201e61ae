"""The photo's thumbnail in the Scene section: read once when the photo is chosen (or a file is opened),
kept as a preview icon; drawing only looks the icon up, so a redraw never opens the file."""
from __future__ import annotations

from pathlib import Path

import numpy as np

THUMBNAIL_SIDE = 128
_previews = None                       # bpy.utils.previews collection, made on first use
_icons: dict[str, bool] = {}           # resolved photo path -> whether its preview holds the photo


def _resolved(text: str) -> str:
    import bpy

    return str(Path(bpy.path.abspath(text)))


def load_thumbnail(text: str) -> bool:
    """Read the photo `text` names (at most THUMBNAIL_SIDE a side, upright) into its preview; False when
    the file cannot be read. Called when the photo is chosen, never while drawing."""
    global _previews
    import bpy.utils.previews

    from ..core.base.errors import SceneFitError
    from ..core.data.imageio import read_image

    if not text:
        return False
    path = _resolved(text)
    try:
        pixels = read_image(path, max_side=THUMBNAIL_SIDE, upright=True)
    except (SceneFitError, OSError, ValueError):
        _icons[path] = False
        return False
    if _previews is None:
        _previews = bpy.utils.previews.new()
    item = _previews.get(path) or _previews.new(path)
    h, w = pixels.shape[:2]
    channels = pixels.shape[2] if pixels.ndim == 3 else 1
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = np.clip(pixels.reshape(h, w, channels)[..., :3] if channels >= 3 else
                            np.repeat(pixels.reshape(h, w, channels)[..., :1], 3, axis=2), 0.0, 1.0)
    item.image_size = (w, h)
    item.image_pixels_float = rgba[::-1].ravel()   # Blender's first row is the bottom one
    _icons[path] = True
    return True


def thumbnail(text: str):
    """The preview of the photo `text` names when it was read (None otherwise): no file access."""
    if not text or _previews is None:
        return None
    path = _resolved(text)
    return _previews[path] if _icons.get(path) else None


def clear_thumbnails() -> None:
    global _previews
    import bpy.utils.previews

    _icons.clear()
    if _previews is not None:
        bpy.utils.previews.remove(_previews)
        _previews = None
