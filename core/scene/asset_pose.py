"""Where the asset stands in the photo's world, how big it is and which way it faces.

Core's model (`place_asset`): the camera is fixed (core/scene/camera.py) and the normalised asset is
stood on the floor under the placement pixel, faced to the camera and scaled to span `size` of the
photo's height. Blender's model (`camera_for_placement`, `asset_in_view`): the artist's asset is not
moved, and the camera is placed around it, or read from the artist's camera. The two are one
similarity seen from either side, so a composite made either way shows the asset where and as large
as the other does.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..data.mesh import Mesh, vertex_normals
from .camera import CAMERA_HEIGHT, PhotoCamera, camera_origin, camera_pose, pixel_ray
from .floor import place_on_floor
from .frame import rotation_z


ASSUMED_CAMERA_HEIGHT_M = 1.5   # to state placements in metres: a hand-held camera at chest height


@dataclass(frozen=True)
class ObjectPlacement:
    """Where the asset stands and how big it is; world units are camera heights (CAMERA_HEIGHT = 1)."""

    pixel: tuple[float, float]
    base: tuple[float, float, float]    # the point under the asset's centre (on the floor when on_floor)
    on_floor: bool
    why: str
    scale: float                        # normalised mesh (radius 0.5) -> world
    facing_deg: float                   # rotation about Z that turns the asset's front (-Y) to the camera
    height: float                       # world height of the placed asset
    pixel_box: tuple[int, int, int, int]  # x0, y0, x1, y1 of its projection (clipped to the photo)

    def report(self) -> dict:
        m = ASSUMED_CAMERA_HEIGHT_M / CAMERA_HEIGHT
        return {"pixel": [round(v, 2) for v in self.pixel], "on_floor": self.on_floor, "why": self.why,
                "base_camera_heights": [round(v, 4) for v in self.base],
                "base_m": [round(v * m, 3) for v in self.base],
                "distance_m": round(float(np.linalg.norm(np.subtract(self.base, (0, 0, CAMERA_HEIGHT)))) * m, 3),
                "height_m": round(self.height * m, 3), "scale": round(self.scale, 5),
                "facing_deg": round(self.facing_deg, 2), "pixel_box": list(self.pixel_box),
                "metres_assume": f"camera {ASSUMED_CAMERA_HEIGHT_M} m above the floor"}


def _offset(lo: np.ndarray, hi: np.ndarray, scale: float, anchor, on_floor: bool) -> np.ndarray:
    """Translation putting the scaled, rotated asset (bounds lo, hi) at `anchor`: its bottom on the floor
    under the anchor when it stands, its middle on the anchor when it floats."""
    centre = (lo + hi) / 2
    z0 = -lo[2] * scale if on_floor else anchor[2] - centre[2] * scale
    return np.array([anchor[0] - centre[0] * scale, anchor[1] - centre[1] * scale, z0])


# An asset this many times wider than tall (a ground plane around a small thing) reaches behind the
# camera at any useful size, since --object-size sets its height: the message then says what helps.
FLAT_RATIO = 20.0


def _behind_the_camera(size: float, extent: np.ndarray) -> str:
    ratio = float(max(extent[0], extent[1]) / max(extent[2], 1e-9))
    # Said to the command line and to Blender alike: each names its own setting.
    if ratio >= FLAT_RATIO:
        return (f"The asset is {ratio:.0f} times as wide as it is tall (a ground plane?): at size {size:g} (--object-size, "
                "Blender's Size) it would reach behind the camera, and only a tiny one fits; place the object alone "
                "(--object NAME, or select only it in Blender).")
    return (f"At size {size:g} (--object-size, Blender's Size) the asset would reach behind the camera; pick a smaller "
            "size or a point further away.")


def place_asset(normalized: Mesh, camera: PhotoCamera, pixel: tuple[float, float], size: float,
                turn_deg: float = 0.0) -> ObjectPlacement:
    """Stand the normalised asset on the floor under `pixel` (or float it on the pixel's ray when the
    pixel is above the horizon), facing the camera (then turned by `turn_deg` about Z), scaled so its
    projection spans `size` x photo height."""
    floor = place_on_floor(camera, pixel)
    origin = camera_origin()
    on_floor = not floor.clamped
    if on_floor:
        anchor = floor.object_position
        why = "the picked point is on the floor: the asset stands there"
    else:  # as far as the nearest floor point in that direction, on the picked pixel's own ray
        anchor = origin + pixel_ray(camera, *pixel) * float(np.linalg.norm(floor.object_position - origin))
        why = "the picked point is above the horizon: the asset floats on its ray and casts no floor shadow"
    to_camera = origin[:2] - anchor[:2]
    # front (-Y) -> towards the camera, then the requested turn
    facing = math.degrees(math.atan2(to_camera[1], to_camera[0])) + 90.0 + turn_deg
    rotated = normalized.positions.astype(np.float64) @ rotation_z(facing).T
    lo, hi = rotated.min(axis=0), rotated.max(axis=0)

    def placed(scale: float) -> np.ndarray:
        return rotated * scale + _offset(lo, hi, scale, anchor, on_floor)

    target = size * camera.height
    distance = float(np.linalg.norm(anchor - origin))
    _, _, _, _, half_h = camera.basis()
    scale = size * 2 * half_h * distance / max(hi[2] - lo[2], 1e-6)
    forward = camera.basis()[0]
    for _ in range(8):  # the projected height is nearly linear in the scale; a few fixed-point steps
        world = placed(scale)
        if ((world - origin) @ forward).min() <= 1e-3:
            raise InputError(_behind_the_camera(size, hi - lo))
        ys = camera.project(world, origin)[:, 1]
        extent = float(ys.max() - ys.min())
        scale *= target / max(extent, 1e-6)
    world = placed(scale)
    xy = camera.project(world, origin)
    x0, y0 = np.floor(xy.min(axis=0)).astype(int)
    x1, y1 = np.ceil(xy.max(axis=0)).astype(int)
    box = (int(np.clip(x0 - 2, 0, camera.width)), int(np.clip(y0 - 2, 0, camera.height)),
           int(np.clip(x1 + 2, 0, camera.width)), int(np.clip(y1 + 2, 0, camera.height)))
    if box[2] <= box[0] or box[3] <= box[1]:
        raise InputError("The placed asset falls outside the photo; pick a point inside it.")
    base = (anchor[0], anchor[1], 0.0 if on_floor else anchor[2])
    return ObjectPlacement(tuple(float(v) for v in pixel), tuple(float(v) for v in base), on_floor, why,  # type: ignore[arg-type]
                           float(scale), float(facing), float((hi[2] - lo[2]) * scale), box)


def placement_transform(normalized: Mesh, placement: ObjectPlacement) -> tuple[np.ndarray, float, np.ndarray]:
    """(rotation R, scale s, offset t) with world = R @ p * s + t for the normalised mesh's points p."""
    rotation = rotation_z(placement.facing_deg)
    rotated = normalized.positions.astype(np.float64) @ rotation.T
    offset = _offset(rotated.min(axis=0), rotated.max(axis=0), placement.scale, placement.base, placement.on_floor)
    return rotation, placement.scale, offset


