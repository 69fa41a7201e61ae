"""Mitsuba 3 scenes built from plain arrays, rendered differentiably and bridged to torch.

One `AssetRenderer` owns one scene, built once. Each call updates what changed (texture maps,
environment map, camera) through `mi.traverse` and renders; gradients with respect to the maps and
the environment map flow back to torch through `dr.wrap`.

Conventions:
- World space is Blender's (Z up). Mitsuba's envmap is Y up, so the emitter gets `ENVMAP_TO_WORLD`,
  which makes a latitude-longitude map light the asset from the same directions as Blender's
  Environment Texture does (top row = +Z, bottom row = -Z; the centre column (u = 0.5) looks along
  +X, u = 0.25 along +Y, u = 0 / 1 along -X, u = 0.75 along -Y; see `blender_direction_to_equirect_uv`,
  checked against Cycles in tests/blender/test_lighting_blender.py).
- Mesh UVs arrive in OpenGL convention (v = 0 at the bottom); Mitsuba looks textures up with v = 0 at
  the top row, so v is flipped when the mesh is built.
- Maps are torch tensors (H, W, C), linear, rows top to bottom as in image files.
"""
from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from .backend import Backend, init_mitsuba
from .orbit_camera import Camera
from ..base.errors import InputError
from ..data.maps import FLAT_NORMAL
from ..data.materials import MaterialPart, material_parts
from ..data.mesh import Mesh, vertex_normals
from ..scene.frame import ENVMAP_TO_WORLD
from ..data.uv_raster import wrap_modes


# Each material's BSDF's maps, under its shape's id; with a normal map the principled BSDF sits inside
# Mitsuba's `normalmap` BSDF, one level down.
MAP_NAMES = ("base_color", "roughness", "metallic")
# The renderers a differentiable render can be asked of: the loop renderer (core/render/loop_renderer.py:
# cached G-buffers shaded in torch) and Mitsuba's path tracing (this module).
RENDERER_TYPES = ("loop", "path")
ENVMAP_KEY = "environment.data"


@dataclass(frozen=True)
class SphereSpec:
    """The light-capturing apparatus: a white, smooth, diffuse sphere."""

    center: tuple[float, float, float] = (0.9, 0.0, -0.25)
    radius: float = 0.25
    albedo: float = 1.0


@dataclass(frozen=True)
class SceneOptions:
    floor: bool = False             # infinite diffuse floor under the asset, for shadows
    floor_albedo: float = 0.8
    sphere: SphereSpec | None = None
    max_depth: int = 6              # path length; 2 is direct light only
    integrator_type: str = "prb"    # "prb" (path replay, cheap gradients) or "path"
    floor_extent: float = 1000.0
    hide_emitters: bool = False     # True: the environment is not seen directly (rgb is 0 where alpha is 0)

    def __post_init__(self) -> None:
        if self.integrator_type not in ("prb", "path"):
            raise InputError(f"integrator_type must be 'prb' or 'path', got {self.integrator_type!r}.")
        if self.max_depth < 2 and self.max_depth != -1:
            raise InputError(f"max_depth must be at least 2 (camera -> surface -> light), got {self.max_depth}.")


@dataclass(frozen=True)
class WindowCamera:
    """A pinhole given by its pose, rendering only the pixels `crop` (x0, y0, width, height) of a
    `film` (width, height) image; fov_x_deg spans the film's width. The adapt stage's global views use
    it for the photo camera seen from the asset's own frame (core/stages/compose.py)."""

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_x_deg: float
    film: tuple[int, int]
    crop: tuple[int, int, int, int]
    film_offset: tuple[float, float] = (0.0, 0.0)   # the lens shift: PhotoCamera.film_offset

    @property
    def width(self) -> int:
        return self.crop[2]

    @property
    def height(self) -> int:
        return self.crop[3]


@dataclass
class RenderOutput:
    """Torch tensors (h, w, C): radiance is linear HDR; alpha is 1 where the asset (or floor/sphere) is."""

    rgb: Any
    alpha: Any
    seconds: float = 0.0


