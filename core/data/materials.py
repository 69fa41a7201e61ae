"""An asset's materials as read from Blender, and the atlas that fits several of them at once.

A mesh may carry several materials, each with its own UV layout (they may overlap in UV space).
The neural texture lives on the surface (3D points), not in UV space, so one network serves all
of them: for fitting and rendering, each material's UV square is moved into its own cell of a
square atlas (g x g cells, g = ceil(sqrt(M))). Baking for game export goes the other way and
writes each material's maps in the asset's own UV layout, so the asset keeps its structure (the
paper instead re-maps the whole mesh into one new atlas; a game pipeline wants its own layout).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..base.errors import InputError
from .maps import FLAT_NORMAL, PBRMaps
from .mesh import Mesh
from .uv_raster import UVRaster, rasterize_uv, seam_fill_index, wrap_modes


@dataclass(frozen=True)
class Material:
    """One material slot of the asset: the maps SceneFit fits, and an account of how they were read.

    read: what was read, node and channel ("Roughness <- image 'mr.png' G via Separate Color").
    kept: what is not fitted but carried unchanged into renders or game export (normal map, alpha,
        emission, occlusion).
    dropped: what SceneFit neither fits nor carries, and why.
    wrap: how its UVs outside [0, 1] read the maps, (u, v), as its textures' sampler says (see
        core.data.uv_raster.WRAP_MODES): the maps are fitted and baked wrapped the same way.
    """

    name: str
    maps: PBRMaps
    read: tuple[str, ...] = ()
    kept: tuple[str, ...] = ()
    dropped: tuple[str, ...] = ()
    alpha_mode: str = "OPAQUE"           # glTF's OPAQUE, MASK or BLEND
    wrap: tuple[str, str] = ("repeat", "repeat")

    def __post_init__(self) -> None:
        object.__setattr__(self, "wrap", wrap_modes(self.wrap))

    def report(self) -> dict:
        h, w = self.maps.resolution
        return {"name": self.name, "resolution": [int(h), int(w)], "alpha_mode": self.alpha_mode,
                "wrap": list(self.wrap), "read": list(self.read), "kept": list(self.kept),
                "dropped": list(self.dropped)}


@dataclass(frozen=True)
class AssetMaterials:
    """A mesh whose `material_index` (or its single material) refers into `materials`."""

    mesh: Mesh
    materials: tuple[Material, ...]
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        if not self.materials:
            raise InputError(f"Mesh '{self.mesh.name}' has no material SceneFit can read.")
        if self.mesh.material_count != len(self.materials):
            raise InputError(f"Mesh '{self.mesh.name}' uses {self.mesh.material_count} materials but "
                             f"{len(self.materials)} were read.")

    def fitting_view(self) -> tuple[Mesh, PBRMaps]:
        """One mesh and one set of maps that every single-texture stage (render, adapt) can use:
        the asset itself for one material, the atlas for several. The mesh carries each material's
        wrap mode, and an atlas mesh says it is one, so renders sample each material's own cell with
        its own UVs (core.render, material_parts)."""
        mesh = fitting_mesh(self.mesh, self.wraps, len(self.materials))
        if len(self.materials) == 1:
            return mesh, self.materials[0].maps
        size = atlas_cell_size([m.maps for m in self.materials])
        return mesh, atlas_maps([m.maps for m in self.materials], size)

    def report(self) -> list[dict]:
        return [m.report() for m in self.materials]

    @property
    def wraps(self) -> list[tuple[str, str]]:
        return [m.wrap for m in self.materials]


def atlas_grid(count: int) -> int:
    """Cells per side of the square atlas holding `count` materials."""
    return max(1, math.ceil(math.sqrt(count)))


def atlas_cell(index: int, count: int) -> tuple[int, int]:
    """(row from the top, column) of material `index`'s cell."""
    g = atlas_grid(count)
    return index // g, index % g


def atlas_cell_size(maps: list[PBRMaps]) -> int:
    """Texels per cell side: the largest material's own base colour size."""
    return max(max(m.resolution) for m in maps)


