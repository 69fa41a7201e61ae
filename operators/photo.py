"""How an operator's job sees the photo (main thread): the photo chosen, its size, the artist's camera that
shows it, the camera and sun a job uses."""
from __future__ import annotations

import math
from pathlib import Path

import bpy

from ..core.base.errors import InputError


def photo_path(context) -> Path:
    """The photo chosen in the panel, resolved ('//' is the .blend's folder); one sentence if missing."""
    text = context.scene.scenefit.photo_path
    if not text:
        raise InputError("No photo is chosen; pick one in the SceneFit panel's Scene section.")
    path = Path(bpy.path.abspath(text))
    if not path.is_file():
        raise InputError(f"The photo '{path}' does not exist; choose another in the Scene section.")
    return path


# -- the photo's camera ------------------------------------------------------------------------------
_photo_sizes: dict[str, tuple[int, int] | None] = {}   # resolved photo path -> its upright size


def remember_photo_size(text: str) -> tuple[int, int] | None:
    """Read (once per path) and keep the upright size of the photo `text` names: what the panel draws from."""
    from ..core.data.imageio import upright_size

    if not text:
        return None
    path = str(Path(bpy.path.abspath(text)))
    try:
        _photo_sizes[path] = upright_size(Path(path)) if Path(path).is_file() else None
    except (OSError, ValueError):
        _photo_sizes[path] = None
    return _photo_sizes[path]


def artist_camera(context, photo: Path, read: bool = True):
    """(camera object, why) when the scene's active camera is the artist's and shows the photo (matched
    with the fSpy importer or by eye): SceneFit then composes through it. (None, "") otherwise.
    read=False (drawing): only a size already read is used, the file is never opened."""
    from ..blender_io.scene_camera import matched_scene_camera

    key = str(photo)
    size = remember_photo_size(key) if read else _photo_sizes.get(key)
    return matched_scene_camera(context.scene, photo, size) if size else (None, "")


def photo_view(context, photo: Path, obj=None) -> dict:
    """How a job sees the photo, decided once for every operator:

    camera: {"fov_deg", "pitch_deg", "roll_deg", and the artist's camera's "shift_x", "shift_y"} to use, or None to estimate it from the photo in the job;
    sun_deg: the dominant light's (azimuth, elevation) the artist set (Pick Sun), or None, and
    sun_uncertainty_deg how far off it may be;
    camera_source: "blender" (the artist's camera shows the photo), "user" (the panel's values), or
    "estimate"; scene_camera: that camera's name; placement, size, turn_deg: where the asset stands (from
    the arrangement through the artist's camera, else the panel's); notes: what is not modelled."""
    settings = context.scene.scenefit
    view = {"camera": None, "camera_source": "estimate", "scene_camera": "", "placement": tuple(settings.placement),
            "size": float(settings.size), "turn_deg": math.degrees(settings.turn), "notes": []}
    camera, why = artist_camera(context, photo)
    if camera is not None:
        from ..blender_io.scene_camera import horizontal_fov_deg, lens_shift, scene_view
        from ..core.data.imageio import upright_size

        size = upright_size(photo)
        if obj is not None:
            seen, notes = scene_view(camera, obj, size, context.evaluated_depsgraph_get())
            fov, pitch, roll = seen.fov_deg, seen.pitch_deg, seen.roll_deg
            view.update(placement=seen.placement, size=min(1.0, seen.size), turn_deg=seen.turn_deg, notes=notes)
        else:
            import numpy as np

            from ..core.scene.camera import camera_pose

            _, pitch, roll = camera_pose(np.array(camera.matrix_world), f"The scene camera '{camera.name}'")
            fov = horizontal_fov_deg(camera, *size)
        view.update(camera={"fov_deg": fov, "pitch_deg": pitch, "roll_deg": roll, **lens_shift(camera, *size)},
                    camera_source="blender",
                    scene_camera=camera.name)
        view["notes"].insert(0, f"the scene camera '{camera.name}' is used as it is: {why}")
    elif settings.camera_from == "panel":
        view.update(camera={"fov_deg": math.degrees(settings.fov), "pitch_deg": math.degrees(settings.pitch),
                            "roll_deg": math.degrees(settings.roll)}, camera_source="user")
    view["sun_deg"] = ((math.degrees(settings.sun_azimuth), math.degrees(settings.sun_elevation))
                       if settings.sun_from == "set" else None)
    view["sun_uncertainty_deg"] = math.degrees(settings.sun_uncertainty) if settings.sun_from == "set" else 0.0
    return view


def composite_camera(context, photo: Path, view: dict):
    """The PhotoCamera the Cycles set-up uses when no job hands one back: the view's, else the camera stage's of
    the run that made the World's light map (lens shift included), else the photo's estimate."""
    from ..core.pipeline.layout import camera_of, run_folder_of
    from ..core.scene.camera import PhotoCamera

    if view["camera"] is not None:
        return PhotoCamera(**view["camera"])
    light = context.scene.scenefit.light_path
    run_folder = run_folder_of(bpy.path.abspath(light)) if light else None
    if run_folder is not None:
        return camera_of(run_folder, 1, 1)[0]
    from ..core.stages.camera import photo_camera_estimate

    return photo_camera_estimate(photo).photo_camera()