def placed_mesh(normalized: Mesh, placement: ObjectPlacement) -> Mesh:
    """The normalised mesh moved into the photo's world (the caller's mesh is not touched)."""
    rotation, scale, offset = placement_transform(normalized, placement)
    normals = normalized.normals if normalized.normals is not None else vertex_normals(normalized.positions,
                                                                                       normalized.faces)
    return Mesh.from_arrays(normalized.positions.astype(np.float64) @ rotation.T * scale + offset, normalized.faces,
                            normalized.uvs, np.asarray(normals, np.float64) @ rotation.T, normalized.name,
                            normalized.material_index, normalized.wraps, normalized.atlas)


def photo_camera_in_object_frame(camera: PhotoCamera, normalized: Mesh, placement: ObjectPlacement
                                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The photo camera's (origin, forward, up) in the normalised asset's own frame: rendering the
    unmoved asset from there shows exactly what the photo camera sees of the placed one (a similarity
    keeps angles, so the field of view is the same)."""
    rotation, scale, offset = placement_transform(normalized, placement)
    forward, _, up, _, _ = camera.basis()
    origin = rotation.T @ (camera_origin() - offset) / scale
    return origin, rotation.T @ forward, rotation.T @ up


def envmap_in_object_frame(envmap, placement: ObjectPlacement):
    """The world's light map as the unmoved asset sees it: the asset is turned by facing_deg about Z, so
    the map turns the other way (a shift of its columns, to the nearest column)."""
    shift = int(round(placement.facing_deg / 360.0 * envmap.shape[1]))
    return np.roll(envmap, shift, axis=1) if isinstance(envmap, np.ndarray) else envmap.roll(shift, 1)


def camera_for_placement(base: np.ndarray, height: float, placement: tuple[float, float], size: float,
                         camera: PhotoCamera) -> np.ndarray:
    """Where SceneFit's photo camera stands so the asset's base point lands on `placement`, `size` tall.

    `camera` is core's photo camera (looking along +Y, the light map's azimuth 0; its field of view, pitch,
    roll, lens shift and aspect are used). base: the asset's bottom centre in world space; height: its height.
    The asset is not moved: the camera is placed around it.
    """
    if not 0.0 < size <= 1.0 or height <= 0.0:
        raise InputError("The asset's size in the photo must be in (0, 1] and the asset must have a height.")
    forward, right, up, _, tan_h = camera.basis()
    # Depth along the view at which `height` fills `size` of the frame's height.
    depth = height / (size * 2.0 * tan_h)
    plane_x, plane_y = camera.plane_xy(placement[0] * camera.width, placement[1] * camera.height)
    ray = forward + plane_x * right + plane_y * up
    position = np.asarray(base, np.float64) - depth * ray
    if position[2] <= base[2]:
        raise InputError(f"The placement ({placement[0]:.2f}, {placement[1]:.2f}) is above the horizon of a camera "
                         f"at pitch {camera.pitch_deg:.0f}°; pick a point on the ground or lower the Pitch.")
    return position


@dataclass(frozen=True)
class SceneView:
    """The artist's arrangement seen through their camera, in the terms the pipeline takes: the
    camera's field of view, pitch and roll, and the asset's placement, size and turn (see asset_in_view)."""

    fov_deg: float
    pitch_deg: float
    roll_deg: float
    yaw_deg: float                      # the camera's heading; the light map is turned by yaw - 90 to match
    placement: tuple[float, float]      # where the asset's base point is in the photo (fractions, y from the top)
    size: float                         # the asset's height in the photo as a fraction of its height
    turn_deg: float                     # the asset's turn about Z past facing the camera (place_asset)


def asset_in_view(camera_to_world: np.ndarray, fov_deg: float, width: int, height: int, points: np.ndarray,
                  object_yaw_deg: float, shown: str = "the camera") -> SceneView:
    """What the pipeline needs to compose the asset as the artist's camera sees it.

    points: the asset's vertices in world space; object_yaw_deg: the object's turn about Z (its mesh is
    handed to the pipeline in object space). place_asset stands the asset's bottom centre,
    taken in axes turned with the camera, on the floor under the placement pixel, faces it to the camera
    and scales it to `size`: a similarity of this arrangement, so the composite shows the asset where and
    as large as the camera does."""
    matrix = np.asarray(camera_to_world, np.float64)
    yaw, pitch, roll = camera_pose(matrix, shown)
    origin = matrix[:3, 3]
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=fov_deg, width=width, height=height, roll_deg=roll)
    points = np.asarray(points, np.float64)
    # The bottom centre of the bounding box in axes where the camera looks along +Y, as core takes it.
    turn = rotation_z(90.0 - yaw)
    turned = points @ turn.T
    lo, hi = turned.min(axis=0), turned.max(axis=0)
    base = turn.T @ np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    forward = camera.basis()[0]
    if ((points - origin) @ forward).min() <= 0.0:
        raise InputError("Part of the asset is behind the scene camera; move the camera or the asset so the camera "
                         "sees all of it.")
    x, y = camera.project(base[None], origin)[0]
    ys = camera.project(points, origin)[:, 1]
    to_camera = origin[:2] - base[:2]
    facing = math.degrees(math.atan2(to_camera[1], to_camera[0]))
    return SceneView(fov_deg=float(fov_deg), pitch_deg=pitch, roll_deg=roll, yaw_deg=yaw,
                     placement=(float(x / width), float(y / height)),
                     size=float((ys.max() - ys.min()) / height),
                     turn_deg=float((object_yaw_deg - facing - 90.0 + 180.0) % 360.0 - 180.0))
