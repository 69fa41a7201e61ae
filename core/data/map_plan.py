"""An asset's maps planned on Blender's main thread and computed in a job's worker.

Reading a material's node facts needs bpy; decoding its image files does not, and takes long. So the
reading is split: the main thread builds each map as a small tree of `Deferred` steps whose leaves are
`Source`s (a texture file to decode, pixels Blender alone holds, a Cycles bake done between redraws),
and `resolve` computes the tree anywhere, bit for bit what the same steps give on the main thread.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..base.errors import InputError
from .imageio import check_decodes, read_texture_bytes, srgb_to_linear
from .map_steps import STEPS
from .maps import PBRMaps
from .materials import AssetMaterials, Material
from .mesh import Mesh


class Source:
    """A leaf of a map's tree: pixels that `pixels()` gives, wherever it is called."""

    def pixels(self) -> np.ndarray:
        raise NotImplementedError


@dataclass(frozen=True)
class Deferred:
    """The step named `step` (core/data/map_steps.STEPS) of `args`, once every argument is computed."""

    step: str
    args: tuple


def is_pending(value: object) -> bool:
    return isinstance(value, (Deferred, Source))


def later(step: str, *args: Any) -> Any:
    """The step of `args` now when no argument waits for pixels (constants, small), else a Deferred step."""
    if any(is_pending(a) for a in args):
        return Deferred(step, args)
    return STEPS[step](*args)


def resolve(value: Any) -> Any:
    """The value of a tree of Deferred steps and Sources (a plain value is its own)."""
    if isinstance(value, Deferred):
        return STEPS[value.step](*(resolve(a) for a in value.args))
    if isinstance(value, Source):
        return value.pixels()
    return value


# 8-bit PNG and JPEG files decode to the same bytes here as in Blender's own readers (checked on the corpus).
FILE_MAGIC = {b"\x89PNG": ".png", b"\xff\xd8": ".jpg"}


@dataclass(frozen=True)
class TextureFile(Source):
    """A texture's stored bytes (a file, or what a .blend / .glb packs) decoded as Blender would:
    (H, W, 4) float32 rows top first, 8-bit values x (1/255), sRGB undone when `decode_srgb`."""

    name: str                     # how a sentence names it (the path, or Blender's image name when packed)
    path: str = ""
    packed: bytes | None = field(default=None, repr=False)
    decode_srgb: bool = True

    def pixels(self) -> np.ndarray:
        if self.packed is None:
            stored = _decoded(Path(self.path), self.name)
        else:
            suffix = next((s for m, s in FILE_MAGIC.items() if self.packed.startswith(m)), ".png")
            fd, tmp = tempfile.mkstemp(suffix=suffix)
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(self.packed)
                stored = _decoded(Path(tmp), self.name)
            finally:
                os.unlink(tmp)
        return rgba_linear(stored, self.decode_srgb)


def _decoded(path: Path, shown: str) -> np.ndarray:
    try:
        return read_texture_bytes(path)
    except InputError as error:
        raise InputError(str(error).replace(str(path), shown)) from None


def rgba_linear(stored: np.ndarray, decode_srgb: bool) -> np.ndarray:
    """(H, W, C) uint8 -> (H, W, 4) float32 as Blender's image.pixels gives it (grey spread over RGB,
    alpha 1 where there is none), the sRGB transfer undone when `decode_srgb`."""
    h, w, c = stored.shape
    pixels = stored.astype(np.float32) * np.float32(1.0 / 255.0)   # Blender's byte -> float
    if c < 3:
        pixels = np.concatenate([np.repeat(pixels[..., :1], 3, axis=2), pixels[..., 1:2]], axis=2)
    if pixels.shape[2] == 3:
        pixels = np.concatenate([pixels, np.ones((h, w, 1), np.float32)], axis=2)
    pixels = np.ascontiguousarray(pixels)
    if decode_srgb:
        pixels[..., :3] = srgb_to_linear(pixels[..., :3])
    return pixels


@dataclass(frozen=True)
class CheckedPixels(Source):
    """Pixels Blender holds, copied on the main thread; their stored file (or packed bytes) is checked in
    the job to decode whole (Blender shows a truncated JPEG's missing rows grey and says nothing)."""

    held: np.ndarray = field(repr=False)
    stored: str | bytes | None = field(default=None, repr=False)
    name: str = ""

    def pixels(self) -> np.ndarray:
        if self.stored is not None:
            check_decodes(self.stored, self.name)
        return self.held


@dataclass(frozen=True)
class PendingMaterial:
    """A Material whose maps are still a tree (see the module's docstring)."""

    name: str
    maps: Any
    read: tuple[str, ...] = ()
    kept: tuple[str, ...] = ()
    dropped: tuple[str, ...] = ()
    alpha_mode: str = "OPAQUE"
    wrap: tuple[str, str] = ("repeat", "repeat")

    def resolved(self) -> Material:
        maps = resolve(self.maps)
        if not isinstance(maps, PBRMaps):
            raise TypeError(f"material '{self.name}' resolved to {type(maps).__name__}, not PBRMaps")
        return Material(name=self.name, maps=maps, read=self.read, kept=self.kept, dropped=self.dropped,
                        alpha_mode=self.alpha_mode, wrap=self.wrap)


@dataclass
class PendingAsset:
    """An AssetMaterials planned on the main thread. `bakes`: the Cycles bakes the main thread still owes,
    one per timer tick (each has `run()` and `words`); `resolved()` in the job decodes everything else."""

    mesh: Mesh
    materials: tuple[PendingMaterial, ...]
    notes: tuple[str, ...] = ()
    bakes: list = field(default_factory=list)

    def for_job(self) -> PlannedAsset:
        """The plan as plain data for a job's worker: each bake (all run by now) as the pixels it baked."""
        waiting = [b for b in self.bakes if not b.done]
        if waiting:
            raise RuntimeError(f"{len(waiting)} bake(s) of the asset's procedural inputs were not run")
        return PlannedAsset(mesh=self.mesh, notes=self.notes, materials=tuple(
            replace(m, maps=_baked_in(m.maps)) for m in self.materials))

    def resolved(self) -> AssetMaterials:
        return self.for_job().resolved()


@dataclass(frozen=True)
class PlannedAsset:
    """A PendingAsset handed to a job: plain data (frozen dataclasses, arrays, bytes, names of steps)."""

    mesh: Mesh
    materials: tuple[PendingMaterial, ...]
    notes: tuple[str, ...] = ()

    def resolved(self) -> AssetMaterials:
        return AssetMaterials(mesh=self.mesh, materials=tuple(m.resolved() for m in self.materials),
                              notes=self.notes)


def _baked_in(value: Any) -> Any:
    """`value`'s tree with every leaf only the main thread can compute (a bake) replaced by its pixels."""
    if isinstance(value, Deferred):
        return Deferred(value.step, tuple(_baked_in(a) for a in value.args))
    if isinstance(value, Source) and not isinstance(value, (TextureFile, CheckedPixels)):
        return value.pixels()
    return value


def fitting_inputs(data: dict) -> tuple[Mesh, PBRMaps]:
    """(mesh, maps) a job fits: data['asset'] (planned, or read) as its fitting view (one material as it is,
    several as their atlas), else a script's own data['mesh'] and data['maps']."""
    if data.get("asset") is not None:
        return resolved_asset(data["asset"]).fitting_view()
    return data["mesh"], data["maps"]


def resolved_asset(value: PendingAsset | PlannedAsset | AssetMaterials) -> AssetMaterials:
    """The asset's materials, whichever side read them."""
    return value if isinstance(value, AssetMaterials) else value.resolved()
