"""The composite set up in Blender: a camera matched to the photo, the photo behind the render, a
shadow-catcher floor under the asset, all in SceneFit's own scene ("SceneFit Composite"), which links
the asset's objects: F12 there renders the composite in Cycles.

The artist's scene is theirs: its render engine, resolution, film, colour management, scene camera
and compositor are never changed (the composite scene has its own). Only new objects and data are
made (tagged ["scenefit"]); the asset is not moved: the camera is placed around it
(core/scene/asset_pose.py `camera_for_placement`) looking along +Y, the direction the light stage
takes for the photo, so the estimated World lights the asset from the right side. Deleting the
composite scene deletes all of it.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.base.errors import InputError
from ..core.data.imageio import CHECK_SIDE, read_image, stored_orientation
from ..core.scene.asset_pose import camera_for_placement
from ..core.scene.camera import PHOTO_YAW_DEG, PhotoCamera, camera_pose
from .tag import TAG
from .world import world_controls

CAMERA_NAME = "SceneFit Camera"
FLOOR_NAME = "SceneFit Shadow Catcher"
COMPOSITOR_NAME = "SceneFit Composite"
SCENE_NAME = "SceneFit Composite"
COMPOSITE_SAMPLES = 128   # a new composite scene's Cycles samples (the artist's scene's are for their engine)


# (path, mtime, size) of the photos decoded whole this session: by load_photo_image's check, or by a job.
_checked_photos: set[tuple] = set()


def _photo_key(path: Path) -> tuple | None:
    try:
        stat = path.stat()
    except OSError:
        return None
    return str(path.resolve()), stat.st_mtime_ns, stat.st_size


def photo_read_whole(path: str | Path) -> None:
    """Say that the photo at `path` decoded whole (a job's pipeline read it, or the check did): its Blender
    image is loaded without decoding it again on the main thread."""
    key = _photo_key(Path(path))
    if key is not None:
        _checked_photos.add(key)


def load_photo_image(path: str | Path):
    """The photo as a Blender image (reused when already loaded); one sentence when unreadable.

    Blender shows images as stored and ignores EXIF Orientation, while SceneFit reads photos upright
    (core/imageio.read_image): a phone's sideways-stored photo gets an upright, packed copy, so the
    camera background, the clicked placement and the pipeline all see the same picture."""
    import bpy

    path = Path(path)
    # Decoded once by OpenImageIO first (band by band, reduced): Blender shows a truncated JPEG with
    # its missing rows grey and says nothing, and a refusal here leaves no datablock in the file. Once per
    # file: a 24 MP photo takes seconds, and a job that read it whole already checked it (photo_read_whole).
    if _photo_key(path) not in _checked_photos:
        read_image(path, max_side=CHECK_SIDE)
        photo_read_whole(path)
    orientation = stored_orientation(path)
    if orientation not in (0, 1):
        return _upright_copy(path, orientation)
    known = {image.as_pointer() for image in bpy.data.images}
    try:
        image = bpy.data.images.load(str(path), check_existing=True)
    except RuntimeError as error:   # unreadable for Blender (permissions, a vanished file)
        raise InputError(f"Blender cannot read the photo '{path}' ({error}); save it as PNG or JPEG.") from None
    if image.size[0] == 0 or image.size[1] == 0:
        if image.as_pointer() not in known:   # ours, just made: the refusal leaves the file as it was
            bpy.data.images.remove(image)
        raise InputError(f"Blender cannot read the photo '{path}'; save it as PNG or JPEG.")
    return image


def _upright_copy(path: Path, orientation: int):
    import bpy

    key = f"{path.resolve()}#orientation{orientation}"
    for image in bpy.data.images:
        if image.get(TAG) == key:
            return image
    pixels = read_image(path, upright=True)[..., :3]
    h, w = pixels.shape[:2]
    image = bpy.data.images.new(f"{path.stem} (upright)", w, h, alpha=False)
    image.colorspace_settings.name = "sRGB"
    rgba = np.concatenate([pixels, np.ones((h, w, 1), np.float32)], axis=2)
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())   # Blender's rows run bottom-up
    image.pack()
    image[TAG] = key
    return image


def _tagged(collection, name: str):
    item = collection.get(name)
    return item if item is not None and TAG in item else None


def camera_rotation(forward, up):
    """The 3x3 rotation (mathutils.Matrix) of a Blender camera looking along `forward` with `up` up:
    Blender cameras look along local -Z with local +Y up."""
    import mathutils

    z_axis, y_axis = -np.asarray(forward, np.float64), np.asarray(up, np.float64)
    return mathutils.Matrix(np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis]).tolist())


def new_plane(name: str, half: float):
    """A NEW square plane object on z = 0, `half` wide each way (not linked to a scene)."""
    import bpy

    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)], [],
                     [(0, 1, 2, 3)])
    return bpy.data.objects.new(name, mesh)


def transparent_cycles(scene) -> None:
    """Cycles with a transparent film and the Standard view, so radiance comes out as it was rendered."""
    scene.render.engine = "CYCLES"
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"


def composite_scene():
    """SceneFit's own scene for the Cycles composite (made once per file, tagged): Cycles, a transparent
    film and the Standard view, so the photo's pixels come out as they went in. The artist's scenes are
    never switched to it; F12 with it active renders the composite."""
    import bpy

    scene = _tagged(bpy.data.scenes, SCENE_NAME)
    if scene is None:
        scene = bpy.data.scenes.new(SCENE_NAME)
        scene[TAG] = "composite"
        scene.cycles.samples = COMPOSITE_SAMPLES
    transparent_cycles(scene)
    return scene


def settle(scene) -> None:
    """The scene's objects' world matrices brought up to date: the composite scene is not the window's, so
    Blender does not evaluate it by itself (SceneFit's camera there would keep an old matrix_world)."""
    for layer in scene.view_layers:
        layer.update()


def is_composite_scene(scene) -> bool:
    return scene is not None and scene.get(TAG) == "composite"


def link_into(scene, objects) -> None:
    """The objects linked (not copied) into `scene`'s own collection: one object, several scenes."""
    for obj in objects:
        if scene not in obj.users_scene:
            scene.collection.objects.link(obj)


def unlink_others(scene, kept) -> None:
    """Composing one asset never shows another: the composite scene's objects that are neither SceneFit's
    own (its camera, floor) nor `kept` are unlinked from it (they stay in the artist's scenes)."""
    keep = {o.as_pointer() for o in kept}
    for obj in list(scene.collection.objects):
        if TAG not in obj and obj.as_pointer() not in keep:
            scene.collection.objects.unlink(obj)


def ensure_photo_camera(scene, image, camera: PhotoCamera):
    """SceneFit's camera (made once per file) in the composite scene (`composite_scene`): core's `camera`
    (its horizontal field of view, pitch, roll and lens shift) at the photo's aspect, the photo as its
    background; the composite scene's camera and resolution. `scene` is the artist's: neither its camera
    nor its resolution changes."""
    import bpy

    own = composite_scene()
    cam = _tagged(bpy.data.objects, CAMERA_NAME)
    if cam is None:
        data = bpy.data.cameras.new(CAMERA_NAME)
        cam = bpy.data.objects.new(CAMERA_NAME, data)
        cam[TAG] = "camera"
        data[TAG] = "camera"
    link_into(own, [cam])
    data = cam.data
    data.sensor_fit = "HORIZONTAL"
    data.angle = math.radians(camera.fov_deg)
    w, h = image.size
    # Blender measures the shift in the side its sensor fits (the width here), PhotoCamera in the longer side.
    data.shift_x = camera.shift_x * max(w, h) / w
    data.shift_y = camera.shift_y * max(w, h) / w
    cam.rotation_mode = "XYZ"
    # The light stage's photo camera: looking along +Y (yaw 90) at the photo's pitch and roll.
    forward, _, up, _, _ = PhotoCamera(pitch_deg=camera.pitch_deg, roll_deg=camera.roll_deg).basis()
    cam.rotation_euler = camera_rotation(forward, up).to_euler("XYZ")
    set_photo_resolution(own, image)
    show_photo(data, image)
    own.camera = cam
    settle(own)
    return cam


def set_photo_resolution(scene, image) -> None:
    w, h = image.size
    scene.render.resolution_x, scene.render.resolution_y = int(w), int(h)
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0


def show_photo(data, image) -> None:
    """The photo as the camera's (data's) shown background, behind the scene."""
    data.show_background_images = True
    backgrounds = [bg for bg in data.background_images if bg.image == image]
    for bg in data.background_images:
        bg.show_background_image = bg.image == image
    if not backgrounds:
        bg = data.background_images.new()
        bg.image, bg.alpha, bg.display_depth, bg.frame_method = image, 1.0, "BACK", "FIT"


def world_box(objects: list) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) corner of the objects' bounding boxes in world space."""
    corners = np.array([o.matrix_world @ _vector(c) for o in objects for c in o.bound_box], dtype=np.float64)
    return corners.min(axis=0), corners.max(axis=0)


def object_base(obj) -> tuple[np.ndarray, float]:
    """The object's (or a list of objects': one asset's) bottom centre in world space and its height
    (evaluated bounding boxes)."""
    lo, hi = world_box(obj if isinstance(obj, (list, tuple)) else [obj])
    return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]), float(hi[2] - lo[2])


