"""Evaluated Blender mesh -> core.mesh.Mesh (triangulated, split at UV and normal seams)."""
from __future__ import annotations

import numpy as np

from ..core.base.errors import InputError
from ..core.data.mesh import Mesh

_GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


def world_matrix(obj) -> np.ndarray:
    """The object's 4x4 object-to-world matrix as float64 (rows are matrix rows)."""
    return np.array(obj.matrix_world, dtype=np.float64)


def _get(collection, attr: str, count: int, width: int, dtype) -> np.ndarray:
    out = np.empty(count * width, dtype=dtype)
    collection.foreach_get(attr, out)
    return out.reshape(count, width) if width > 1 else out


def mesh_from_object(obj, depsgraph, space: str = "object") -> Mesh:
    """The object's evaluated geometry (modifiers applied) as a Mesh.

    Triangulated through Blender's loop triangles; a vertex is split wherever the triangles meeting
    there disagree on UV or on the (custom or auto-smooth) corner normal, so each vertex has one of
    each. space: "object" (positions in object space; see world_matrix(obj)) or "world".
    The object and its data are only read: the evaluated copy is freed before returning.
    """
    if space not in ("object", "world"):
        raise ValueError(f"space must be 'object' or 'world', not {space!r}")
    if obj is None or obj.type not in _GEOMETRY_TYPES:
        kind = "nothing" if obj is None else f"a {obj.type.lower()} object"
        raise InputError(f"SceneFit needs a mesh object, but {kind} was given; select a mesh.")
    evaluated = obj.evaluated_get(depsgraph)
    me = evaluated.to_mesh()
    try:
        if me is None or len(me.polygons) == 0:
            raise InputError(f"Object '{obj.name}' has no faces; SceneFit needs a surface to texture.")
        # No UV map at all: every corner at (0, 0), as Blender's own renders read it (one texel per
        # material); adaptation then unwraps it anew (core.surface_layout: its UVs are all collapsed).
        uv_layer = me.uv_layers.active
        me.calc_loop_triangles()
        n_tris, n_loops, n_verts = len(me.loop_triangles), len(me.loops), len(me.vertices)
        tri_loops = _get(me.loop_triangles, "loops", n_tris, 3, np.int32).ravel()
        co = _get(me.vertices, "co", n_verts, 3, np.float32)
        loop_vertex = _get(me.loops, "vertex_index", n_loops, 1, np.int32)
        loop_uv = np.zeros((n_loops, 2), np.float32) if uv_layer is None else \
            _get(uv_layer.uv, "vector", n_loops, 2, np.float32)
        loop_normal = _get(me.corner_normals, "vector", n_loops, 3, np.float32)
        tri_material = _get(me.loop_triangles, "material_index", n_tris, 1, np.int32)
    finally:
        evaluated.to_mesh_clear()

    # One output vertex per distinct (vertex, uv, normal); compare floats by their exact bits.
    corners = tri_loops
    key = np.concatenate([
        loop_vertex[corners][:, None],
        loop_uv[corners].view(np.int32),
        loop_normal[corners].view(np.int32),
    ], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    chosen = corners[first]
    positions = co[loop_vertex[chosen]].astype(np.float64)
    normals = loop_normal[chosen].astype(np.float64)
    faces = inverse.reshape(-1, 3)
    if space == "world":
        m = world_matrix(obj)
        positions = positions @ m[:3, :3].T + m[:3, 3]
        normals = normals @ np.linalg.inv(m[:3, :3])  # inverse transpose, applied to row vectors
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
        if np.linalg.det(m[:3, :3]) < 0:   # a mirroring node turns every triangle inside out: wind it back
            faces = faces[:, [0, 2, 1]]
    # Material slot per triangle, kept when the object has several slots (see read_object_materials).
    material_index = tri_material if len(obj.material_slots) > 1 else None
    return Mesh.from_arrays(positions, faces, loop_uv[chosen], normals, name=obj.name,
                            material_index=material_index)
