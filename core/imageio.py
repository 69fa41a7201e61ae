"""Reading and writing images through OpenImageIO, atomically, with explicit colour spaces."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .atomic import replace_atomic
from .errors import InputError


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Pixels as float32 (H, W, C) exactly as stored (8-bit files scaled to [0, 1], no colour change)."""
    import OpenImageIO as oiio

    path = Path(path)
    if not path.is_file():
        raise InputError(f"Image '{path}' does not exist.")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"Image '{path}' cannot be read: {oiio.geterror()}")
    try:
        pixels = inp.read_image("float")
    finally:
        inp.close()
    if pixels is None:
        raise InputError(f"Image '{path}' cannot be decoded: {oiio.geterror()}")
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    return pixels


def read_color_image(path: str | os.PathLike) -> np.ndarray:
    """RGB as linear float32: 8/16-bit files are decoded from sRGB, float files (EXR/HDR) taken as linear."""
    pixels = read_image(path)
    if pixels.shape[2] == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    rgb = pixels[..., :3]
    if Path(path).suffix.lower() in (".exr", ".hdr"):
        return np.ascontiguousarray(rgb, dtype=np.float32)
    return srgb_to_linear(rgb)


def write_image(path: str | os.PathLike, pixels: np.ndarray, dtype: str | None = None) -> Path:
    """Write through a temporary file in the same folder and rename, so no half-written file is seen.

    dtype: "uint8", "uint16", "half" or "float"; by default uint8 for PNG/JPEG and float for EXR/HDR.
    Values are written as given: convert colour spaces before calling.
    """
    import OpenImageIO as oiio

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
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise InputError(f"OpenImageIO cannot write '{path.suffix}' files: {oiio.geterror()}")
        spec = oiio.ImageSpec(w, h, c, dtype)
        if path.suffix.lower() == ".exr":
            spec.attribute("compression", "zip")
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
