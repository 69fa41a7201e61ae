"""A triangle mesh as plain arrays, split at UV seams so every vertex has one UV."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError

# The paper normalises every asset into a sphere of this radius, centred at the origin (appendix).
NORMALIZED_RADIUS = 0.5


@dataclass(frozen=True)
class Mesh:
    """Vertices are already split where UVs or normals differ, as renderers need.

    positions: (V, 3) float32, object space.
    faces:     (F, 3) int32 indices into positions.
    uvs:       (V, 2) float32, OpenGL convention (v = 0 at the bottom of the image).
    normals:   (V, 3) float32 unit vertex normals, or None for flat shading.
    material_index: (F,) int32 material slot of each face, or None when the mesh has one material.
        Several materials each own their UV layout (they may overlap in UV space).
    wraps: per material slot, how its UVs outside [0, 1] read its maps, (u, v) as its textures'
        sampler says (core.data.uv_raster.WRAP_MODES); () reads every slot as repeat.
    atlas: the UVs are core.materials' atlas (each material's own UVs moved into its cell of one
        square), as fitting_view gives them; renderers and rasterisers then sample each material's
        cell with its own UVs and wrap mode (core.materials.own_uv_mesh undoes the move).
    """

    positions: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    normals: np.ndarray | None = None
    name: str = "asset"
    material_index: np.ndarray | None = None
    wraps: tuple[tuple[str, str], ...] = ()
    atlas: bool = False

    def __post_init__(self) -> None:
        p, f, uv = self.positions, self.faces, self.uvs
        if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            raise InputError(f"Mesh '{self.name}' has no vertices; select an object with geometry.")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise InputError(f"Mesh '{self.name}' has no faces; SceneFit needs a surface to texture.")
        if uv is None or uv.shape != (len(p), 2):
            raise InputError(
                f"Mesh '{self.name}' has no UV map; unwrap it in Blender (UV > Smart UV Project) first."
            )
        check_face_indices(f, len(p), f"Mesh '{self.name}'")
        if not (np.isfinite(p).all() and np.isfinite(uv).all()):
            raise InputError(f"Mesh '{self.name}' has NaN or infinite coordinates.")
        if self.normals is not None:
            n = self.normals
            if n.shape != p.shape:
                raise InputError(f"Mesh '{self.name}' has {len(n)} normals for {len(p)} vertices.")
            if not np.isfinite(n).all():
                raise InputError(f"Mesh '{self.name}' has NaN or infinite normals; recalculate them in Blender "
                                 "(Mesh > Normals > Reset Vectors) or leave them out.")
            if not (np.abs(n).sum(axis=1) > 0).any():
                raise InputError(f"Mesh '{self.name}' has all-zero normals; recalculate them in Blender "
                                 "(Mesh > Normals > Reset Vectors) or leave them out.")
        if self.material_index is not None and self.material_index.shape != (len(f),):
            raise InputError(f"Mesh '{self.name}' has {len(self.material_index)} face materials for {len(f)} faces.")
        if self.wraps and len(self.wraps) != self.material_count:
            raise InputError(f"Mesh '{self.name}' has {len(self.wraps)} wrap modes for {self.material_count} materials.")
        # Freeze the arrays too, so nothing downstream edits the user's data in place.
        for a in (p, f, uv, self.normals, self.material_index):
            if a is not None:
                a.setflags(write=False)

    @staticmethod
    def from_arrays(positions, faces, uvs, normals=None, name: str = "asset", material_index=None,
                    wraps: tuple[tuple[str, str], ...] = (), atlas: bool = False) -> "Mesh":
        positions, faces = np.asarray(positions), np.asarray(faces)
        # Checked before the cast to int32: an int64 index of 2^32 + 5 would otherwise wrap to a valid 5.
        if faces.dtype.kind in "iu" and positions.ndim == 2 and faces.ndim == 2 and faces.shape[-1:] == (3,):
            check_face_indices(faces, len(positions), f"Mesh '{name}'")
        if material_index is not None:
            material_index = np.asarray(material_index)
            if material_index.size and (material_index.min() < 0 or material_index.max() > np.iinfo(np.int32).max):
                raise InputError(f"Mesh '{name}' has material slots outside 0..{np.iinfo(np.int32).max} "
                                 f"({material_index.min()}..{material_index.max()}); re-export the asset.")
        return Mesh(
            positions=np.ascontiguousarray(positions, dtype=np.float32),
            faces=np.ascontiguousarray(faces, dtype=np.int32),
            uvs=np.ascontiguousarray(uvs, dtype=np.float32),
            normals=None if normals is None else np.ascontiguousarray(normals, dtype=np.float32),
            name=name,
            material_index=None if material_index is None else np.ascontiguousarray(material_index, dtype=np.int32),
            wraps=tuple(tuple(w) for w in wraps),  # type: ignore[misc]
            atlas=atlas,
        )

    @property
    def material_count(self) -> int:
        return 1 if self.material_index is None else int(self.material_index.max()) + 1


def check_face_indices(faces: np.ndarray, vertex_count: int, what: str) -> None:
    """Every face index must name one of the mesh's vertices; `what` begins the sentence ("Mesh 'x'")."""
    if faces.size and (faces.min() < 0 or faces.max() >= vertex_count):
        raise InputError(f"{what} has face indices {faces.min()}..{faces.max()} outside its vertex list "
                         f"(0..{vertex_count - 1}); re-export the asset.")


@dataclass(frozen=True)
class NormalizeTransform:
    """object_space = normalized * scale + center; kept so results map back onto the asset."""

    center: np.ndarray
    scale: float

    def to_normalized(self, points: np.ndarray) -> np.ndarray:
        return (points - self.center) / self.scale

    def to_object(self, points: np.ndarray) -> np.ndarray:
        return points * self.scale + self.center


def normalize_to_unit_sphere(mesh: Mesh, radius: float = NORMALIZED_RADIUS) -> tuple[Mesh, NormalizeTransform]:
    """Centre the bounding box at the origin and scale so the farthest vertex sits at `radius`."""
    p = mesh.positions.astype(np.float64)
    center = 0.5 * (p.min(axis=0) + p.max(axis=0))
    extent = np.linalg.norm(p - center, axis=1).max()
    if not np.isfinite(extent) or extent <= 0.0:
        raise InputError(f"Mesh '{mesh.name}' is degenerate: all its vertices are at one point.")
    scale = float(extent / radius)
    normalized = Mesh.from_arrays(((p - center) / scale), mesh.faces, mesh.uvs, mesh.normals, mesh.name,
                                  mesh.material_index, mesh.wraps, mesh.atlas)
    return normalized, NormalizeTransform(center=center.astype(np.float32), scale=scale)


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (for meshes that come without them)."""
    p = positions.astype(np.float64)
    fn = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.maximum(length, 1e-30), np.array([0.0, 0.0, 1.0]))
    return n.astype(np.float32)