def atlas_mesh(mesh: Mesh) -> Mesh:
    """The mesh with each material's UVs moved into its atlas cell (vertices split between materials);
    it keeps its wrap modes and is marked `atlas` (own_uv_mesh undoes the move)."""
    if mesh.material_index is None or mesh.material_count == 1:
        return mesh
    count, g = mesh.material_count, atlas_grid(mesh.material_count)
    corner_vertex = mesh.faces.reshape(-1)
    corner_material = np.repeat(mesh.material_index, 3)
    key = corner_vertex.astype(np.int64) * count + corner_material
    unique, inverse = np.unique(key, return_inverse=True)
    vertex, material = unique // count, unique % count
    row, col = material // g, material % g
    uv = mesh.uvs[vertex].astype(np.float64)
    uv = np.stack([(uv[:, 0] + col) / g, (uv[:, 1] + (g - 1 - row)) / g], axis=1)
    normals = None if mesh.normals is None else mesh.normals[vertex]
    return Mesh.from_arrays(mesh.positions[vertex], inverse.reshape(-1, 3), uv, normals, mesh.name,
                            mesh.material_index, mesh.wraps, atlas=True)


def fitting_mesh(mesh: Mesh, wraps, count: int) -> Mesh:
    """The mesh a fit of `count` materials uses: each material's wrap mode on it, and their atlas for several."""
    mesh = replace(mesh, wraps=tuple(wraps))
    return atlas_mesh(mesh) if count > 1 else mesh


def own_uv_mesh(mesh: Mesh) -> Mesh:
    """An atlas mesh with each material's own UVs back (its move into its cell undone); other meshes as
    they are. The faces and vertices stay those of `mesh`."""
    if not mesh.atlas:
        return mesh
    g = atlas_grid(mesh.material_count)
    material = np.zeros(len(mesh.positions), np.int64)
    material[mesh.faces.reshape(-1)] = np.repeat(mesh.material_index, 3)   # type: ignore[arg-type]  # atlas_mesh split shared vertices
    row, col = material // g, material % g
    uv = mesh.uvs.astype(np.float64) * g
    uv = np.stack([uv[:, 0] - col, uv[:, 1] - (g - 1 - row)], axis=1)
    return Mesh.from_arrays(mesh.positions, mesh.faces, uv, mesh.normals, mesh.name, mesh.material_index, mesh.wraps)


def mesh_raster(mesh: Mesh, size: int) -> UVRaster:
    """The UV raster at size² of a mesh as fitting_view gives it: an atlas mesh's materials each in their
    own cell, wrapped as their samplers say (atlas_raster); one material with its wrap mode."""
    wraps = list(mesh.wraps) or [("repeat", "repeat")] * mesh.material_count
    if mesh.atlas:
        return atlas_raster(mesh, own_uv_mesh(mesh), size, wraps)
    return rasterize_uv(mesh, size, wrap=wraps[0] if mesh.material_count == 1 else "repeat")


@dataclass(frozen=True)
class MaterialPart:
    """One material's faces as a renderer draws them: in its own UVs, sampling its own texels (rows,
    cols) of the maps the renderer is given (its atlas cell, or all of them) with its wrap mode."""

    index: int
    mesh: Mesh
    wrap: tuple[str, str]
    rows: slice
    cols: slice


def material_parts(mesh: Mesh, shape: tuple[int, int]) -> list[MaterialPart]:
    """The parts a renderer draws `mesh` as, for maps of `shape` (H, W): one per material of an atlas
    mesh (a material without faces has none), else the whole mesh. So UVs that tile past [0, 1] read
    their own material's texels, never a neighbouring cell's."""
    wraps = list(mesh.wraps) or [("repeat", "repeat")] * mesh.material_count
    h, w = shape
    if not mesh.atlas:
        wrap = wraps[0] if mesh.material_count == 1 else ("repeat", "repeat")
        return [MaterialPart(0, mesh, wrap, slice(0, h), slice(0, w))]
    own, count = own_uv_mesh(mesh), mesh.material_count
    cell_h, cell_w = h // atlas_grid(count), w // atlas_grid(count)   # as atlas_raster places the texels
    parts = []
    for index in range(count):
        if not (mesh.material_index == index).any():  # type: ignore[union-attr]
            continue
        r, c = atlas_cell(index, count)
        parts.append(MaterialPart(index, material_submesh(own, index), wraps[index],
                                  slice(r * cell_h, (r + 1) * cell_h), slice(c * cell_w, (c + 1) * cell_w)))
    return parts


