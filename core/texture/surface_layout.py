"""A new UV layout for an adapted texture where the asset's own UVs cannot hold a result per surface.

The residual adaptation learns lives on the surface (the hash grid takes 3D points); the asset's
own maps live in its UVs. Where faces share texels (mirrored halves, tiling, palette textures whose
UVs collapse to points), a texture read through those UVs shows one surface's residual on all of
them, and adaptation can only paint what they share. So adaptation decides once, from the UVs
(`uv_sharing`): past SHARED_LIMIT of the surface it works in a new layout made by xatlas, records it
in texture.pt (`SurfaceLayout`), and every later view of that texture (compose, render, the game
bake's new UV set) reads it there: each new texel's base is the asset's own map sampled at that
point's own UV, its residual the network at that point. Without adaptation nothing is re-mapped.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from ..base.errors import InputError
from ..data.materials import atlas_grid, atlas_slices, mesh_digest, mesh_raster, own_uv_mesh
from ..data.mesh import Mesh, normalize_to_unit_sphere
from .neural_texture import NeuralTexture, to_logit
from ..data.uv_raster import UVRaster, rasterize_uv, sample_image

# More than this share of the surface reading texels another part also reads: a new layout.
SHARED_LIMIT = 0.05
# The raster the sharing is measured on (texel centres inside UV triangles, per material).
SHARING_SIDE = 512
# A face whose texel density is below this share of the asset's median has collapsed UVs (a palette).
COLLAPSED_DENSITY = 1e-3
# Empty texels between xatlas's charts, so bilinear reads and seam dilation never mix two charts.
CHART_PADDING = 2


@dataclass(frozen=True)
class UVSharing:
    """Shares of the surface area (0..1) whose texels another part of the surface also reads.

    collapsed: faces whose UVs have (almost) no area, as palette textures make them.
    overlapped: faces whose UV area lies over other faces' (mirrored halves, repeats, stacked islands).
    """

    collapsed: float
    overlapped: float

    @property
    def shared(self) -> float:
        return self.collapsed + self.overlapped

    def needs_new_layout(self) -> bool:
        return self.shared > SHARED_LIMIT

    def report(self) -> dict:
        return {"shared_surface": round(self.shared, 4), "collapsed_surface": round(self.collapsed, 4),
                "overlapped_surface": round(self.overlapped, 4), "limit": SHARED_LIMIT}


def uv_sharing(mesh: Mesh, side: int = SHARING_SIDE) -> UVSharing:
    """How much of `mesh`'s surface shares texels, each material in its own UVs and wrap mode (an atlas
    mesh as fitting_view gives it, or a plain one). Overlap is the UV area laid beyond the union that
    the texel centres show; a material's overlap is spread over its faces by their 3D area."""
    own = own_uv_mesh(mesh)
    corners = own.positions.astype(np.float64)[own.faces]
    area3 = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    uv = own.uvs.astype(np.float64)[own.faces]
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    area_uv = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    total = area3.sum()
    if total <= 0:
        raise InputError(f"Mesh '{mesh.name}' has no surface area.")
    density = np.divide(area_uv, area3, out=np.zeros_like(area3), where=area3 > 0)
    typical = _weighted_median(density, area3)
    collapsed = (area3 > 0) & (density <= COLLAPSED_DENSITY * typical)
    material = np.zeros(len(own.faces), np.int64) if own.material_index is None else own.material_index
    wraps = list(mesh.wraps) or [("repeat", "repeat")] * mesh.material_count
    overlapped = 0.0
    for index in range(mesh.material_count):
        faces = (material == index) & ~collapsed & (area3 > 0)
        laid = area_uv[faces].sum()
        if laid <= 0:
            continue
        part = Mesh.from_arrays(own.positions, own.faces[faces], own.uvs, name=mesh.name)
        try:
            union = rasterize_uv(part, side, wrap=wraps[index], border_width=0.0).mask.mean()
        except InputError:   # clamped UVs wholly outside [0, 1]: every face reads the image's edge
            union = 0.0
        overlapped += max(0.0, 1.0 - union / laid) * area3[faces].sum()
    return UVSharing(collapsed=float(area3[collapsed].sum() / total), overlapped=float(overlapped / total))


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