def _vector(values):
    from mathutils import Vector

    return Vector(values)


def ensure_shadow_catcher(scene, base: np.ndarray, extent: float):
    """A large plane under the asset that only catches shadows (Cycles), made once per file, in `scene`
    (the composite scene)."""
    import bpy

    floor = _tagged(bpy.data.objects, FLOOR_NAME)
    if floor is None:
        floor = new_plane(FLOOR_NAME, 1.0)
        floor.data[TAG] = "floor"
        floor[TAG] = "floor"
    link_into(scene, [floor])
    floor.location = (float(base[0]), float(base[1]), float(base[2]))
    floor.scale = (extent, extent, 1.0)
    floor.is_shadow_catcher = True
    return floor


def photo_behind_render(scene, image) -> None:
    """Film transparent, and the compositor puts the render over the photo (Standard view: the photo's
    pixels come out as they went in). Only ever on the composite scene: its compositor is SceneFit's
    own to rebuild, on Blender 5 (a node group per scene) as on 4.x (the scene's own tree)."""
    if not is_composite_scene(scene):   # an artist's compositor is never cleared
        raise ValueError(f"photo_behind_render sets up SceneFit's composite scene only, not '{scene.name}'.")
    transparent_cycles(scene)
    scene.view_settings.look = "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    tree, output, image_socket = _own_compositor(scene)
    layers = tree.nodes.new("CompositorNodeRLayers")
    layers.scene = scene
    photo = tree.nodes.new("CompositorNodeImage")
    photo.image = image
    over = tree.nodes.new("CompositorNodeAlphaOver")
    photo.location, layers.location, over.location, output.location = (-400, 200), (-400, -100), (-100, 0), (200, 0)
    background_input, foreground_input = [s for s in over.inputs if s.type == "RGBA"][:2]
    tree.links.new(photo.outputs["Image"], background_input)
    tree.links.new(layers.outputs["Image"], foreground_input)
    tree.links.new(over.outputs[0], image_socket)