def atlas_raster(atlas: Mesh, mesh: Mesh, size: int, wraps: list[tuple[str, str]]) -> UVRaster:
    """The raster of `atlas` (atlas_mesh(mesh), normalised or not) at size²: each material's faces are
    rasterised in their own UVs (those of `mesh`), wrapped as that material's sampler says, into its
    cell. So UVs that tile past [0, 1] stay in their own cell instead of reaching into the next one."""
    if mesh.material_index is None or mesh.material_count == 1:
        return rasterize_uv(atlas, size, wrap=wraps[0])
    count = mesh.material_count
    cell = size // atlas_grid(count)
    faces = np.arange(3 * len(mesh.faces)).reshape(-1, 3)
    # The atlas's corners (its positions, e.g. normalised) with the asset's own UVs, face by face.
    corners = Mesh.from_arrays(atlas.positions[atlas.faces].reshape(-1, 3), faces, mesh.uvs[mesh.faces].reshape(-1, 2),
                               None if atlas.normals is None else atlas.normals[atlas.faces].reshape(-1, 3),
                               mesh.name, mesh.material_index)
    arrays = {"position": np.zeros((size, size, 3), np.float32), "mask": np.zeros((size, size), bool),
              "border": np.zeros((size, size), bool), "face": np.full((size, size), -1, np.int32),
              "barycentric": np.zeros((size, size, 3), np.float32),
              "normal": None if atlas.normals is None else np.zeros((size, size, 3), np.float32)}
    refusal = None
    for index, (rows, cols) in enumerate(atlas_slices(count, cell)):
        try:
            raster = rasterize_uv(material_submesh(corners, index), cell, wrap=wraps[index])
        except InputError as error:  # a material whose UVs cover no texel leaves its cell empty
            refusal = refusal or error
            continue
        for name, plane in arrays.items():
            if plane is not None:
                plane[rows, cols] = getattr(raster, name)
        ids = np.flatnonzero(mesh.material_index == index).astype(np.int32)  # the submesh's faces in mesh's order
        arrays["face"][rows, cols] = np.where(raster.face >= 0, ids[np.maximum(raster.face, 0)], -1)  # type: ignore[index]
    if not arrays["mask"].any():  # type: ignore[union-attr]
        raise refusal  # type: ignore[misc]
    return UVRaster(fill_index=seam_fill_index(arrays["border"]), **arrays)  # type: ignore[arg-type]


def material_submesh(mesh: Mesh, index: int) -> Mesh:
    """The faces of material `index` alone, in their own UV layout (positions unchanged)."""
    if mesh.material_index is None:
        if index != 0:
            raise InputError(f"Mesh '{mesh.name}' has one material; there is no material {index}.")
        return mesh
    faces = mesh.faces[mesh.material_index == index]
    if len(faces) == 0:
        raise InputError(f"No face of mesh '{mesh.name}' uses material {index}.")
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    normals = None if mesh.normals is None else mesh.normals[used]
    return Mesh.from_arrays(mesh.positions[used], inverse.reshape(-1, 3), mesh.uvs[used], normals, mesh.name)


def atlas_slices(count: int, cell: int) -> list[tuple[slice, slice]]:
    """(rows, columns) of each material's cell in an atlas of `cell`-texel cells."""
    out = []
    for index in range(count):
        r, c = atlas_cell(index, count)
        out.append((slice(r * cell, (r + 1) * cell), slice(c * cell, (c + 1) * cell)))
    return out


def atlas_stack(planes: list[np.ndarray], cell: int, empty=0.0) -> np.ndarray:
    """Per-material (cell, cell, C) arrays placed into one atlas (empty cells hold `empty`)."""
    g = atlas_grid(len(planes))
    out = np.empty((g * cell, g * cell, planes[0].shape[2]), np.float32)
    out[...] = np.asarray(empty, np.float32)
    for plane, (rows, cols) in zip(planes, atlas_slices(len(planes), cell)):
        out[rows, cols] = plane
    return out


def atlas_maps(maps: list[PBRMaps], cell: int) -> PBRMaps:
    """Every material's maps resized to `cell` and placed in its atlas cell."""
    stack = atlas_stack([m.stacked_at(cell, cell) for m in maps], cell)
    normal = None
    if any(m.normal is not None for m in maps):
        normal = atlas_stack([m.normal_at(cell, cell) for m in maps], cell, empty=FLAT_NORMAL)
    return PBRMaps(base_color=stack[..., :3].copy(), roughness=stack[..., 3].copy(),
                   metallic=stack[..., 4].copy(), normal=normal)


def mesh_digest(mesh: Mesh) -> str:
    """Names a mesh by its faces and own UVs (not its positions, so normalised and object space agree). Here,
    without torch: Blender's main thread names the asset's mesh at a click."""
    own = own_uv_mesh(mesh)
    digest = hashlib.sha256()
    for array in (own.faces, own.uvs, np.asarray([len(own.positions)], np.int64)):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()[:16]
