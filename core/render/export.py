"""Write an asset, its maps, a camera and the lighting as a Mitsuba 3 scene that `mitsuba` renders alone.

Layout written into `out_dir`:
    scene.xml, mesh.ply, base_color.png (sRGB), roughness.png / metallic.png (linear), envmap.exr
Several materials are several shapes, each with its own UVs, images and wrap mode (mesh_0.ply,
base_color_0.png, ...), as SceneFit's renders draw them (never one atlas whose tiling UVs read a
neighbouring material's cell).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.atomic import TEMP_MARK, write_text_atomic
from .backend import init_mitsuba
from .orbit_camera import Camera
from ..base.errors import InputError
from ..data.imageio import linear_to_srgb, write_image
from ..data.maps import PBRMaps
from ..data.materials import material_parts
from ..data.mesh import Mesh, normalize_to_unit_sphere
from .environment import check_environment
from .renderer import _mitsuba_mesh, drawn_part
from ..scene.frame import ENVMAP_TO_WORLD


def _add(parent: ET.Element, tag: str, **attrs) -> ET.Element:
    return ET.SubElement(parent, tag, {k: str(v) for k, v in attrs.items()})


def _matrix(parent: ET.Element, name: str, m: np.ndarray) -> None:
    t = _add(parent, "transform", name=name)
    _add(t, "matrix", value=" ".join(f"{x:.9g}" for x in np.asarray(m, dtype=np.float64).ravel()))


def _texture_or_value(parent: ET.Element, name: str, value, filename: str | None, wrap: str = "repeat") -> None:
    if filename is None:
        _add(parent, "float", name=name, value=f"{float(value):.6g}")
        return
    tex = _add(parent, "texture", type="bitmap", name=name)
    _add(tex, "string", name="filename", value=filename)
    _add(tex, "boolean", name="raw", value="true")
    _add(tex, "string", name="wrap_mode", value=wrap)


def _exported_parts(mi, mesh: Mesh, maps: PBRMaps, out_dir: Path) -> list[dict]:
    """Each material part as the live renderer draws it (core.render.drawn_part: its own UVs, its own
    texels, its wrap mode), written as a PLY and its images; one material keeps the plain names
    (mesh.ply, base_color.png, ...), several are numbered (mesh_0.ply, base_color_0.png, ...)."""
    import torch  # lazy: torch takes seconds to load

    stack = torch.from_numpy(np.ascontiguousarray(maps.stacked(), np.float32))
    drawn = [drawn_part(part) for part in material_parts(mesh, maps.resolution)]
    out = []
    for index, part in enumerate(drawn):
        tag = "" if len(drawn) == 1 else f"_{index}"
        texels = part.texels(stack).numpy()
        # The PLY holds Mitsuba's own texture convention (v = 0 at the top row), so it is read unflipped.
        tmp_ply = out_dir / f".mesh{tag}.ply{TEMP_MARK}"
        _mitsuba_mesh(mi, part.mesh).write_ply(str(tmp_ply))
        tmp_ply.replace(out_dir / f"mesh{tag}.ply")
        write_image(out_dir / f"base_color{tag}.png", linear_to_srgb(texels[..., 0:3]))
        files: dict[str, str | float] = {"mesh": f"mesh{tag}.ply", "base_color": f"base_color{tag}.png",
                                         "wrap": part.mode}
        for channel, name in ((3, "roughness"), (4, "metallic")):
            if isinstance(getattr(maps, name), np.ndarray):
                write_image(out_dir / f"{name}{tag}.png", texels[..., channel], dtype="uint16")
                files[name] = f"{name}{tag}.png"
            else:
                files[name] = float(getattr(maps, name))
        out.append(files)
    return out


@dataclass(frozen=True)
class LookAt:
    """A camera given in the mesh's own frame (e.g. the photo's camera in Blender's world space)."""

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov_deg: float = 60.0   # horizontal
    width: int = 512
    height: int = 512


def export_mitsuba_scene(mesh: Mesh, maps: PBRMaps, out_dir: str | Path, camera: Camera | LookAt | None = None,
                         envmap: np.ndarray | None = None, spp: int = 256, max_depth: int = 8) -> Path:
    """Write the scene; returns the path of scene.xml. Nothing outside `out_dir` is touched.

    The mesh keeps its own size and place; `camera` is given in SceneFit's normalised frame (asset in
    the radius-0.5 sphere at the origin) and is carried into the asset's frame, so it frames the
    asset as SceneFit's renders do. A `LookAt` is used as given (the mesh's frame, horizontal FOV).

    envmap: linear (H, 2H, 3) radiance in Blender's equirectangular convention; None writes a
    constant white environment.
    """
    if spp < 1 or max_depth < 1:
        raise InputError(f"Samples per pixel and path depth must be at least 1, got {spp} and {max_depth}.")
    if envmap is not None:
        check_environment(np.asarray(envmap), "The environment map to export")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    init_mitsuba()
    import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

    camera = camera or Camera(width=512, height=512)
    if isinstance(camera, LookAt):
        origin, target, up = (np.asarray(v, np.float64) for v in (camera.origin, camera.target, camera.up))
        fov_axis = "x"
    else:
        _, transform = normalize_to_unit_sphere(mesh)
        origin = transform.to_object(camera.origin)
        target = transform.to_object(np.asarray(camera.target, dtype=np.float64))
        up, fov_axis = np.array([0.0, 0.0, 1.0]), "smaller"
    parts = _exported_parts(mi, mesh, maps, out_dir)
    scene = ET.Element("scene", version="3.0.0")
    integrator = _add(scene, "integrator", type="path")
    _add(integrator, "integer", name="max_depth", value=max_depth)

    sensor = _add(scene, "sensor", type="perspective")
    _add(sensor, "string", name="fov_axis", value=fov_axis)
    _add(sensor, "float", name="fov", value=f"{camera.fov_deg:.9g}")
    _add(_add(sensor, "transform", name="to_world"), "lookat", origin=",".join(f"{x:.9g}" for x in origin),
         target=",".join(f"{x:.9g}" for x in target), up=",".join(f"{x:.9g}" for x in up))
    _add(_add(sensor, "sampler", type="independent"), "integer", name="sample_count", value=spp)
    film = _add(sensor, "film", type="hdrfilm")
    _add(film, "integer", name="width", value=camera.width)
    _add(film, "integer", name="height", value=camera.height)
    _add(film, "rfilter", type="box")

    emitter = _add(scene, "emitter", type="envmap")
    env = np.ones((16, 32, 3), np.float32) if envmap is None else np.asarray(envmap, np.float32)
    write_image(out_dir / "envmap.exr", env)
    _add(emitter, "string", name="filename", value="envmap.exr")
    _matrix(emitter, "to_world", ENVMAP_TO_WORLD)

    for files in parts:
        shape = _add(scene, "shape", type="ply")
        _add(shape, "string", name="filename", value=files["mesh"])
        _add(shape, "boolean", name="flip_tex_coords", value="false")
        bsdf = _add(shape, "bsdf", type="principled")
        base = _add(bsdf, "texture", type="bitmap", name="base_color")
        _add(base, "string", name="filename", value=files["base_color"])  # sRGB, decoded by Mitsuba
        _add(base, "string", name="wrap_mode", value=files["wrap"])
        for name in ("roughness", "metallic"):
            _texture_or_value(bsdf, name, files[name], files[name] if isinstance(files[name], str) else None,
                              files["wrap"])
    ET.indent(scene)
    xml_path = out_dir / "scene.xml"
    write_text_atomic(xml_path, ET.tostring(scene, encoding="unicode") + "\n")
    return xml_path