@dataclass(frozen=True)
class SurfaceLayout:
    """The new layout an adapted texture is read in: UVs per face corner (F, 3, 2) of the asset's
    (fitting view) mesh, in its face order; `mesh_digest` names that mesh (its faces and own UVs)."""

    corner_uvs: np.ndarray
    mesh_digest: str
    sharing: dict
    seconds: float = 0.0

    def to_payload(self) -> dict:
        return {"corner_uvs": torch.from_numpy(np.ascontiguousarray(self.corner_uvs, np.float32)),
                "mesh_digest": self.mesh_digest, "sharing": dict(self.sharing)}

    @staticmethod
    def from_payload(payload: dict) -> "SurfaceLayout":
        uvs = payload["corner_uvs"]
        return SurfaceLayout(np.asarray(uvs.numpy() if torch.is_tensor(uvs) else uvs, np.float32),
                             str(payload["mesh_digest"]), dict(payload.get("sharing", {})))

    def remapped(self, mesh: Mesh) -> Mesh:
        """`mesh` (in any space) with this layout's UVs: one vertex per face corner."""
        if mesh_digest(mesh) != self.mesh_digest or len(mesh.faces) != len(self.corner_uvs):
            raise InputError(f"This texture was adapted in a new UV layout of another mesh than '{mesh.name}'; "
                             "adapt it again for this asset.")
        faces = mesh.faces
        corners = np.arange(3 * len(faces)).reshape(-1, 3)
        normals = None if mesh.normals is None else mesh.normals[faces].reshape(-1, 3)
        count = mesh.material_count
        return Mesh.from_arrays(mesh.positions[faces].reshape(-1, 3), corners, self.corner_uvs.reshape(-1, 2),
                                normals, mesh.name, mesh.material_index, (("clamp", "clamp"),) * count)


def new_layout(mesh: Mesh, resolution: int, sharing: UVSharing) -> SurfaceLayout:
    """xatlas's charts of `mesh` packed for a resolution² texture, as UVs per face corner."""
    import xatlas  # lazy: its wheel is not on every platform

    started = time.perf_counter()
    atlas = xatlas.Atlas()
    atlas.add_mesh(np.ascontiguousarray(mesh.positions, np.float32), np.ascontiguousarray(mesh.faces, np.uint32))
    charts = xatlas.ChartOptions()
    charts.max_iterations = 1            # one growing pass: 3x faster than the default, charts as usable
    pack = xatlas.PackOptions()
    pack.resolution, pack.padding = int(resolution), CHART_PADDING
    atlas.generate(chart_options=charts, pack_options=pack)
    _, indices, uvs = atlas.get_mesh(0)
    indices = np.asarray(indices, np.int64).reshape(-1, 3)
    if len(indices) != len(mesh.faces):
        raise InputError(f"xatlas returned {len(indices)} faces for the {len(mesh.faces)} of '{mesh.name}'.")
    return SurfaceLayout(np.asarray(uvs, np.float32)[indices], mesh_digest(mesh), sharing.report(),
                         time.perf_counter() - started)


@dataclass(frozen=True)
class TextureView:
    """A texture as a renderer reads it on a mesh: the mesh (remapped when the texture has a layout),
    its raster at the texture's resolution, and the base for that raster (None: the texture's own)."""

    mesh: Mesh
    raster: UVRaster
    base_logit: torch.Tensor | None
    report: dict

    def stack(self, texture: NeuralTexture) -> np.ndarray:
        """(R, R, 5) maps in this view's layout."""
        raster = self.raster
        with torch.no_grad():
            maps = texture.texture(raster.position, raster.border, raster.fill_index, self.base_logit)
        return maps.cpu().numpy().astype(np.float32)


def texture_view(texture: NeuralTexture, mesh: Mesh, layout: SurfaceLayout | None = None) -> TextureView:
    """How `texture` is read on `mesh` (its fitting view, in any space): in the texture's new layout when it
    has one (or `layout`), else in the mesh's own UVs. The view's mesh is in `mesh`'s space."""
    layout = layout or getattr(texture, "layout", None)
    normalized, _ = normalize_to_unit_sphere(mesh)
    resolution = texture.config.resolution
    if layout is None:
        return TextureView(mesh, mesh_raster(normalized, resolution), None, {"uv_layout": "own"})
    remapped = layout.remapped(normalized)
    raster = rasterize_uv(remapped, resolution, wrap="clamp")
    base = transferred_base(texture, normalized, raster) if texture.config.residual else None
    report = {"uv_layout": "new (xatlas)", **layout.sharing}
    return TextureView(layout.remapped(mesh), raster, base, report)