def _owned(array_type, values: np.ndarray):
    """`values` as a Dr.Jit array in memory of its own. Built straight from NumPy it would share NumPy's
    memory, whose alignment varies from run to run, and Dr.Jit reads an unaligned buffer with other
    instructions: the same scene would compile a kernel that differs from the cached one."""
    import drjit as dr  # lazy: Mitsuba is heavy and Blender may lack it

    owned = array_type(values) + dr.opaque(array_type, 0)
    dr.eval(owned)
    return owned


def _mitsuba_mesh(mi, mesh: Mesh):
    """A mi.Mesh from our arrays (v flipped to Mitsuba's top-row-first texture lookup)."""
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.faces)
    m = mi.Mesh(mesh.name, vertex_count=len(mesh.positions), face_count=len(mesh.faces),
                has_vertex_normals=True, has_vertex_texcoords=True)
    params = mi.traverse(m)
    uv = mesh.uvs.astype(np.float32).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    params["vertex_positions"] = _owned(mi.Float, mesh.positions.astype(np.float32).ravel())
    params["faces"] = _owned(mi.UInt32, mesh.faces.astype(np.uint32).ravel())
    params["vertex_normals"] = _owned(mi.Float, normals.astype(np.float32).ravel())
    params["vertex_texcoords"] = _owned(mi.Float, uv.ravel())
    params.update()
    return m


def _bitmap_texture(mi, data: np.ndarray, wrap: str = "repeat") -> dict:
    data = np.ascontiguousarray(data, dtype=np.float32)
    if data.ndim == 2:
        data = data[..., None]
    return {"type": "bitmap", "bitmap": mi.Bitmap(data), "raw": True, "filter_type": "bilinear", "wrap_mode": wrap}


@dataclass(frozen=True)
class DrawnPart:
    """A material part as Mitsuba draws it. Mitsuba has one wrap mode per bitmap, so a part whose u and
    v wrap differently is drawn with the same result another way (see drawn_part): `mesh` holds the
    UVs drawn, `mode` is the bitmaps' wrap mode, and `doubled` the axis (0 = u, 1 = v) whose texels
    are followed by their mirror image, or None."""

    part: MaterialPart
    mesh: Mesh
    mode: str
    doubled: int | None = None

    def texels(self, maps):
        """This part's texels of torch maps (H, W, C), as its bitmaps hold them (gradients flow through)."""
        import torch  # lazy: torch takes seconds to load

        cell = maps[self.part.rows, self.part.cols]
        if self.doubled is not None:
            cell = torch.cat([cell, torch.flip(cell, dims=[1 - self.doubled])], dim=1 - self.doubled)
        return cell.float().contiguous()


def drawn_part(part: MaterialPart) -> DrawnPart:
    """How Mitsuba draws `part` with its wrap mode (u, v) exactly. One mode for both: the bitmaps wrap so.
    A clamped axis beside another mode: its UVs are cut at the centres of its edge texels and held
    there (past them clamp reads the edge texels, as any mode does at those UVs), and the bitmaps wrap
    as the other axis says. Repeat beside mirror: the texels followed by their mirror image along the
    mirrored axis, repeated, at half that axis's UV (one mirror period is one repeat of the pair)."""
    u, v = wrap_modes(part.wrap)
    if u == v:
        return DrawnPart(part, part.mesh, u)
    mesh, size = part.mesh, (part.cols.stop - part.cols.start, part.rows.stop - part.rows.start)
    for axis, mode in enumerate((u, v)):
        if mode == "clamp":
            low, high = 0.5 / size[axis], 1.0 - 0.5 / size[axis]
            mesh = cut_at_uv(cut_at_uv(mesh, axis, low), axis, high)
            uv = mesh.uvs.copy()
            uv[:, axis] = np.clip(uv[:, axis], low, high)
            mesh = Mesh.from_arrays(mesh.positions, mesh.faces, uv, mesh.normals, mesh.name)
    rest = [mode for mode in (u, v) if mode != "clamp"]
    if len(rest) == 1:
        return DrawnPart(part, mesh, rest[0])
    axis = (u, v).index("mirror")
    uv = mesh.uvs.astype(np.float64)
    # Rows run top first (v = 1 is row 0): the doubled image's lower half is the mirror below v = 0.
    uv[:, axis] = uv[:, 0] / 2 if axis == 0 else (1.0 + uv[:, 1]) / 2
    return DrawnPart(part, Mesh.from_arrays(mesh.positions, mesh.faces, uv, mesh.normals, mesh.name), "repeat", axis)