def _own_compositor(scene) -> tuple:
    """(tree, its output node, the output's image socket) of the composite scene's compositor, emptied."""
    import bpy

    if hasattr(scene, "compositing_node_group"):  # Blender 5: a compositor node group per scene
        tree = _tagged(bpy.data.node_groups, COMPOSITOR_NAME)
        if tree is None:
            tree = bpy.data.node_groups.new(COMPOSITOR_NAME, "CompositorNodeTree")
            tree[TAG] = "compositor"
            tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        tree.nodes.clear()
        output = tree.nodes.new("NodeGroupOutput")
        scene.compositing_node_group = tree
        return tree, output, output.inputs[0]
    scene.use_nodes = True   # Blender 4.x: the scene's own tree (this scene is SceneFit's)
    tree = scene.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("CompositorNodeComposite")
    return tree, output, output.inputs["Image"]


def setup_composite(context, obj, photo_path: str | Path, placement: tuple[float, float], size: float,
                    camera: PhotoCamera, scene_camera=None, world=None) -> dict:
    """Camera, photo background, shadow catcher and compositing for `obj` (an object, or a list of the
    objects of one asset) in the photo; returns them.

    scene_camera: the artist's camera that shows the photo (blender_io/scene_camera.py), used as it is;
    else SceneFit's camera, with `camera`'s field of view, pitch and roll, is placed around the asset
    for `placement` and `size`. The World SceneFit made is turned to the camera's heading, since the
    light map's azimuth 0 is the photo camera's view.

    Everything goes into the composite scene (`composite_scene`), which links the asset's objects, the
    camera and the floor, and is lit by `world` (else the artist's scene's World); the artist's scene
    keeps its engine, resolution, film, colour management, camera and compositor. The artist's camera
    is linked there as it is (not changed)."""
    artist = context.scene
    objects = list(obj) if isinstance(obj, (list, tuple)) else [obj]
    image = load_photo_image(photo_path)
    w, h = image.size
    base, height = object_base(objects)
    own = composite_scene()
    if scene_camera is None:
        at_photo = replace(camera, width=w, height=h)
        position = camera_for_placement(base, height, placement, size, at_photo)
        cam = ensure_photo_camera(artist, image, at_photo)
        cam.location = tuple(float(v) for v in position)
        yaw = PHOTO_YAW_DEG
    else:
        cam = scene_camera
        link_into(own, [cam])
        own.camera = cam
        set_photo_resolution(own, image)
        position = np.array(cam.matrix_world.translation, np.float64)
        yaw = camera_pose(np.array(cam.matrix_world, np.float64))[0]
    link_into(own, objects)
    unlink_others(own, objects + [cam])
    own.world = world if world is not None else artist.world
    turn_world_to(own.world, yaw)
    reach = float(np.linalg.norm(position - base))
    floor = ensure_shadow_catcher(own, base, extent=4.0 * reach)
    photo_behind_render(own, image)
    settle(own)
    return {"camera": cam, "floor": floor, "photo": image, "scene": own}


def turn_world_to(world, yaw_deg: float) -> None:
    """Turn a World SceneFit made (blender_io/world.py) so its map's azimuth 0 lies along a camera heading
    yaw_deg (90: +Y, SceneFit's own camera, no turn); the artist's own Worlds are left alone."""
    mapping, _ = world_controls(world)
    if mapping is None or TAG not in world:
        return
    mapping.inputs["Rotation"].default_value[2] = math.radians(PHOTO_YAW_DEG - yaw_deg)
