"""The artist's own camera. When the scene's active camera shows the photo as its background (as the
fSpy importer and matching by eye leave it), SceneFit composes through that camera as it is: its field
of view, pitch, roll and position, with the asset where the artist put it (core/scene/asset_pose.py's
asset_in_view turns that arrangement into the pipeline's placement, size and turn). Nothing of the
artist's is changed: the camera is read, never moved.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.base.errors import InputError
from ..core.scene.asset_pose import SceneView, asset_in_view
from .tag import TAG   # SceneFit's own objects carry it; its camera is SceneFit's to move



def photo_background(camera, photo_path: str | Path, photo_size: tuple[int, int]) -> str | None:
    """Why `camera` (an object) shows the photo, or None: a shown background image of the photo's file, or,
    for a packed image (the fSpy importer packs the one its project holds), of the photo's pixel size."""
    import bpy

    data = camera.data
    if camera.type != "CAMERA" or not data.show_background_images:
        return None
    photo = Path(photo_path).resolve()
    for background in data.background_images:
        image = background.image
        if not background.show_background_image or image is None:
            continue
        if image.filepath and not image.packed_file:
            try:
                if Path(bpy.path.abspath(image.filepath)).resolve() == photo:
                    return f"its background image '{image.name}' is the photo's file"
            except OSError:
                continue
        elif image.packed_file and tuple(image.size) == tuple(photo_size):
            return f"its background image '{image.name}' is packed and of the photo's size {photo_size[0]}x{photo_size[1]}"
    return None


def matched_scene_camera(scene, photo_path: str | Path, photo_size: tuple[int, int]):
    """(camera object, why) when the scene's active camera is the artist's and shows the photo, else (None, "")."""
    camera = scene.camera
    if camera is None or TAG in camera:
        return None, ""
    why = photo_background(camera, photo_path, photo_size)
    return (camera, why) if why else (None, "")


def horizontal_fov_deg(camera, width: int, height: int) -> float:
    """The horizontal field of view of a perspective camera on a width x height frame, from its lens and
    sensor as Blender fits the sensor (AUTO: along the longer side)."""
    data = camera.data
    if data.type != "PERSP":
        raise InputError(f"The scene camera '{camera.name}' is {data.type.lower()}; SceneFit composes through "
                         "perspective cameras, so set its type to Perspective.")
    fit = data.sensor_fit
    if fit == "AUTO":
        fit, sensor = ("HORIZONTAL" if width >= height else "VERTICAL"), data.sensor_width
    else:
        sensor = data.sensor_width if fit == "HORIZONTAL" else data.sensor_height
    half = sensor / (2.0 * data.lens)
    if fit == "VERTICAL":
        half *= width / height
    return math.degrees(2.0 * math.atan(half))


def shift_unit_pixels(camera, width: int, height: int) -> float:
    """The frame side, in pixels, that Blender measures a camera's lens shift in: the side its sensor fits
    (AUTO: the longer one)."""
    fit = camera.data.sensor_fit
    if fit == "AUTO":
        return float(max(width, height))
    return float(width if fit == "HORIZONTAL" else height)


def principal_point(camera, width: int, height: int) -> tuple[float, float]:
    """Where the camera's optical axis meets a width x height frame, in pixels (x right, y down): the centre
    moved by the lens shift (fSpy's importer sets the shift from the principal point it solved). A shift
    to the right moves the view right, so the axis's pixel moves left."""
    unit = shift_unit_pixels(camera, width, height)
    return width / 2.0 - camera.data.shift_x * unit, height / 2.0 + camera.data.shift_y * unit


def lens_shift(camera, width: int, height: int) -> dict:
    """The camera's lens shift as core's PhotoCamera holds it (fractions of the frame's longer side)."""
    unit = shift_unit_pixels(camera, width, height) / max(width, height)
    return {"shift_x": float(camera.data.shift_x) * unit, "shift_y": float(camera.data.shift_y) * unit}


def scene_view(camera, obj, photo_size: tuple[int, int], depsgraph) -> tuple[SceneView, list[str]]:
    """The arrangement of `obj` seen through the artist's `camera` (core/scene/asset_pose.SceneView) and
    notes on how it is read (a lens shift) and what SceneFit does not model (a tilted or unevenly scaled asset). `obj` may be a
    list of the objects of one asset: read in world space, they stand as they are (no turn of their own)."""
    width, height = photo_size
    notes = []
    objects = list(obj) if isinstance(obj, (list, tuple)) else [obj]
    clouds = []
    for part in objects:
        evaluated = part.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            points = np.empty(len(mesh.vertices) * 3, np.float64)
            mesh.vertices.foreach_get("co", points)
        finally:
            evaluated.to_mesh_clear()
        matrix = np.array(part.matrix_world, np.float64)
        clouds.append(points.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3])
    points = np.concatenate(clouds)
    yaw = 0.0
    if len(objects) == 1:   # one object is read in object space: its own turn and tilt are the asset's
        axes = matrix[:3, :3] / np.linalg.norm(matrix[:3, :3], axis=0)
        if abs(axes[2, 2]) < 0.9999:
            notes.append(f"'{objects[0].name}' is tilted off the vertical; SceneFit stands it upright on the floor")
        yaw = math.degrees(math.atan2(axes[1, 0], axes[0, 0]))
    camera_matrix = np.array(camera.matrix_world, np.float64)
    seen = asset_in_view(camera_matrix, horizontal_fov_deg(camera, width, height), width, height, points, yaw,
                         f"The scene camera '{camera.name}'")
    # A lens shift moves the whole picture by one offset (the optical axis's pixel): the asset stands
    # where the shifted camera shows it, and its size is the same.
    axis_x, axis_y = principal_point(camera, width, height)
    if abs(axis_x - width / 2.0) > 1e-6 or abs(axis_y - height / 2.0) > 1e-6:
        seen = replace(seen, placement=(seen.placement[0] + (axis_x - width / 2.0) / width,
                                        seen.placement[1] + (axis_y - height / 2.0) / height))
        notes.append(f"the camera's lens shift ({camera.data.shift_x:.3f}, {camera.data.shift_y:.3f}) puts its "
                     f"optical axis at pixel ({axis_x:.0f}, {axis_y:.0f}): the asset is placed and rendered as that "
                     "shifted camera shows it")
    return seen, notes