def cut_at_uv(mesh: Mesh, axis: int, value: float) -> Mesh:
    """`mesh` with every triangle that crosses the line uv[axis] = value cut along it (into three), so
    each piece lies on one side. Cut points are made once per edge, so neighbours share them."""
    coord = mesh.uvs[:, axis].astype(np.float64)
    above = coord[mesh.faces] > value
    crossing = above.any(axis=1) & ~above.all(axis=1)
    if not crossing.any():
        return mesh
    faces, side = mesh.faces[crossing].astype(np.int64), above[crossing]
    lone = np.where(side.sum(axis=1) == 1, side.argmax(axis=1), (~side).argmax(axis=1))
    a, b, c = np.take_along_axis(faces, (lone[:, None] + np.arange(3)) % 3, axis=1).T  # winding kept
    edges, inverse = np.unique(np.sort(np.concatenate([np.stack([a, b], 1), np.stack([a, c], 1)]), axis=1),
                               axis=0, return_inverse=True)
    lo, hi = edges.T
    t = ((value - coord[lo]) / (coord[hi] - coord[lo]))[:, None]
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.faces)

    def at_cuts(attr: np.ndarray) -> np.ndarray:
        attr = attr.astype(np.float64)
        return np.concatenate([attr, attr[lo] + t * (attr[hi] - attr[lo])])

    uv, cut_normals = at_cuts(mesh.uvs), at_cuts(normals)
    uv[len(mesh.uvs):, axis] = value
    cut_normals /= np.maximum(np.linalg.norm(cut_normals, axis=1, keepdims=True), 1e-12)
    ab, ac = np.split(len(mesh.positions) + inverse.reshape(-1), 2)
    pieces = np.concatenate([np.stack([a, ab, ac], 1), np.stack([ab, b, c], 1), np.stack([ab, c, ac], 1)])
    return Mesh.from_arrays(at_cuts(mesh.positions), np.concatenate([mesh.faces[~crossing], pieces]), uv,
                            cut_normals, mesh.name)


def material_shapes(mi, mesh: Mesh, maps: np.ndarray, normal_map: np.ndarray | None = None
                    ) -> tuple[dict[str, object], dict[str, DrawnPart], dict[str, dict[str, str]]]:
    """The asset as Mitsuba shapes, one per material part (core.materials.material_parts), each with a
    principled BSDF whose bitmaps hold its texels of `maps` (H, W, 5) and wrap as its sampler says;
    inside a `normalmap` BSDF where `normal_map` (H, W, 3) has a map for it (a cell that is all flat
    is a material without one). Returns the shapes, the drawn parts and each part's map parameters,
    all by shape id."""
    import torch  # lazy: torch takes seconds to load

    maps = torch.from_numpy(np.ascontiguousarray(maps, dtype=np.float32))
    parts = material_parts(mesh, (int(maps.shape[0]), int(maps.shape[1])))
    if normal_map is not None:   # its own size: each part reads its own cell of it
        normal_map = torch.from_numpy(np.ascontiguousarray(normal_map, dtype=np.float32))
        normal_parts = {p.index: p for p in material_parts(mesh, tuple(normal_map.shape[:2]))}
    shapes, drawn, keys = {}, {}, {}
    for part in parts:
        shape_id = "asset" if len(parts) == 1 else f"asset_{part.index}"
        drawn[shape_id] = piece = drawn_part(part)
        texels = piece.texels(maps).numpy()
        bsdf = {"type": "principled", **{name: _bitmap_texture(mi, texels[..., lo:hi], piece.mode)
                                         for name, (lo, hi) in zip(MAP_NAMES, ((0, 3), (3, 4), (4, 5)))}}
        prefix = f"{shape_id}.bsdf."
        normal = None if normal_map is None else replace(piece, part=normal_parts[part.index]).texels(normal_map).numpy()
        if normal is not None and not np.allclose(normal, FLAT_NORMAL):
            bsdf = {"type": "normalmap", "normalmap": _bitmap_texture(mi, np.clip(normal, 0.0, 1.0), piece.mode),
                    "bsdf": bsdf}
            prefix += "nested_bsdf."
        keys[shape_id] = {name: f"{prefix}{name}.data" for name in MAP_NAMES}
        shapes[shape_id] = _mitsuba_mesh(mi, piece.mesh)
        shapes[shape_id].set_bsdf(mi.load_dict(bsdf))
    return shapes, drawn, keys


