"""Rasterising a mesh in UV space: for every texel, the 3D point of the surface it textures.

This gives the paper's position map C (H, W, 3) that the neural texture is evaluated on (§3.2).
Image conventions: row 0 is the top of the image (v = 1), texel (i, j) has its centre at
u = (j + 0.5) / W, v = 1 - (i + 0.5) / H, matching Mesh.uvs (OpenGL, v = 0 at the bottom).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..mesh import Mesh

# Texels whose centre lies within this many texels of a triangle (but inside none) still get a
# position, extrapolated from the nearest triangle, so bilinear lookups at UV seams read real values.
DEFAULT_BORDER = 2.0


@dataclass(frozen=True)
class UVRaster:
    """The mesh seen from UV space at (H, W). All arrays are read-only.

    position:  (H, W, 3) float32 surface point of each texel (mesh space); 0 where `border` is False.
    normal:    (H, W, 3) float32 unit interpolated normal, or None when the mesh has no normals.
    mask:      (H, W) bool, texel centre inside a UV triangle (exact coverage: fit and measure here).
    border:    (H, W) bool, mask plus texels within `border_width` texels of a triangle (evaluate here).
    face:      (H, W) int32 triangle of each `border` texel, -1 elsewhere.
    barycentric: (H, W, 3) float32 weights of the triangle's corners (clamped onto it at the border).
    fill_index: (H*W,) int64 flat index of the nearest `border` texel, for dilating past seams.
    """

    position: np.ndarray
    normal: np.ndarray | None
    mask: np.ndarray
    border: np.ndarray
    face: np.ndarray
    barycentric: np.ndarray
    fill_index: np.ndarray

    @property
    def resolution(self) -> tuple[int, int]:
        return self.mask.shape

    @property
    def coverage(self) -> float:
        """Fraction of texels that a triangle covers."""
        return float(self.mask.mean())


def rasterize_uv(mesh: Mesh, height: int, width: int | None = None, border_width: float = DEFAULT_BORDER) -> UVRaster:
    """Rasterise `mesh` in UV space at (height, width) texels; see UVRaster for what comes back.

    Vectorised: every triangle's (border-grown) bounding box is enumerated in one flat array, the
    candidates are tested with edge functions, and where several triangles claim a texel the one
    whose UV triangle is nearest (inside beats border) wins.
    """
    width = height if width is None else width
    if height < 1 or width < 1:
        raise InputError(f"The texture resolution must be at least 1x1, got {height}x{width}.")
    if border_width < 0:
        raise InputError(f"The seam border must be zero or more texels, got {border_width}.")
    faces = np.asarray(mesh.faces, dtype=np.int64)
    uv = np.asarray(mesh.uvs, dtype=np.float64)
    # Pixel coordinates with texel centres at integers: x = u W - 1/2, y = (1 - v) H - 1/2.
    pix = np.stack((uv[:, 0] * width - 0.5, (1.0 - uv[:, 1]) * height - 0.5), axis=1)
    tri = pix[faces]  # (F, 3, 2)

    # Drop triangles with (numerically) no area in UV space: they texture nothing.
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    keep = np.abs(area2) > 1e-12
    if not keep.any():
        raise InputError(f"Mesh '{mesh.name}' has no UV area: every triangle collapses in its UV map. Unwrap it again.")
    face_ids = np.flatnonzero(keep)
    tri, area2 = tri[keep], area2[keep]

    # Pass 1, exact coverage. Integer bounding boxes of texel centres, clipped to the image.
    lo = np.maximum(np.ceil(tri.min(axis=1) - 1e-9).astype(np.int64), 0)
    hi = np.minimum(np.floor(tri.max(axis=1) + 1e-9).astype(np.int64), np.array([width - 1, height - 1]))
    bw, bh = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    valid = (bw > 0) & (bh > 0)
    face_ids, tri, area2, lo, bw, bh = face_ids[valid], tri[valid], area2[valid], lo[valid], bw[valid], bh[valid]
    counts = bw * bh
    total = int(counts.sum())
    if total == 0:
        raise InputError(
            f"Mesh '{mesh.name}' covers no texel centre: its UVs lie outside [0, 1] or its UV islands are "
            f"smaller than one texel at {width}x{height}."
        )
    # One candidate per (triangle, bbox texel), flat.
    owner = np.repeat(np.arange(len(face_ids)), counts)
    local = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    bwo = bw[owner]
    px = lo[owner, 0] + local % bwo
    py = lo[owner, 1] + local // bwo
    bary = _barycentric(tri[owner], area2[owner], px, py)
    inside = (bary >= -1e-9).all(axis=1)
    owner, px, py, bary = owner[inside], px[inside], py[inside], bary[inside]
    # Texels on a shared edge are claimed twice; keep one (the first in face order).
    flat, first = np.unique(py * width + px, return_index=True)
    owner, bary = owner[first], bary[first]

    n_texels = height * width
    mask = np.zeros(n_texels, dtype=bool)
    mask[flat] = True
    owner_map = np.full(n_texels, -1, dtype=np.int64)
    owner_map[flat] = owner

    # Pass 2, the seam border: texels within border_width of the coverage take the triangle of
    # their nearest covered texel, with barycentrics extrapolated to their centre and clamped onto it.
    if border_width > 0 and len(flat) < n_texels:
        distance, nearest = _nearest_covered(mask.reshape(height, width))
        ring = np.flatnonzero(~mask & (distance.reshape(-1) <= border_width))
        if ring.size:
            ring_owner = owner_map[nearest[ring]]
            ring_bary = _barycentric(tri[ring_owner], area2[ring_owner], ring % width, ring // width)
            flat = np.concatenate((flat, ring))
            owner = np.concatenate((owner, ring_owner))
            bary = np.concatenate((bary, ring_bary))
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)

    verts = np.asarray(mesh.faces, dtype=np.int64)[face_ids[owner]]  # (K, 3)
    pos = np.einsum("kc,kcd->kd", bary, np.asarray(mesh.positions, dtype=np.float64)[verts])
    position = np.zeros((n_texels, 3), dtype=np.float32)
    position[flat] = pos
    border = np.zeros(n_texels, dtype=bool)
    border[flat] = True
    face = np.full(n_texels, -1, dtype=np.int32)
    face[flat] = face_ids[owner]
    barycentric = np.zeros((n_texels, 3), dtype=np.float32)
    barycentric[flat] = bary
    normal = None
    if mesh.normals is not None:
        nrm = np.einsum("kc,kcd->kd", bary, np.asarray(mesh.normals, dtype=np.float64)[verts])
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.where(length > 1e-12, nrm / np.maximum(length, 1e-12), 0.0)
        normal = np.zeros((n_texels, 3), dtype=np.float32)
        normal[flat] = nrm
        normal = normal.reshape(height, width, 3)

    border = border.reshape(height, width)
    result = UVRaster(
        position=position.reshape(height, width, 3),
        normal=normal,
        mask=mask.reshape(height, width),
        border=border,
        face=face.reshape(height, width),
        barycentric=barycentric.reshape(height, width, 3),
        fill_index=seam_fill_index(border),
    )
    for array in (result.position, result.normal, result.mask, result.border, result.face,
                  result.barycentric, result.fill_index):
        if array is not None:
            array.setflags(write=False)
    return result


def seam_fill_index(mask: np.ndarray) -> np.ndarray:
    """(H*W,) int64: for every texel, the flat index of the nearest texel where `mask` is True.

    Covered texels point at themselves, so `values.reshape(H*W, C)[fill_index]` dilates any map
    past its UV islands (a gather, hence differentiable in torch).
    """
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise InputError(f"The coverage mask must be 2D, got shape {mask.shape}.")
    covered = np.flatnonzero(mask)
    if covered.size == 0:
        raise InputError("No texel is covered by the mesh's UV map; check the UVs lie in [0, 1].")
    if covered.size == mask.size:
        return np.arange(mask.size, dtype=np.int64)
    return _nearest_covered(mask)[1]


def _nearest_covered(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance in texels to, and flat index of, the nearest True texel of a non-empty 2D mask."""
    import cv2

    covered = np.flatnonzero(mask)
    # Zero pixels (covered texels) each get their own label, numbered in raster order from 1;
    # every other pixel gets the label of its nearest zero pixel (5x5 mask distance, ~exact).
    src = np.where(mask, 0, 255).astype(np.uint8)
    distance, labels = cv2.distanceTransformWithLabels(src, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    return distance, covered[labels.reshape(-1).astype(np.int64) - 1]


def _barycentric(tri: np.ndarray, area2: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """(K, 3) barycentric weights of points (px, py) in triangles tri (K, 3, 2) of doubled signed area area2."""
    ax, ay = tri[:, 0, 0], tri[:, 0, 1]
    bx, by = tri[:, 1, 0], tri[:, 1, 1]
    cx, cy = tri[:, 2, 0], tri[:, 2, 1]
    w0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / area2
    w1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / area2
    return np.stack((w0, w1, 1.0 - w0 - w1), axis=1)
