"""Rasterising a mesh in UV space: for every texel, the 3D point of the surface it textures.

This gives the paper's position map C (H, W, 3) that the neural texture is evaluated on (§3.2).
Image conventions: row 0 is the top of the image (v = 1), texel (i, j) has its centre at
u = (j + 0.5) / W, v = 1 - (i + 0.5) / H, matching Mesh.uvs (OpenGL, v = 0 at the bottom).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from ..base.errors import InputError
from .mesh import Mesh

# Texels whose centre lies within this many texels of a triangle (but inside none) still get a
# position, extrapolated from the nearest triangle, so bilinear lookups at UV seams read real values.
DEFAULT_BORDER = 2.0
# How UVs outside [0, 1] read the texture: glTF's REPEAT, MIRRORED_REPEAT and CLAMP_TO_EDGE.
WrapMode = Literal["repeat", "mirror", "clamp"]
WRAP_MODES: tuple[str, ...] = get_args(WrapMode)
# (triangle, texel) candidates, or rows of triangles, handled at once: what bounds the memory, however
# large or repeated the UV triangles are (63k triangles each spanning the square asked for 124 GiB).
CHUNK = 1 << 18


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

    def __post_init__(self) -> None:
        for array in (self.position, self.normal, self.mask, self.border, self.face, self.barycentric,
                      self.fill_index):
            if array is not None:
                array.setflags(write=False)

    @property
    def resolution(self) -> tuple[int, int]:
        return self.mask.shape  # type: ignore[return-value]

    @property
    def coverage(self) -> float:
        """Fraction of texels that a triangle covers."""
        return float(self.mask.mean())


def wrap_modes(wrap: str | tuple[str, str]) -> tuple[str, str]:
    """(u, v) wrap modes from one mode for both axes or a pair; see WRAP_MODES."""
    modes = (wrap, wrap) if isinstance(wrap, str) else tuple(wrap)
    if len(modes) != 2 or any(mode not in WRAP_MODES for mode in modes):
        raise InputError(f"The UV wrap mode must be one of {', '.join(WRAP_MODES)}, or a pair of them for u and v; "
                         f"got {wrap!r}.")
    return modes


def rasterize_uv(mesh: Mesh, height: int, width: int | None = None, border_width: float = DEFAULT_BORDER,
                 wrap: str | tuple[str, str] = "repeat") -> UVRaster:
    """Rasterise `mesh` in UV space at (height, width) texels; see UVRaster for what comes back.

    wrap: how UVs outside [0, 1] read the texture, per axis (u, v) or for both, as glTF's samplers
    say: "repeat" (the default) and "mirror" tile the image, so such a texel belongs to the first
    triangle that covers any of its copies; under "clamp" only UVs inside the image cover texels.

    Triangles are taken in face order, a bounded number of (triangle, texel) candidates at a time:
    the candidates of each row of a triangle lie in the span its edges allow there, less the texels
    of that row an earlier triangle already holds (they never change hands), and are tested with
    edge functions; the first triangle whose edges reach a texel's centre holds it. So the memory
    depends on the texture and the mesh, not on how large or how often repeated its UV triangles are.
    """
    width = height if width is None else width
    if height < 1 or width < 1:
        raise InputError(f"The texture resolution must be at least 1x1, got {height}x{width}.")
    if border_width < 0:
        raise InputError(f"The seam border must be zero or more texels, got {border_width}.")
    modes = wrap_modes(wrap)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    uv = np.asarray(mesh.uvs, dtype=np.float64)
    # Pixel coordinates with texel centres at integers: x = u W - 1/2, y = (1 - v) H - 1/2.
    pix = np.stack((uv[:, 0] * width - 0.5, (1.0 - uv[:, 1]) * height - 0.5), axis=1)
    texels = _Texels(tri=pix[faces], height=height, width=width, modes=modes)
    flat, owner, bary = _covered_texels(texels, mesh.name)
    mask = np.zeros(height * width, dtype=bool)
    mask[flat] = True
    if border_width > 0 and len(flat) < height * width:
        flat, owner, bary = _add_border(texels, mask, border_width, flat, owner, bary)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    return _raster(mesh, faces[owner], flat, owner, bary, mask, height, width)


@dataclass
class _Texels:
    """What both passes of rasterize_uv share: the faces' corners in pixel coordinates (F, 3, 2) and
    the image; `area2`, `owner_map`, `tiles` and `point` are filled in by pass 1."""

    tri: np.ndarray
    height: int
    width: int
    modes: tuple[str, str]
    area2: np.ndarray | None = None
    owner_map: np.ndarray | None = None
    tiles: np.ndarray | None = None
    point: np.ndarray | None = None

    def weights(self, owner: np.ndarray, flat: np.ndarray, near: np.ndarray) -> np.ndarray:
        """Barycentrics of texels `flat` in faces `owner`, in the image copy where texels `near` are held."""
        assert self.area2 is not None and self.point is not None and self.tiles is not None, "pass 1 fills them"
        return _weights(self.tri, self.area2, self.point, owner,
                        _unwrapped(flat % self.width, self.tiles[0, near], self.width, self.modes[0]),
                        _unwrapped(flat // self.width, self.tiles[1, near], self.height, self.modes[1]))


def _covered_texels(texels: _Texels, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pass 1, exact coverage: (flat texel index, face, barycentrics) of every texel a face holds."""
    tri, height, width, modes = texels.tri, texels.height, texels.width, texels.modes
    # Triangles with (numerically) no UV area are not rasterised as areas; like those too small to hold
    # a texel centre, they sample one texel (see _claim_points).
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    real = np.abs(area2) > 1e-12
    # Integer bounding boxes of texel centres (in the tiled plane), clipped to the image along an axis
    # that clamps.
    lo = np.ceil(tri.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(tri.max(axis=1) + 1e-9).astype(np.int64)
    for axis, (mode, size) in enumerate(zip(modes, (width, height))):
        if mode == "clamp":
            lo[:, axis], hi[:, axis] = np.maximum(lo[:, axis], 0), np.minimum(hi[:, axis], size - 1)
    areas = np.flatnonzero(real & (hi >= lo).all(axis=1))
    owner_map, tiles = _cover(tri[areas], area2[areas], lo[areas], hi[areas], height, width, modes)
    held = owner_map >= 0
    owner_map[held] = areas[owner_map[held]]  # face numbers from here on
    point = _claim_points(tri, owner_map, tiles, height, width, modes)
    texels.area2, texels.owner_map, texels.tiles, texels.point = area2, owner_map, tiles, point
    flat = np.flatnonzero(owner_map >= 0)
    if flat.size == 0:
        # (with repeating UVs every face samples some texel, so only clamped UVs come here)
        raise InputError(f"Mesh '{name}' covers no texel centre at {width}x{height}: its UV islands lie "
                         "outside [0, 1] where the texture clamps; unwrap it inside [0, 1].")
    owner = owner_map[flat]
    return flat, owner, texels.weights(owner, flat, flat)


def _add_border(texels: _Texels, mask: np.ndarray, border_width: float, flat: np.ndarray, owner: np.ndarray,
                bary: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pass 2, the seam border: texels within border_width of the coverage take the triangle of their
    nearest covered texel, with barycentrics extrapolated to their centre (clamped onto it later)."""
    distance, nearest = _nearest_covered(mask.reshape(texels.height, texels.width))
    ring = np.flatnonzero(~mask & (distance.reshape(-1) <= border_width))
    if not ring.size:
        return flat, owner, bary
    # (in the copy of the image where the nearest covered texel's triangle lies)
    near = nearest[ring]
    ring_owner = texels.owner_map[near]  # type: ignore[index]
    ring_bary = texels.weights(ring_owner, ring, near)
    return np.concatenate((flat, ring)), np.concatenate((owner, ring_owner)), np.concatenate((bary, ring_bary))


def _raster(mesh: Mesh, verts: np.ndarray, flat: np.ndarray, owner: np.ndarray, bary: np.ndarray,
            mask: np.ndarray, height: int, width: int) -> UVRaster:
    """The UVRaster of texels `flat` held by faces `owner` (corners `verts`) with weights `bary`."""
    n_texels = height * width

    def image(values: np.ndarray, fill, dtype) -> np.ndarray:
        out = np.full((n_texels,) + values.shape[1:], fill, dtype=dtype)
        out[flat] = values
        return out.reshape((height, width) + values.shape[1:])

    pos = np.einsum("kc,kcd->kd", bary, np.asarray(mesh.positions, dtype=np.float64)[verts])
    normal = None
    if mesh.normals is not None:
        nrm = np.einsum("kc,kcd->kd", bary, np.asarray(mesh.normals, dtype=np.float64)[verts])
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        normal = image(np.where(length > 1e-12, nrm / np.maximum(length, 1e-12), 0.0), 0.0, np.float32)
    border = image(np.ones(flat.size, bool), False, bool)
    return UVRaster(
        position=image(pos, 0.0, np.float32),
        normal=normal,
        mask=mask.reshape(height, width),
        border=border,
        face=image(owner, -1, np.int32),
        barycentric=image(bary, 0.0, np.float32),
        fill_index=seam_fill_index(border),
    )


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
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    covered = np.flatnonzero(mask)
    # Zero pixels (covered texels) each get their own label, numbered in raster order from 1;
    # every other pixel gets the label of its nearest zero pixel (5x5 mask distance, ~exact).
    src = np.where(mask, 0, 255).astype(np.uint8)
    distance, labels = cv2.distanceTransformWithLabels(src, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    return distance, covered[labels.reshape(-1).astype(np.int64) - 1]


def _texel(coord: np.ndarray, size: int, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """(texel index, tile) along one axis of integer texel coordinates in the tiled plane: tile k holds
    coordinates [k size, (k + 1) size), a copy of the image, mirrored in odd tiles under "mirror"."""
    if mode == "clamp":  # only coordinates inside the image are ever enumerated
        return coord, np.zeros_like(coord)
    tile = coord // size
    local = coord - tile * size
    return (np.where(tile % 2 == 1, size - 1 - local, local) if mode == "mirror" else local), tile


def sample_image(image: np.ndarray, uv: np.ndarray, wrap: str | tuple[str, str] = "repeat") -> np.ndarray:
    """(N, C) bilinear reads of `image` (H, W, C) at `uv` (N, 2), outside [0, 1] as `wrap` says per axis:
    the texture lookup a glTF sampler makes, in rasterize_uv's texel convention."""
    height, width = image.shape[:2]
    modes = wrap_modes(wrap)
    x = np.asarray(uv[:, 0], np.float64) * width - 0.5
    y = (1.0 - np.asarray(uv[:, 1], np.float64)) * height - 0.5
    out = np.zeros((len(uv), image.shape[2]), np.float64)
    for axis_x, weight_x in ((np.floor(x), 1.0 - (x - np.floor(x))), (np.floor(x) + 1, x - np.floor(x))):
        for axis_y, weight_y in ((np.floor(y), 1.0 - (y - np.floor(y))), (np.floor(y) + 1, y - np.floor(y))):
            col = _texel_index(axis_x.astype(np.int64), width, modes[0])
            row = _texel_index(axis_y.astype(np.int64), height, modes[1])
            out += (weight_x * weight_y)[:, None] * image[row, col]
    return out.astype(np.float32)


def _texel_index(coord: np.ndarray, size: int, mode: str) -> np.ndarray:
    """The image texel an integer texel coordinate of the tiled plane reads (clamp: the nearest edge)."""
    return np.clip(coord, 0, size - 1) if mode == "clamp" else _texel(coord, size, mode)[0]


def _unwrapped(index: np.ndarray, tile: np.ndarray, size: int, mode: str) -> np.ndarray:
    """The coordinate in the tiled plane of texel `index` in copy `tile` (the inverse of _texel)."""
    if mode == "clamp":
        return index
    local = np.where(tile % 2 == 1, size - 1 - index, index) if mode == "mirror" else index
    return tile * size + local


def _row_spans(tri: np.ndarray, area2: np.ndarray, y: np.ndarray, lo: np.ndarray, hi: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Integer [first, last] x of each triangle's candidates on its row y: where its three edge
    functions allow (the test's tolerance plus two texels of margin for rounding), within [lo, hi]."""
    sign = np.sign(area2)
    tolerance = 1e-9 * np.abs(area2)
    first, last = lo.astype(np.float64), hi.astype(np.float64)
    for i in range(3):  # edge (b, c) opposite corner i: w_i A = k + s x, linear in x along the row
        (bx, by), (cx, cy) = tri[:, (i + 1) % 3].T, tri[:, (i + 2) % 3].T
        k, s = (bx * (cy - y) - cx * (by - y)) * sign, (by - cy) * sign
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (-tolerance - k) / s
        first = np.where(s > 0, np.maximum(first, bound), first)
        last = np.where(s < 0, np.minimum(last, bound), last)
    first = np.maximum(np.ceil(np.clip(first, lo - 3, hi + 3)).astype(np.int64) - 2, lo)
    last = np.minimum(np.floor(np.clip(last, lo - 3, hi + 3)).astype(np.int64) + 2, hi)
    return first, last


class _Free:
    """For each texel row, the columns [lo, hi] outside which every texel is already held: a span is
    cut to them before its candidates are made (held texels never change hands)."""

    def __init__(self, owner_map: np.ndarray, height: int, width: int) -> None:
        self.owner, self.width = owner_map.reshape(height, width), width
        self.lo, self.hi = np.zeros(height, np.int64), np.full(height, width - 1, np.int64)
        self.left = height * width

    def update(self, rows: np.ndarray, claimed: int) -> None:
        self.left -= claimed
        free = self.owner[rows] < 0
        some = free.any(axis=1)
        self.lo[rows] = np.where(some, free.argmax(axis=1), self.width)
        self.hi[rows] = np.where(some, self.width - 1 - free[:, ::-1].argmax(axis=1), -1)


def _cover(tri: np.ndarray, area2: np.ndarray, lo: np.ndarray, hi: np.ndarray, height: int, width: int,
           modes: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
    """Pass 1 of rasterize_uv: (H*W,) index into `tri` of the triangle holding each texel (-1: none),
    and (2, H*W) the tiles (u, v) of the image copy in which it holds it.

    Work goes in chunks of CHUNK: rows of triangles (each row weighted by the tiles it may cross),
    then candidates, so no array grows with the size or repetition of the UV triangles."""
    owner_map = np.full(height * width, -1, np.int64)
    tiles = np.zeros((2, height * width), np.int64)
    free = _Free(owner_map, height, width)
    rows = hi[:, 1] - lo[:, 1] + 1
    per_row = (hi[:, 0] - lo[:, 0]) // width + 2 if modes[0] != "clamp" else np.ones(len(tri), np.int64)
    ends = np.cumsum(rows * per_row)
    starts = ends - rows * per_row
    for begin in range(0, int(ends[-1]) if len(ends) else 0, CHUNK):
        if free.left == 0:
            break
        # The rows whose weighted start lies in [begin, begin + CHUNK), in face order then downwards.
        t = np.arange(np.searchsorted(ends, begin, side="right"), np.searchsorted(starts, begin + CHUNK))
        first = np.clip(-((starts[t] - begin) // per_row[t]), 0, rows[t])
        count = np.clip(-((starts[t] - begin - CHUNK) // per_row[t]), 0, rows[t]) - first
        t, first = np.repeat(t, count), np.repeat(first, count)
        y = lo[t, 1] + first + np.arange(t.size) - np.repeat(np.cumsum(count) - count, count)
        a, b = _row_spans(tri[t], area2[t], y, lo[t, 0], hi[t, 0])
        t, y, a, b = t[a <= b], y[a <= b], a[a <= b], b[a <= b]
        if modes[0] != "clamp":  # a span crossing copies of the image is cut at their edges
            tile_a, tile_b = a // width, b // width
            n = tile_b - tile_a + 1
            tile = np.repeat(tile_a, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
            t, y, a, b = np.repeat(t, n), np.repeat(y, n), np.repeat(a, n), np.repeat(b, n)
            a, b = np.maximum(a, tile * width), np.minimum(b, tile * width + width - 1)
        _claim(tri, area2, t, y, a, b, owner_map, tiles, free, height, width, modes)
    return owner_map, tiles


def _claim(tri, area2, t, y, a, b, owner_map, tiles, free: _Free, height: int, width: int,
           modes: tuple[str, str]) -> None:
    """Test the candidates of spans [a, b] (each within one copy of the image) on rows y of triangles
    t, in order and CHUNK at a time, and give each texel not yet held to the first that covers it."""
    row, tile_v = _texel(y, height, modes[1])
    col_a, tile_u = _texel(a, width, modes[0])
    col_b, _ = _texel(b, width, modes[0])
    # In a mirrored copy x runs right to left through the image's columns.
    flip = (tile_u % 2 == 1) if modes[0] == "mirror" else np.zeros(t.size, bool)
    left, right, base = np.minimum(col_a, col_b), np.maximum(col_a, col_b), tile_u * width
    while t.size and free.left:
        left, right = np.maximum(left, free.lo[row]), np.minimum(right, free.hi[row])
        some = left <= right
        t, row, tile_v, flip, left, right, base = (x[some] for x in (t, row, tile_v, flip, left, right, base))
        if not t.size:
            return
        length = right - left + 1
        k = max(int(np.searchsorted(np.cumsum(length), CHUNK, side="right")), 1)
        take = length[:k].copy()
        take[-1] = min(take[-1], CHUNK)  # a span longer than CHUNK goes in parts
        offset = np.arange(take.sum()) - np.repeat(np.cumsum(take) - take, take)
        owner = np.repeat(t[:k], take)
        px = np.repeat(base[:k] + np.where(flip[:k], width - 1 - right[:k], left[:k]), take) + offset
        py = np.repeat(_unwrapped(row[:k], tile_v[:k], height, modes[1]), take)
        bary = _barycentric(tri[owner], area2[owner], px, py)
        inside = (bary >= -1e-9).all(axis=1)
        col, copy_u = _texel(px[inside], width, modes[0])
        texel = np.repeat(row[:k], take)[inside] * width + col
        texel, first = np.unique(texel, return_index=True)  # the first candidate (in order) of each texel
        new = owner_map[texel] < 0
        texel, first = texel[new], first[new]
        owner_map[texel] = owner[inside][first]
        tiles[0, texel], tiles[1, texel] = copy_u[first], np.repeat(tile_v[:k], take)[inside][first]
        free.update(np.unique(texel // width), texel.size)
        if take[-1] < length[k - 1]:  # the rest of a long span stays for the next round
            left[k - 1] += np.where(flip[k - 1], 0, take[-1])
            right[k - 1] -= np.where(flip[k - 1], take[-1], 0)
            k -= 1
        t, row, tile_v, flip, left, right, base = (x[k:] for x in (t, row, tile_v, flip, left, right, base))


def _claim_points(tri: np.ndarray, owner_map: np.ndarray, tiles: np.ndarray, height: int, width: int,
                  modes: tuple[str, str]) -> np.ndarray:
    """Faces that hold no texel after pass 1 (UVs collapsed to a point, as palette and atlas textures
    are mapped, or smaller than a texel) take the texel a sampler reads at their UV centre, when no
    face holds it yet (in face order): a palette face's colour is the texel it samples. Under clamp, a
    centre outside the image takes nothing. Returns (F,) bool, the faces that took a texel."""
    held = np.zeros(len(tri), bool)
    held[owner_map[owner_map >= 0]] = True
    faces = np.flatnonzero(~held)
    point = np.zeros(len(tri), bool)
    if not faces.size:
        return point
    coord = np.floor(tri[faces].mean(axis=1) + 0.5).astype(np.int64)  # the texel whose square holds the centre
    col, tile_u = _texel(coord[:, 0], width, modes[0])
    row, tile_v = _texel(coord[:, 1], height, modes[1])
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    faces, col, row, tile_u, tile_v = (x[inside] for x in (faces, col, row, tile_u, tile_v))
    texel, first = np.unique(row * width + col, return_index=True)  # the first face (in order) of each texel
    new = owner_map[texel] < 0
    texel, first = texel[new], first[new]
    owner_map[texel] = faces[first]
    tiles[0, texel], tiles[1, texel] = tile_u[first], tile_v[first]
    point[faces[first]] = True
    return point


def _weights(tri: np.ndarray, area2: np.ndarray, point: np.ndarray, owner: np.ndarray, px: np.ndarray,
             py: np.ndarray) -> np.ndarray:
    """(K, 3) barycentric weights of points (px, py) in faces `owner`; a face that holds its texel as
    a point (see _claim_points) is read at its centre."""
    safe = np.where(point[owner], 1.0, area2[owner])
    bary = _barycentric(tri[owner], safe, px, py)
    bary[point[owner]] = 1.0 / 3.0
    return bary


def _barycentric(tri: np.ndarray, area2: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """(K, 3) barycentric weights of points (px, py) in triangles tri (K, 3, 2) of doubled signed area area2."""
    ax, ay = tri[:, 0, 0], tri[:, 0, 1]
    bx, by = tri[:, 1, 0], tri[:, 1, 1]
    cx, cy = tri[:, 2, 0], tri[:, 2, 1]
    w0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / area2
    w1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / area2
    return np.stack((w0, w1, 1.0 - w0 - w1), axis=1)
