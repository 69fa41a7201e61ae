"""Reading and writing images through OpenImageIO, atomically, with explicit colour spaces."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ..base.atomic import replace_atomic, temp_affixes
from ..base.errors import InputError
from ..base.quiet import native_output_captured


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def read_image(path: str | os.PathLike, max_side: int | None = None, upright: bool = False) -> np.ndarray:
    """Pixels as float32 (H, W, C) exactly as stored (8-bit files scaled to [0, 1], no colour change).

    upright: turn the pixels as the file's EXIF Orientation says, as a photo viewer shows them (a
    phone's portrait photo is stored sideways with Orientation 6). For photos only: textures are
    used as stored, as Blender and glTF viewers do.

    Colour channels of RGBA files are read as stored, not multiplied by alpha (OpenImageIO's
    default would darken them wherever alpha < 1).

    max_side: an image longer than this is reduced while it is read, band by band, by the whole
    factor k = ceil(long side / max_side) (each output pixel the mean of k x k stored ones, which keeps
    an HDR image's energy), so an 8000x6000 photo never sits in memory at full size.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"'{path}' is a folder, not an image; give the image file's path.")
    if not path.is_file():
        raise InputError(f"Image '{path}' does not exist.")
    pixels, orientation = _decoded(path, lambda inp: (*_read_reduced(inp, max_side),
                                                      inp.spec().get_int_attribute("Orientation", 1)))
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if upright and orientation in TURNED_ORIENTATIONS:
        pixels = _reoriented(pixels, orientation)
    return pixels


def _decoded(path: Path, read) -> tuple:
    """(pixels, extra) of `read(inp)` -> (pixels, the reader's error, extra) on `path` opened with its colour as
    stored (never multiplied by alpha); one sentence (InputError) when it does not open or decode whole."""
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    extra = None
    with native_output_captured() as chatter:
        inp = oiio.ImageInput.open(str(path), config)
        pixels = None
        if inp is not None:
            try:
                pixels, reason, extra = read(inp)
            finally:
                inp.close()
        else:
            reason = oiio.geterror()
    if pixels is None or reason:
        # A truncated JPEG still "decodes", its missing rows grey, with only an error left on the
        # reader ("Premature end of JPEG file"): any error while reading refuses the file.
        # libjpeg's errors repeat the path the message already names.
        reason = _first_line(reason).replace(f' ("{path}")', "") or chatter.last_line() or \
            "the file is empty, truncated or not an image"
        raise InputError(f"Image '{path}' cannot be {'read' if inp is None else 'decoded'} ({reason}); re-export it "
                         "as PNG, JPEG or EXR.")
    return pixels, extra


def read_texture_bytes(path: str | os.PathLike) -> np.ndarray:
    """An 8-bit texture's stored values, (H, W, C) uint8, colour as stored (never multiplied by alpha);
    one sentence when the file does not decode whole (a truncated JPEG's rows would come back grey)."""
    def stored(inp):
        spec = inp.spec()
        return inp.read_image(0, 0, 0, spec.nchannels, "uint8"), inp.geterror(), spec

    pixels, spec = _decoded(Path(path), stored)
    pixels = np.asarray(pixels, np.uint8)
    return pixels.reshape(spec.height, spec.width, spec.nchannels) if pixels.ndim != 3 else pixels


# Formats OpenImageIO and Blender both decode fully, so a file one refuses is damaged, not exotic.
CHECKED_FORMATS = {".png": b"\x89PNG", ".jpg": b"\xff\xd8", ".jpeg": b"\xff\xd8"}
# The long side an image is decoded at when only whether it decodes matters.
CHECK_SIDE = 256


def check_decodes(source: str | os.PathLike | bytes, shown: str) -> None:
    """Refuse (one sentence naming `shown`) a JPEG or PNG, a file or its bytes, that does not decode
    whole; other formats pass. For images another decoder reads (Blender shows a truncated JPEG with
    its missing rows grey and says nothing): the pixels are read reduced and dropped."""
    if isinstance(source, (bytes, bytearray)):
        kind = next((s for s, magic in CHECKED_FORMATS.items() if bytes(source[:4]).startswith(magic)), None)
        if kind is None:
            return
        fd, tmp = tempfile.mkstemp(suffix=kind)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(source)
            _check_file(Path(tmp), shown)
        finally:
            os.unlink(tmp)
        return
    path = Path(source)
    if path.suffix.lower() in CHECKED_FORMATS:
        _check_file(path, shown)


def _check_file(path: Path, shown: str) -> None:
    try:
        read_image(path, max_side=CHECK_SIDE)
    except InputError as error:
        raise InputError(str(error).replace(str(path), shown)) from None


# EXIF Orientation 2-8 turn or mirror the stored pixels (5-8 swap width and height); 1 is upright, and any
# other value (0, a file's own invention) is read as stored, as photo viewers do.
TURNED_ORIENTATIONS = range(2, 9)
SWAPPED_ORIENTATIONS = range(5, 9)


def _reoriented(pixels: np.ndarray, orientation: int) -> np.ndarray:
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    h, w, c = pixels.shape
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, c, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels))
    buf.specmod().attribute("Orientation", int(orientation))
    return np.asarray(oiio.ImageBufAlgo.reorient(buf).get_pixels(oiio.FLOAT), np.float32).reshape(
        (w, h, c) if orientation in SWAPPED_ORIENTATIONS else (h, w, c))


