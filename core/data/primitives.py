"""Small UV-mapped meshes built from formulas: test subjects and the light-capturing sphere."""
from __future__ import annotations

import numpy as np

from .mesh import Mesh


def uv_sphere(radius: float = 0.5, segments: int = 48, rings: int = 24, name: str = "sphere") -> Mesh:
    """Latitude-longitude sphere; u follows longitude, v = 1 at the north (+Z) pole."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    uvs = np.stack([p / (2.0 * np.pi), 1.0 - t / np.pi], axis=-1).reshape(-1, 2)
    row = segments + 1
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = (i * row + j).ravel()
    b, c, d = a + 1, a + row, a + row + 1
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    # Drop the zero-area triangles at the poles.
    area = np.linalg.norm(np.cross(normals[faces[:, 1]] - normals[faces[:, 0]],
                                   normals[faces[:, 2]] - normals[faces[:, 0]]), axis=1)
    return Mesh.from_arrays(normals * radius, faces[area > 1e-12], uvs, normals, name=name)


def grid_plane(size: float = 1.0, divisions: int = 8, name: str = "plane") -> Mesh:
    """A square in the XZ plane facing -Y (towards the default camera); UV (0,0) at the bottom left."""
    s = np.linspace(0.0, 1.0, divisions + 1)
    u, v = np.meshgrid(s, s, indexing="xy")
    positions = np.stack([(u - 0.5) * size, np.zeros_like(u), (v - 0.5) * size], axis=-1).reshape(-1, 3)
    uvs = np.stack([u, v], axis=-1).reshape(-1, 2)
    row = divisions + 1
    i, j = np.meshgrid(np.arange(divisions), np.arange(divisions), indexing="ij")
    a = (i * row + j).ravel()
    b, c, d = a + 1, a + row, a + row + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    normals = np.tile([0.0, -1.0, 0.0], (len(positions), 1))
    return Mesh.from_arrays(positions, faces, uvs, normals, name=name)