def pad_envmap(envmap):
    """Mitsuba stores the map with one wrapped column on each side (so bilinear lookups wrap)."""
    import torch  # lazy: torch takes seconds to load

    return torch.cat([envmap[:, -1:], envmap, envmap[:, :1]], dim=1)


class AssetRenderer:
    """A Mitsuba scene of one asset under an environment map, built once and updated per render."""

    def __init__(self, mesh: Mesh, maps_shape: tuple[int, int], envmap: np.ndarray,
                 options: SceneOptions = SceneOptions(), variant: str | None = None,
                 normal_map: np.ndarray | None = None) -> None:
        """normal_map: optional (H, W, 3) tangent-space map in [0, 1] (OpenGL convention, as glTF and
        Blender store it), fixed for the renderer's life. Mitsuba's `normalmap` BSDF perturbs the
        shading normal in the frame of the UV derivative dp/du, so the mesh's UVs give the tangents."""
        self.backend: Backend = init_mitsuba(variant)
        import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

        envmap = np.asarray(envmap, dtype=np.float32)
        if envmap.ndim != 3 or envmap.shape[2] != 3 or envmap.shape[1] != 2 * envmap.shape[0]:
            raise InputError(f"The environment map must be RGB with width = 2 x height, got {envmap.shape}.")
        if not np.isfinite(envmap).all() or envmap.min() < 0:
            raise InputError("The environment map holds negative, NaN or infinite radiance.")
        h, w = maps_shape
        self.mesh, self.options, self.maps_shape = mesh, options, (h, w)
        self.envmap_shape = envmap.shape
        if normal_map is not None:
            normal_map = np.asarray(normal_map, dtype=np.float32)
            if normal_map.ndim != 3 or normal_map.shape[2] != 3 or not np.isfinite(normal_map).all():
                raise InputError(f"The normal map must be a finite RGB image, got shape {normal_map.shape}.")
        grey = np.concatenate([np.full((h, w, 4), 0.5, np.float32), np.zeros((h, w, 1), np.float32)], axis=-1)
        # One shape per material, each sampling its own texels with its own wrap mode (material_shapes).
        shapes, self.parts, self.keys = material_shapes(mi, mesh, grey, normal_map)
        scene: dict = {
            "type": "scene",
            "integrator": {"type": options.integrator_type, "max_depth": options.max_depth,
                           "hide_emitters": options.hide_emitters},
            "environment": {"type": "envmap", "bitmap": mi.Bitmap(envmap),
                            "to_world": mi.ScalarTransform4f(ENVMAP_TO_WORLD)},
            **shapes,
        }
        if options.floor:
            z = float(mesh.positions[:, 2].min())
            scene["floor"] = {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, z]).scale(options.floor_extent),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": options.floor_albedo}},
            }
        if options.sphere is not None:
            s = options.sphere
            scene["apparatus"] = {
                "type": "sphere", "center": list(s.center), "radius": s.radius,
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": s.albedo}},
            }
        self.scene = mi.load_dict(scene)
        self.params = mi.traverse(self.scene)
        wanted = [*(key for keys in self.keys.values() for key in keys.values()), ENVMAP_KEY]
        for key in wanted:
            if key not in self.params:
                raise RuntimeError(f"Mitsuba scene lacks parameter {key}; got {list(self.params.keys())[:20]}")
        self.params.keep(wanted)
        self._sensors: dict[tuple, object] = {}   # by film size; a window's by film, crop and offset
        self._aov_integrator = None
        self._sensor_by_index: dict[int, object] = {}
        self._wrapped: Callable | None = None
        # weak reference to a differentiable render whose backward has not run
        self._pending: weakref.ReferenceType | None = None

    # -- cameras -------------------------------------------------------------------------------
    def _sensor(self, camera: "Camera | WindowCamera"):
        import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

        if isinstance(camera, WindowCamera):
            return self._window_sensor(camera)
        key = (camera.width, camera.height)
        if key not in self._sensors:
            self._sensors[key] = mi.load_dict({
                "type": "perspective", "fov": 40.0, "fov_axis": "x",
                "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                         "pixel_format": "rgba", "rfilter": {"type": "box"}},
                "sampler": {"type": "independent"},
            })
        sensor = self._sensors[key]
        p = mi.traverse(sensor)
        # The paper's FOV applies to the smaller image side; Mitsuba takes it along x.
        fov_small = np.radians(camera.fov_deg)
        aspect = camera.width / camera.height
        fov_x = fov_small if aspect <= 1 else 2 * np.arctan(np.tan(fov_small / 2) * aspect)
        p["x_fov"] = float(np.degrees(fov_x))
        p["to_world"] = mi.Transform4f().look_at(origin=camera.origin.tolist(), target=list(camera.target),
                                                 up=[0.0, 0.0, 1.0])
        p.update()
        return sensor

    def _window_sensor(self, camera: WindowCamera):
        """One sensor per film and crop; its pose and field of view are updated in place (no recompile)."""
        import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

        key = ("window", camera.film, camera.crop, camera.film_offset)
        if key not in self._sensors:
            x0, y0, w, h = camera.crop
            self._sensors[key] = mi.load_dict({
                "type": "perspective", "fov": 40.0, "fov_axis": "x",
                "principal_point_offset_x": camera.film_offset[0], "principal_point_offset_y": camera.film_offset[1],
                "film": {"type": "hdrfilm", "width": camera.film[0], "height": camera.film[1], "pixel_format": "rgba",
                         "rfilter": {"type": "box"}, "crop_offset_x": x0, "crop_offset_y": y0,
                         "crop_width": w, "crop_height": h},
                "sampler": {"type": "independent"},
            })
        sensor = self._sensors[key]
        p = mi.traverse(sensor)
        p["x_fov"] = float(camera.fov_x_deg)
        p["to_world"] = mi.Transform4f().look_at(origin=[float(v) for v in camera.origin],
                                                 target=[float(v) for v in camera.target],
                                                 up=[float(v) for v in camera.up])
        p.update()
        return sensor

    # -- rendering -----------------------------------------------------------------------------
    def _render_fn(self):
        if self._wrapped is None:
            # lazy: Mitsuba is heavy and Blender may lack it
            import drjit as dr
            import mitsuba as mi

            # The function holds the scene's parts, not the renderer: a renderer in a reference cycle lives
            # until Python's cycle collector runs, and while its Mitsuba objects live every new scene's
            # kernels also dispatch to them, so they differ from the cached ones and compile again.
            params, keys, scene, sensors = self.params, self.keys, self.scene, self._sensor_by_index

            @dr.wrap(source="torch", target="drjit")
            def render(texels: dict, envmap, sensor_index: int, spp: int, seed: int):
                for shape_id, maps in texels.items():
                    for name, values in zip(MAP_NAMES, maps):
                        params[keys[shape_id][name]] = values
                params[ENVMAP_KEY] = envmap
                params.update()
                sensor = sensors[sensor_index]
                # Seeds are opaque so a new seed does not recompile the kernel.
                return mi.render(scene, params, sensor=sensor, spp=spp,
                                 seed=dr.opaque(mi.UInt32, seed), seed_grad=dr.opaque(mi.UInt32, seed + 0x9E37))

            self._wrapped = render
        return self._wrapped

    def render(self, camera: "Camera | WindowCamera", base_color, roughness, metallic, envmap, spp: int = 16,
               seed: int = 0) -> RenderOutput:
        """Render RGBA. Arguments are torch tensors: maps (H, W, 3|1), envmap (He, We, 3), linear.

        Tensors that require grad receive gradients through `dr.wrap` on backward().
        """
        import torch  # lazy: torch takes seconds to load

        t0 = time.perf_counter()
        self._refuse_while_backward_pending()
        maps = [self._check_map(base_color, 3, "base colour"), self._check_map(roughness, 1, "roughness"),
                self._check_map(metallic, 1, "metallic")]
        if tuple(envmap.shape) != tuple(self.envmap_shape):
            raise InputError(f"Environment map shape {tuple(envmap.shape)} differs from the scene's {self.envmap_shape}.")
        sensor = self._sensor(camera)
        self._sensor_by_index[0] = sensor
        # Each part's own texels (torch slices, so gradients reach the maps given).
        # Moved to the renderer's backend (an environment map on the CPU beside a texture on the GPU must
        # not reach a CUDA scene as an LLVM array), and the image back to where the maps are.
        device = self.backend.torch_device
        texels = {shape_id: [part.texels(m).to(device) for m in maps] for shape_id, part in self.parts.items()}
        image = self._render_fn()(texels, pad_envmap(envmap.float()).to(device), 0, int(spp), int(seed))
        image = image.to(device=maps[0].device, dtype=torch.float32)
        if image.requires_grad:
            self._track_pending(image)
        return RenderOutput(rgb=image[..., :3], alpha=image[..., 3:4], seconds=time.perf_counter() - t0)

    # Mitsuba's backward replays the render from the scene's *current* state (camera, maps, light), so a
    # second render through this scene before the first one's backward would silently give the first
    # one wrong gradients. Refuse instead; a render dropped without backward stops counting.
    def _track_pending(self, image) -> None:
        self._pending = weakref.ref(image)

        def done(grad):
            self._pending = None
            return grad

        image.register_hook(done)

    def _refuse_while_backward_pending(self) -> None:
        if self._pending is not None and self._pending() is not None:
            raise RuntimeError(
                "A differentiable render of this scene is still waiting for backward(); call backward() (or drop "
                "the result) before rendering again, since Mitsuba replays a render from the scene's current state."
            )
        self._pending = None

    def _check_map(self, tensor, channels: int, name: str):
        if tensor.ndim == 2:
            tensor = tensor[..., None]
        if tuple(tensor.shape) != (*self.maps_shape, channels):
            raise InputError(f"The {name} map has shape {tuple(tensor.shape)}, expected {(*self.maps_shape, channels)}.")
        return tensor

    def render_albedo(self, camera: Camera, maps: np.ndarray) -> np.ndarray:
        """(H, W, 4): the base colour of `maps` (H, W, 5) seen at each pixel centre, and 1 where the asset
        is hit (0 elsewhere): what the texture shows, without light or noise."""
        # lazy: Mitsuba and torch are heavy, and Blender may lack Mitsuba
        import mitsuba as mi
        import torch

        stack = torch.from_numpy(np.ascontiguousarray(maps, np.float32))
        self.render(camera, stack[..., 0:3], stack[..., 3:4], stack[..., 4:5],
                    torch.ones(self.envmap_shape, dtype=torch.float32), spp=1)   # sets the maps into the scene
        integrator = mi.load_dict({"type": "aov", "aovs": "aa:albedo,dd:depth"})
        image = np.array(mi.render(self.scene, sensor=self._sensor(camera), integrator=integrator, spp=1))
        return np.concatenate([image[..., 0:3], (image[..., 3:4] > 0).astype(np.float32)], axis=2)

    def render_aovs(self, camera: Camera) -> dict[str, np.ndarray]:
        """Shading normals (world space), depth and coverage, one sample at pixel centres, no gradients."""
        import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

        self._refuse_while_backward_pending()
        if self._aov_integrator is None:
            self._aov_integrator = mi.load_dict({"type": "aov", "aovs": "nn:sh_normal,dd:depth"})
        sensor = self._sensor(camera)
        # Without a nested integrator the aov integrator returns exactly its channels: nn.xyz, dd.
        image = np.array(mi.render(self.scene, sensor=sensor, integrator=self._aov_integrator, spp=1))
        normals = image[..., 0:3]
        depth = image[..., 3]
        return {"normal": normals, "depth": depth, "coverage": (depth > 0).astype(np.float32)}