def stored_orientation(path: str | os.PathLike) -> int:
    """The file's EXIF Orientation (1: stored upright; 0 when it cannot be opened)."""
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return 0
    try:
        return inp.spec().get_int_attribute("Orientation", 1)
    finally:
        inp.close()


def upright_size(path: str | os.PathLike) -> tuple[int, int] | None:
    """(width, height) of the image as SceneFit reads it (EXIF Orientation 5-8 swap them), from its
    header alone; None when it cannot be opened."""
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return None
    try:
        spec = inp.spec()
        size = (int(spec.width), int(spec.height))
        return size[::-1] if spec.get_int_attribute("Orientation", 1) in SWAPPED_ORIENTATIONS else size
    finally:
        inp.close()


def reduction_factor(width: int, height: int, max_side: int | None) -> int:
    return 1 if not max_side or max(width, height) <= max_side else -(-max(width, height) // max_side)


def _read_reduced(inp, max_side: int | None, band_rows: int = 32) -> tuple[np.ndarray | None, str]:
    """The pixels (None when unreadable) and the reader's error text ("" when it read cleanly).

    The error is collected after every read: geterror() clears it, and a later band may read cleanly
    after an earlier one was cut short."""
    spec = inp.spec()
    w, h, c = spec.width, spec.height, spec.nchannels
    k = reduction_factor(w, h, max_side)
    if k == 1:
        pixels = inp.read_image("float")
        return pixels, inp.geterror()
    out_w, out_h = -(-w // k), -(-h // k)
    out = np.empty((out_h, out_w, c), np.float32)
    for row in range(0, out_h, band_rows):
        y0, y1 = row * k, min(h, (row + band_rows) * k)
        band = inp.read_scanlines(0, 0, y0 + spec.y, y1 + spec.y, 0, 0, c, "float")
        reason = inp.geterror()
        if band is None or reason:
            return None, reason
        band = np.asarray(band, np.float32).reshape(y1 - y0, w, c)
        rows = -(-(y1 - y0) // k)
        # Pad the last partial block by repeating the edge, then average k x k blocks.
        band = np.pad(band, ((0, rows * k - (y1 - y0)), (0, out_w * k - w), (0, 0)), mode="edge")
        out[row:row + rows] = band.reshape(rows, k, out_w, k, c).mean(axis=(1, 3))
    return out, ""


def _first_line(text: str) -> str:
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    return lines[0] if lines else ""


def read_color_image(path: str | os.PathLike, upright: bool = False) -> np.ndarray:
    """RGB as linear float32: 8/16-bit files are decoded from sRGB, float files (EXR/HDR) taken as linear.
    upright: as `read_image` (for photos)."""
    pixels = read_image(path, upright=upright)
    if pixels.shape[2] == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    rgb = pixels[..., :3]
    if Path(path).suffix.lower() in (".exr", ".hdr"):
        return np.ascontiguousarray(rgb, dtype=np.float32)
    return srgb_to_linear(rgb)


PNG_LEVEL = 3


def write_image(path: str | os.PathLike, pixels: np.ndarray, dtype: str | None = None,
                smallest: bool = False) -> Path:
    """Write through a temporary file in the same folder and rename, so no half-written file is seen.

    dtype: "uint8", "uint16", "half" or "float"; by default uint8 for PNG/JPEG and float for EXR/HDR.
    Values are written as given: convert colour spaces before calling.
    smallest: a PNG at zlib's highest level (slower to write; for files that ship, like a game bake).
    """
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if dtype is None:
        dtype = "float" if path.suffix.lower() in (".exr", ".hdr") else "uint8"
    if dtype in ("uint8", "uint16"):
        pixels = np.clip(pixels, 0.0, 1.0)
    h, w, c = pixels.shape
    fd, tmp = tempfile.mkstemp(**temp_affixes(path, keep_suffix=True))
    os.close(fd)
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise InputError(f"OpenImageIO cannot write '{path.suffix}' files: {oiio.geterror()}")
        spec = oiio.ImageSpec(w, h, c, dtype)
        if path.suffix.lower() == ".exr":
            spec.attribute("compression", "zip")
        spec.attribute("oiio:UnassociatedAlpha", 1)  # colour is stored as given, never divided by alpha
        # zlib level 3 unless asked for the smallest: half the time of the usual 6 for ~10% more bytes
        spec.attribute("png:compressionLevel", 9 if smallest else PNG_LEVEL)
        if not out.open(tmp, spec):
            raise InputError(f"Cannot open '{path}' for writing: {out.geterror()}")
        ok = out.write_image(np.ascontiguousarray(pixels))
        out.close()
        if not ok:
            raise InputError(f"Cannot write '{path}': {out.geterror()}")
        replace_atomic(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path
