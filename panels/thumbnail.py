"""The photo's thumbnail in the Scene section: read once when the photo is chosen (or a file is opened, unless
the same file was read already), at thumbnail size (a JPEG's reduced decode) in a reader thread of its own,
kept as a preview icon; drawing only looks the icon up, so a redraw never opens the file."""
from __future__ import annotations

from pathlib import Path

import numpy as np

THUMBNAIL_SIDE = 128
_previews = None                       # bpy.utils.previews collection, made on first use
_icons: dict[str, tuple] = {}          # resolved photo path -> (its mtime and size, read: True, False, None: decoding)
# OpenCV's reduced JPEG decodes (libjpeg's DCT scaling: 1/2, 1/4, 1/8 of each side, never decoded whole).
_REDUCED = ((8, "IMREAD_REDUCED_COLOR_8"), (4, "IMREAD_REDUCED_COLOR_4"), (2, "IMREAD_REDUCED_COLOR_2"))


def thumbnail_pixels(path: str, side: int = THUMBNAIL_SIDE) -> np.ndarray:
    """The photo at most `side` pixels a side, upright, RGB float in [0, 1]: a JPEG decoded reduced by the largest
    of 1/8, 1/4, 1/2 that keeps `side` (OpenCV; EXIF orientation applied), then averaged down; any other
    file through core's banded reader."""
    import cv2  # lazy: Blender may lack it (missing_modules)

    from ..core.data.imageio import read_image, upright_size

    if Path(path).suffix.lower() in (".jpg", ".jpeg"):
        size = upright_size(Path(path))
        if size is not None:
            factor, flag = next(((f, name) for f, name in _REDUCED if max(size) // f >= side), (1, "IMREAD_COLOR"))
            pixels = cv2.imdecode(np.fromfile(path, np.uint8), getattr(cv2, flag))
            if pixels is not None:
                h, w = pixels.shape[:2]
                scale = side / max(h, w)
                if scale < 1.0:
                    pixels = cv2.resize(pixels, (max(1, round(w * scale)), max(1, round(h * scale))),
                                        interpolation=cv2.INTER_AREA)
                return pixels[..., ::-1].astype(np.float32) / 255.0
    return read_image(path, max_side=side, upright=True)


def _resolved(text: str) -> str:
    import bpy

    return str(Path(bpy.path.abspath(text)))


def load_thumbnail(text: str) -> None:
    """Ask for the photo `text` names at most THUMBNAIL_SIDE a side, upright, as its preview: decoded in the
    reader thread (a 24 MP JPEG's reduced decode still takes a tenth of a second or more on a busy machine),
    put into the preview by the next draw or the main thread's timer. Once per file (its mtime and size): a
    file reopened, or another scene of the same photo, is not read again. Called when the photo is chosen
    or a file is opened, never while drawing."""
    global _reader
    import queue
    import threading

    if not text:
        return
    path = _resolved(text)
    try:
        stat = Path(path).stat()
        stamp = (stat.st_mtime_ns, stat.st_size)
    except OSError:
        _icons[path] = (None, False)
        return
    known = _icons.get(path)
    if known is not None and known[0] == stamp:
        return
    if _reader is None:
        _reader = queue.Queue()
        threading.Thread(target=_read_thumbnails, args=(_reader,), name="scenefit-thumbnails", daemon=True).start()
    done = threading.Event()
    _icons[path] = (stamp, None)
    _pending[path] = (done, [])
    _reader.put((path, done, _pending[path][1]))
    _watch()


# The reader thread lives as long as Blender (a thread that ends inside a C++ library while Python shuts down
# aborts the process): path -> (an Event set once decoded, [the pixels, or None when unreadable]).
_reader = None
_pending: dict[str, tuple] = {}


def _read_thumbnails(asked) -> None:
    from ..core.base.errors import SceneFitError

    while True:
        path, done, box = asked.get()
        try:
            box.append(thumbnail_pixels(path))
        except (SceneFitError, OSError, ValueError):
            box.append(None)
        except Exception:   # (any reader's failure leaves no thumbnail, never the thread stopped)
            box.append(None)
        done.set()


def _watch() -> None:
    """Poll for decoded thumbnails on Blender's main thread (a timer; without an event loop, drawing does it)."""
    import bpy

    if not bpy.app.timers.is_registered(_apply_ready):
        bpy.app.timers.register(_apply_ready, first_interval=0.05, persistent=True)


def _apply_ready() -> float | None:
    """Put every decoded thumbnail into its preview (main thread); again in 0.1 s while any is still decoding."""
    import bpy

    shown = False
    for path, (done, box) in list(_pending.items()):
        if done.is_set():
            del _pending[path]
            _show(path, box[0])
            shown = True
    if shown and bpy.context.window_manager is not None:
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
    return 0.1 if _pending else None


def _show(path: str, pixels) -> None:
    global _previews
    import bpy.utils.previews

    stamp = _icons.get(path, (None, None))[0]
    if pixels is None:
        _icons[path] = (stamp, False)
        return
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
    _icons[path] = (stamp, True)


def wait_for_thumbnails(timeout: float | None = None) -> None:
    """Wait until every thumbnail asked for is decoded and shown (scripts and tests, which have no event loop)."""
    for done, _ in list(_pending.values()):
        done.wait(timeout)
    _apply_ready()


def thumbnail(text: str):
    """The preview of the photo `text` names when it was read (None otherwise, and while it is decoded): no
    file access; a thumbnail decoded since the last draw is put into its preview here."""
    if not text:
        return None
    if _pending:
        _apply_ready()
    if _previews is None:
        return None
    path = _resolved(text)
    known = _icons.get(path)
    return _previews[path] if known is not None and known[1] else None


def clear_thumbnails() -> None:
    global _previews
    import bpy.utils.previews

    import bpy

    _icons.clear()
    _pending.clear()
    if bpy.app.timers.is_registered(_apply_ready):
        bpy.app.timers.unregister(_apply_ready)
    if _previews is not None:
        bpy.utils.previews.remove(_previews)
        _previews = None
