"""Baking a neural texture into game-ready maps, one set per material in the asset's own UV layout.

This is the part of `scenefit bake` that needs no Blender: the network is evaluated on each
material's faces, rasterised in that material's UVs at a power-of-two size, and quantised to
the 8 bits glTF stores (base colour sRGB, roughness/metallic linear). A channel that is constant
over the material's texels becomes a factor instead of an image. blender_io.gltf_export puts
these maps into the asset's materials and writes glTF 2.0 with Blender's exporter.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from ...base.errors import InputError
from ...data.imageio import linear_to_srgb
from ...data.maps import PBRMaps
from ...data.materials import atlas_grid, atlas_slices, material_submesh
from ...texture.surface_layout import own_uvs_at, uv_sharing
from ...data.mesh import Mesh, normalize_to_unit_sphere
from ...texture.bake import bake_texture
from ...texture.neural_texture import NeuralTexture, to_logit
from ...data.uv_raster import rasterize_uv, sample_image

# A channel whose covered texels all lie within this many 8-bit steps of each other is a constant.
CONSTANT_SPREAD = 1
# A channel that was a constant in the asset stays a factor while the fitted values scatter less
# than this (standard deviation; a draft fit of a constant scatters by about 0.015). A texture
# that adaptation really varied scatters more and is written as an image.
CONSTANT_SCATTER = 0.04


@dataclass(frozen=True)
class BakedMaterial:
    """One material's maps as written to glTF.

    base_color: (N, N, 3) uint8 sRGB bytes. roughness, metallic: (N, N) uint8 linear bytes, or a
    float in [0, 1] when the channel is constant (it becomes glTF's roughnessFactor / metallicFactor).
    coverage: fraction of texels inside the material's UV triangles.
    wrap: how its UVs outside [0, 1] read the maps, (u, v): what the exported sampler must say.
    """

    name: str
    base_color: np.ndarray
    roughness: np.ndarray | float
    metallic: np.ndarray | float
    coverage: float
    wrap: tuple[str, str] = ("repeat", "repeat")
    # The channels ("base_color", "roughness", "metallic") whose baked maps are what the material already
    # gives (see unchanged_channels): its own nodes are written for them, not a re-encoded copy.
    unchanged: frozenset = frozenset()
    # Baked in a new UV map (an adapted texture on UVs that share texels, core.surface_layout): its name,
    # and each texel's UV in the material's own map (so its other images, alpha, can be carried over).
    uv_map: str | None = None
    own_uv: np.ndarray | None = None

    def report(self) -> dict:
        def describe(value):
            return "texture" if isinstance(value, np.ndarray) else f"factor {value:.4g}"

        height, width = self.base_color.shape[:2]
        return {"name": self.name, "size": int(max(height, width)), "width": int(width), "height": int(height),
                "uv_coverage": round(self.coverage, 4),
                "base_color": "texture (sRGB)", "roughness": describe(self.roughness),
                "metallic": describe(self.metallic), "wrap": list(self.wrap),
                **({"uv_map": self.uv_map} if self.uv_map else {})}


def check_texture_size(size: int) -> int:
    if not isinstance(size, (int, np.integer)) or size < 4 or size > 8192 or size & (size - 1):
        raise InputError(f"--texture-size must be a power of two between 4 and 8192, got {size}.")
    return int(size)


def default_texture_size(texture: NeuralTexture, material_count: int) -> int:
    """The size each material was fitted at (its atlas cell), rounded up to a power of two."""
    cell = max(4, texture.config.resolution // atlas_grid(material_count))
    return min(8192, 1 << (cell - 1).bit_length())


def _channel(plane: np.ndarray, mask: np.ndarray, original: float | None) -> np.ndarray | float:
    """8-bit linear bytes, or one value when the channel is constant (see CONSTANT_SCATTER).

    original: the value the asset gave this channel when it was a plain number. A fit of a constant
    scatters around it, so a fitted mean within that scatter is the asset's own value, written exactly
    (a metallic of 0 stays 0, not the fit's 0.0033); one that moved further (adaptation) is the mean."""
    plane = np.clip(plane, 0.0, 1.0)
    data = np.round(plane * 255.0).astype(np.uint8)
    covered = data[mask]
    if not covered.size:
        return data
    mean = float(plane[mask].mean())
    flat = int(covered.max()) - int(covered.min()) <= CONSTANT_SPREAD
    if original is not None and (flat or float(plane[mask].std()) <= CONSTANT_SCATTER):
        return float(original) if abs(mean - float(original)) <= CONSTANT_SCATTER else round(mean, 4)
    return round(mean, 4) if flat else data


def own_texture_shape(maps: PBRMaps, cap: int) -> tuple[int, int]:
    """A material's bake shape (height, width): its own base colour's sides each rounded up to a power
    of two, halved together while the longer is over `cap` (--max-texture), so a 2k texture bakes at 2k
    whatever size the preset adapted at, and a 2048x512 strip stays a strip."""
    cap = check_texture_size(cap)
    height, width = (1 << (max(4, side) - 1).bit_length() for side in maps.resolution)
    while max(height, width) > cap:
        height, width = max(4, height // 2), max(4, width // 2)
    return height, width


def bake_shapes(own_maps: list[PBRMaps], texture_size: int | None, cap: int) -> list[int | tuple[int, int]]:
    """Each material's bake size for bake_game_maps: `texture_size`² for all when given (within `cap`),
    else each at its own images' shape (own_texture_shape). The command line and Bake Asset alike."""
    return [min(texture_size, cap) if texture_size else own_texture_shape(maps, cap) for maps in own_maps]


def own_base_logit(texture: NeuralTexture, own_stack: np.ndarray):
    """A residual texture's base taken from the material's own maps (`own_stack`: PBRMaps.stacked_at
    the bake's size, not the copy the texture stores at its preset's resolution), as logits; None for a
    texture without a base."""
    if not texture.config.residual:
        return None
    stack = torch.from_numpy(np.clip(own_stack, 0.0, 1.0).astype(np.float32))
    return to_logit(stack, torch.tensor(texture.config.channel_min), torch.tensor(texture.config.channel_max))


def material_base(texture: NeuralTexture, index: int, count: int, size: int):
    """A residual texture's base for material `index`'s own UV square at size²: its atlas cell (the
    whole texture for one material) resampled; None for a texture without a base."""
    if not texture.config.residual:
        return None
    cell = texture.config.resolution // atlas_grid(count)
    rows, cols = atlas_slices(count, cell)[index]
    return texture.base_logit_at(rows, cols, size)


# A baked map within this many 8-bit steps of the material's own map on every covered texel is that map:
# the float round trip of an unchanged map (the exact start, nothing adapted) moves a texel by one.
UNCHANGED_STEPS = 1


def unchanged_channels(baked: BakedMaterial, own: PBRMaps, own_stack: np.ndarray, covered: np.ndarray,
                       config) -> frozenset:
    """The channels whose baked bytes are the material's own maps (read through its nodes: factors,
    texture transforms, vertex colours and all) on every covered texel, to UNCHANGED_STEPS. Own values
    outside what the texture holds (config's ranges: a roughness of 0 comes back as 0.03) count as held.
    A map baked smaller than the material's own image is never unchanged: the size asked for wins."""
    ranges = {"base_color": config.base_color_range, "roughness": config.roughness_range,
              "metallic": config.metallic_range}
    planes = {"base_color": (own_stack[..., 0:3], baked.base_color), "roughness": (own_stack[..., 3], baked.roughness),
              "metallic": (own_stack[..., 4], baked.metallic)}
    same = set()
    for name, (mine, written) in planes.items():
        native = getattr(own, name)
        if isinstance(native, np.ndarray) and any(n > b for n, b in zip(native.shape[:2], baked.base_color.shape[:2])):
            continue   # baked smaller than the material's image (--texture-size, --max-texture): a new image
        lo, hi = ranges[name]
        mine = np.clip(mine, lo, hi)
        mine = np.round((linear_to_srgb(mine) if name == "base_color" else mine) * 255.0)
        written = np.broadcast_to(np.asarray(written if isinstance(written, np.ndarray) else
                                             np.round(float(written) * 255.0), np.float64), mine.shape)
        if name != "base_color":   # a factor written as the asset gave it (0 where the texture held 0.03)
            written = np.clip(written, np.round(lo * 255.0), np.round(hi * 255.0))
        if np.abs(mine[covered] - written[covered]).max(initial=0.0) <= UNCHANGED_STEPS:
            same.add(name)
    return frozenset(same)


def bake_game_maps(texture: NeuralTexture, mesh: Mesh, names: list[str], size: int | list[int | tuple[int, int]],
                   constants: list[dict[str, float]] | None = None,
                   wraps: list[tuple[str, str]] | None = None,
                   own_maps: list[PBRMaps] | None = None, remapped: Mesh | None = None,
                   remap: frozenset = frozenset(), uv_map: str | None = None) -> list[BakedMaterial]:
    """Every material's maps at `size`² (or size[i] for material i: a side, or (height, width)) in its
    own UV layout.

    `mesh` is the asset as read (with material_index for several materials, in object space); it is
    normalised here exactly as for fitting, so the network sees the same points. constants[i]
    maps the channels ("roughness", "metallic") that were plain values in material i to those values.
    wraps[i]: how material i's UVs outside [0, 1] read its maps (its sampler; default repeat), as
    convert fitted them. own_maps[i]: material i's own maps, the base of a residual texture at full
    detail (without them the base is the texture's stored copy, resampled).
    remap: the materials baked into the new UV map `uv_map` instead (materials_to_remap), whose UVs are
    `remapped`'s (the same asset read with that map active: the same faces in the same order).
    """
    shapes = [tuple(check_texture_size(side) for side in (s if isinstance(s, tuple) else (s, s)))
              for s in (size if isinstance(size, list) else [size] * len(names))]
    if len(names) != mesh.material_count:
        raise InputError(f"Mesh '{mesh.name}' uses {mesh.material_count} materials, but {len(names)} names "
                         "were given.")
    normalized, _ = normalize_to_unit_sphere(mesh)
    baked = []
    for index, name in enumerate(names):
        wrap = (wraps[index][0], wraps[index][1]) if wraps else ("repeat", "repeat")
        height, width = shapes[index]
        if index in remap:
            baked.append(_remapped_material(texture, normalized, remapped, index, name, max(height, width), wrap,
                                            own_maps[index] if own_maps else None, constants[index] if constants else {},
                                            uv_map))
            continue
        raster = rasterize_uv(material_submesh(normalized, index), height, width, wrap=wrap)
        own_stack = own_maps[index].stacked_at(height, width) if own_maps else None   # resized once, used twice
        if own_stack is not None:
            base = own_base_logit(texture, own_stack)
        else:   # (the texture's own copy is square: a square bake)
            if height != width:
                raise InputError(f"A {width}x{height} bake needs the material's own maps; give a square size.")
            base = material_base(texture, index, len(names), height)
        maps = bake_texture(texture, raster.position, raster.border, raster.fill_index, base)
        material = _baked_material(name, maps, raster, constants[index] if constants else {}, wrap)
        if own_maps and own_stack is not None:
            material = replace(material, unchanged=unchanged_channels(material, own_maps[index], own_stack,
                                                                      raster.mask, texture.config))
        baked.append(material)
    return baked


def materials_to_remap(texture: NeuralTexture, mesh: Mesh, wraps: list[tuple[str, str]]) -> frozenset:
    """The materials whose maps go into a new UV map: none unless adaptation worked per surface (the texture
    carries a new layout); then those whose own UVs share texels (core.surface_layout.uv_sharing)."""
    if getattr(texture, "layout", None) is None:
        return frozenset()
    return frozenset(index for index in range(mesh.material_count)
                     if uv_sharing(replace(material_submesh(mesh, index), wraps=((wraps[index][0], wraps[index][1]),)))
                     .needs_new_layout())


def _remapped_material(texture: NeuralTexture, normalized: Mesh, remapped: Mesh | None, index: int, name: str,
                       side: int, wrap: tuple[str, str], own: PBRMaps | None, was: dict, uv_map: str | None
                       ) -> BakedMaterial:
    """Material `index` baked at side² in the new UV map: each texel's base is the material's own maps read
    at that point's own UV (with its own wrap mode), its residual the network at the point."""
    if remapped is None or own is None or len(remapped.faces) != len(normalized.faces):
        raise InputError(f"Material '{name}' is baked into a new UV map, which needs the asset read with that "
                         "map and the material's own maps.")
    moved, _ = normalize_to_unit_sphere(remapped)
    faces = np.arange(len(normalized.faces)) if normalized.material_index is None else \
        np.flatnonzero(normalized.material_index == index)
    raster = rasterize_uv(material_submesh(moved, index), side, side, wrap="clamp")
    own_uv = own_uvs_at(raster, normalized, faces)
    h, w = own.resolution
    values = sample_image(own.stacked_at(h, w), own_uv.reshape(-1, 2), wrap).reshape(side, side, -1)
    maps = bake_texture(texture, raster.position, raster.border, raster.fill_index, own_base_logit(texture, values))
    return _baked_material(name, maps, raster, was, ("clamp", "clamp"), uv_map=uv_map, own_uv=own_uv)


def _baked_material(name: str, maps: np.ndarray, raster, was: dict, wrap: tuple[str, str], **layout) -> BakedMaterial:
    """Baked maps (H, W, 5) as glTF stores them: 8-bit sRGB base colour, roughness and metallic as images or,
    where constant, factors (`was`: the material's own plain values)."""
    return BakedMaterial(name=name, base_color=np.round(linear_to_srgb(maps[..., 0:3]) * 255.0).astype(np.uint8),
                         roughness=_channel(maps[..., 3], raster.mask, was.get("roughness")),
                         metallic=_channel(maps[..., 4], raster.mask, was.get("metallic")),
                         coverage=raster.coverage, wrap=wrap, **layout)