def adapting_view(texture: NeuralTexture | None, mesh: Mesh) -> tuple[TextureView | None, SurfaceLayout | None, dict]:
    """The view adaptation works in, decided from `mesh`'s UVs (its fitting view, normalised), with the
    report of why: (None, None, report) keeps the asset's own UVs. A texture already adapted in a new
    layout keeps it; a fresh one ("generate") has no base to carry and keeps the own UVs."""
    if texture is None:
        return None, None, {"uv_layout": "own", "why": "a generated texture is made in the asset's own UVs"}
    if isinstance(texture.layout, SurfaceLayout):   # (the one layout a texture is saved with)
        view = texture_view(texture, mesh)
        return view, texture.layout, dict(view.report, why="the texture was adapted in this layout before")
    sharing = uv_sharing(mesh)
    if not sharing.needs_new_layout():
        return None, None, {"uv_layout": "own", **sharing.report(),
                            "why": "every surface has its own texels in the asset's UVs"}
    try:
        import xatlas  # noqa: F401  (bundled where PyPI has a wheel; not for Linux arm64)
    except ImportError:
        return None, None, {"uv_layout": "own", **sharing.report(),
                            "why": f"{sharing.shared:.0%} of the surface shares texels in the asset's UVs, but "
                                   "xatlas (the unwrapper) is not installed here, so surfaces that share texels "
                                   "show one result"}
    try:
        layout = new_layout(normalize_to_unit_sphere(mesh)[0], texture.config.resolution, sharing)
        view = texture_view(texture, mesh, layout)
    except (RuntimeError, ValueError, InputError) as error:   # xatlas failed, or its charts hold no texel
        return None, None, {"uv_layout": "own", **sharing.report(),
                            "why": f"{sharing.shared:.0%} of the surface shares texels in the asset's UVs, but no "
                                   f"new layout could be made ({str(error)[:160]}), so surfaces that share texels "
                                   "show one result"}
    why = (f"{sharing.shared:.0%} of the surface shares texels in the asset's UVs (collapsed "
           f"{sharing.collapsed:.0%}, overlapping {sharing.overlapped:.0%}), so a result there could not "
           "differ per surface; adapted in a new layout by xatlas")
    return view, layout, dict(view.report, why=why, seconds=round(layout.seconds, 2))


def own_uvs_at(raster: UVRaster, own: Mesh, face_ids: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 2): at each texel of `raster` (a remapped mesh's, whose face k is own face face_ids[k], or k),
    the UV that surface point has in `own`'s own layout; texels outside every chart copy their nearest."""
    border = raster.border.reshape(-1)
    face = raster.face.reshape(-1)[border]
    if face_ids is not None:
        face = face_ids[face]
    uv = np.einsum("nk,nkc->nc", raster.barycentric.reshape(-1, 3)[border].astype(np.float64),
                   own.uvs.astype(np.float64)[own.faces[face]])
    flat = np.zeros((border.size, 2), np.float64)
    flat[border] = uv
    return flat[raster.fill_index].reshape(*raster.resolution, 2)


def transferred_base(texture: NeuralTexture, mesh: Mesh, raster: UVRaster) -> torch.Tensor:
    """The texture's stored base (the asset's maps in `mesh`'s own layout: an atlas of cells for several
    materials) read at each texel of `raster` (a remapped mesh's, same faces) through that point's own
    UV, with its material's wrap mode; as logits."""
    values = texture.base_values().detach().cpu().numpy()
    uv = own_uvs_at(raster, own_uv_mesh(mesh)).reshape(-1, 2)
    nearest_face = raster.face.reshape(-1)[raster.fill_index]
    material = np.zeros(len(uv), np.int64) if mesh.material_index is None else mesh.material_index[nearest_face]
    wraps = list(mesh.wraps) or [("repeat", "repeat")] * mesh.material_count
    count = mesh.material_count
    cells = atlas_slices(count, len(values) // atlas_grid(count)) if mesh.atlas else \
        [(slice(None), slice(None))] * count
    read = np.zeros((len(uv), values.shape[2]), np.float32)
    for index, (rows, cols) in enumerate(cells):
        chosen = material == index
        if chosen.any():
            read[chosen] = sample_image(values[rows, cols], uv[chosen], wraps[index])
    stack = torch.from_numpy(read.reshape(*raster.resolution, values.shape[2]))
    config = texture.config
    return to_logit(stack, torch.tensor(config.channel_min), torch.tensor(config.channel_max))
