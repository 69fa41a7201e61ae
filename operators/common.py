"""Helpers shared by the operators (main thread only): inputs, preferences, the run folders."""
from __future__ import annotations

import importlib.util
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import bpy

from ..blender_io.tag import TAG   # what every datablock SceneFit makes carries (operators/results.py)
from ..core.base.errors import InputError
from ..core.data.map_plan import PendingAsset
from ..core.data.materials import AssetMaterials

ADDON_PACKAGE = __package__.rpartition(".")[0]
# On a SceneFit result material: the artist's material it replaced (an ID property, so it survives saving,
# duplicating the object and results made later on other objects).
ORIGINAL_PROPERTY = "scenefit_original"


def artists_material_behind(material, recorded=None):
    """The artist's material behind `material`: itself when it is not a SceneFit result; else the one the
    result replaced (its ORIGINAL_PROPERTY; `recorded`, the Results section's record, for a result made
    before the property was kept); None when neither says."""
    if material is None or TAG not in material:
        return material
    original = material.get(ORIGINAL_PROPERTY)
    return original if isinstance(original, bpy.types.Material) else recorded


# -- dependencies ------------------------------------------------------------------------------------
# Python modules the stages import, by the name the artist would install.
REQUIRED_MODULES = {"torch": "torch", "mitsuba": "mitsuba", "drjit": "drjit", "cv2": "OpenCV",
                    "OpenImageIO": "OpenImageIO", "diffusers": "diffusers", "transformers": "transformers",
                    "peft": "peft"}
_missing: list[str] | None = None


def missing_modules() -> list[str]:
    """The required modules this Blender cannot import (looked up once per session)."""
    global _missing
    if _missing is None:
        _missing = [label for name, label in REQUIRED_MODULES.items() if importlib.util.find_spec(name) is None]
    return _missing


def dependency_sentence() -> str:
    missing = missing_modules()
    if not missing:
        return ""
    return (f"Missing Python modules: {', '.join(missing)}; install the SceneFit build for your platform "
            "(it bundles them).")


def check_dependencies() -> None:
    """One sentence (InputError) instead of an ImportError traceback when the zip lacks its wheels."""
    sentence = dependency_sentence()
    if sentence:
        raise InputError(sentence)


# -- inputs ------------------------------------------------------------------------------------------
@dataclass
class AssetLayout:
    """What an operator works on in Blender, read without touching any pixels.

    objects: the asset's object names (one, or the selected ones as one asset).
    mesh: their mesh, material_index numbering `materials` (object space for one object, as the artist's
    object is wherever it is moved; world space for several, as an asset file's scene is read).
    materials: the material datablocks, one per material of the asset.
    slots: slots[i] = the (object name, slot number) pairs that hold materials[i] (a result replaces them all).
    artists: each material as the artist made it: materials[i], or where its slots hold a SceneFit result,
    the material that result replaced (`artists_materials`). What SceneFit reads and bakes into.
    """

    name: str
    objects: list[str]
    mesh: object
    materials: list
    slots: list[list[tuple[str, int]]]
    artists: list

    def plan(self, context, shown: bool = False, files_in_job: bool = True) -> PendingAsset:
        """Every material's maps as the artist made it, planned here and computed in the job
        (core/data/map_plan.py): its image files decoded there, its procedural chains baked over their own
        faces by the main thread first (`bakes`, one per tick). Run All and Convert again restyle the asset,
        not SceneFit's last result. shown: as the slots show it instead (SceneFit's result where there is one)."""
        from ..blender_io.material import plan_asset

        users = [(bpy.data.objects[pairs[0][0]], pairs[0][1]) for pairs in self.slots]
        return plan_asset(self.mesh, self.materials if shown else self.artists, users, files_in_job)

    def read(self, context, shown: bool = False) -> AssetMaterials:
        """The plan's maps read now, on this thread (Export to Mitsuba, a worker's hand-off)."""
        plan = self.plan(context, shown)
        for bake in plan.bakes:
            bake.run()
        return plan.resolved()

    def fitting_mesh(self):
        """The mesh of `fitting`, read without any pixels (Adapt needs only the mesh: reading the maps
        would bake a procedural material with Cycles for nothing)."""
        from ..blender_io.material import material_wrap
        from ..core.data.materials import fitting_mesh

        return fitting_mesh(self.mesh, [material_wrap(m) for m in self.artists], len(self.materials))

    def fitting(self, context) -> tuple:
        """(mesh, maps, per-material bake data or None) a run fits: several materials as their atlas
        (core/data/materials.py), each then baked in its own UVs for its slots (`bake_data`)."""
        mesh, maps = self.read(context).fitting_view()
        return mesh, maps, self.bake_data() if len(self.materials) > 1 else None

    def bake_data(self) -> dict:
        """What core.game_bake needs to bake each (artist's) material in its own UVs (plain data, for a job)."""
        from ..blender_io.gltf_export import constant_channels
        from ..blender_io.material import material_wrap

        return {"mesh": self.mesh, "names": [m.name for m in self.artists],
                "constants": [constant_channels(m) for m in self.artists],
                "wraps": [material_wrap(m) for m in self.artists]}

    def own_maps(self, context) -> dict:
        """Each artist's material's own maps, which the game bake takes its shape and base from and compares
        its maps with, planned (decoded in the job): a result's images are the texture's working copy, not
        the asset's."""
        return {"own_maps": self.plan(context)}


def artists_materials(context, materials: list, slots: list[list[tuple[str, int]]]) -> list:
    """Each material as the artist made it: where its slots hold a SceneFit result, the material that result
    replaced. The result is a preview of the texture (three maps on a new Principled BSDF): the asset is the
    artist's material, read again by Run All and Convert, and written by Bake Asset with the baked maps in
    place of its own, keeping its normal map, emission, alpha and glTF extensions, as `scenefit bake`
    keeps a file's."""
    originals = recorded_originals(getattr(context.scene, "scenefit", None))   # (None: add-on not registered)
    return [artists_material_behind(material, originals.get(pairs[0])) or material
            for material, pairs in zip(materials, slots)]


def recorded_originals(settings) -> dict:
    """(object name, slot number) -> the material a result replaced there, as the Results section recorded
    it for every slot that got one (a file from before every slot was recorded: its one object's active slot)."""
    if settings is None:
        return {}
    if settings.result_slots:
        return {(e.asset_object.name, e.slot): e.original for e in settings.result_slots
                if e.asset_object is not None and e.original is not None}
    if settings.result_object is None or settings.original_material is None:
        return {}
    return {(settings.result_object.name, settings.result_object.active_material_index): settings.original_material}


def asset_owner(scene):
    """The object whose SceneFitAsset the panel edits: the active object's root (the top of its parents:
    an imported file's root, or the object itself); None without an active object or for SceneFit's own."""
    try:
        layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    except AttributeError:   # a restricted context (registering, loading)
        layer = scene.view_layers[0] if scene.view_layers else None
    obj = layer.objects.active if layer is not None else None
    if obj is None or TAG in obj:
        return None
    while obj.parent is not None:
        obj = obj.parent
    return obj


def asset_state(obj):
    """The SceneFitAsset of `obj`'s root (see asset_owner)."""
    while obj.parent is not None:
        obj = obj.parent
    return obj.scenefit_asset


def asset_digest(layout) -> str:
    """Names the asset's mesh as a texture is fitted to it (its fitting mesh: faces and own UVs, no pixels)."""
    from ..core.texture.surface_layout import mesh_digest

    return mesh_digest(layout.fitting_mesh())


def texture_mesh_digest(text: str) -> str:
    """The mesh digest SceneFit recorded for the texture file `text` (any asset's run that made it), or ""."""
    if not text:
        return ""
    wanted = bpy.path.abspath(text)
    for obj in bpy.data.objects:
        state = getattr(obj, "scenefit_asset", None)
        for run in state.runs if state is not None else ():
            if run.texture_path and run.mesh_digest and bpy.path.abspath(run.texture_path) == wanted:
                return run.mesh_digest
    return ""


def asset_texture(context, layout) -> Path:
    """The active asset's neural texture (its last Convert / Adapt / Run All), refused in one sentence when
    there is none or it was made for another mesh."""
    state = asset_state(bpy.data.objects[layout.name])   # (the active object's, when it is in the asset)
    text = state.texture_path
    path = Path(bpy.path.abspath(text)) if text else None
    if path is None or not path.is_file():
        raise InputError(f"'{layout.name}' has no SceneFit texture yet; run Convert (or Adapt, Run All) on it first.")
    if state.texture_mesh and state.texture_mesh != asset_digest(layout):
        raise InputError(f"The texture '{path.name}' was made for another mesh than '{layout.name}'; convert this "
                         "asset first.")
    return path


def flat_parts(objects: list) -> list[tuple[str, float]]:
    """(name, width / height) of the parts that make a selection too flat to place (a ground plane under a
    tree: the asset is then FLAT_RATIO or more times as wide as tall, and Run All refuses it at most sizes):
    flat parts taken away widest first until the rest is not, only those; [] otherwise. World-space
    bounding boxes (Run All measures the mesh turned to the camera: this is the likely culprit, not a rule)."""
    import numpy as np

    from ..blender_io.compose import world_box
    from ..core.scene.asset_pose import FLAT_RATIO

    def ratio(boxes: list) -> float:
        lo, hi = np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)
        return float(max(hi[0] - lo[0], hi[1] - lo[1]) / max(hi[2] - lo[2], 1e-9))

    boxes = {o.name: world_box([o]) for o in objects}
    if len(boxes) < 2 or ratio(list(boxes.values())) < FLAT_RATIO:
        return []
    width = lambda b: float(max(b[1][0] - b[0][0], b[1][1] - b[0][1]))
    alone = {name: ratio([b]) for name, b in boxes.items()}
    flat = sorted(((name, r) for name, r in alone.items() if r >= FLAT_RATIO), key=lambda item: -width(boxes[item[0]]))
    taken: set[str] = set()
    for count, (name, _) in enumerate(flat, 1):   # a blob shadow or a leaf card under the tree stays
        taken.add(name)
        rest = [b for n, b in boxes.items() if n not in taken]
        if rest and ratio(rest) < FLAT_RATIO:
            return flat[:count]
    return []


def asset_objects(context) -> list:
    """The selected mesh objects when two or more are (one asset), else the active object; SceneFit's own
    objects (its camera, shadow catcher) never count."""
    selected = [o for o in context.selected_objects if o.type == "MESH" and TAG not in o]
    if len(selected) >= 2:
        return sorted(selected, key=lambda o: o.name)
    obj = context.active_object
    if obj is None or obj.type != "MESH":
        raise InputError("No mesh object is active; select the asset (one object, or several to fit them as one).")
    return [obj]


def asset_layout(context) -> AssetLayout:
    """The asset of Run All and Bake Asset: the selected objects in world space, or the active object with
    all its material slots. One sentence (InputError) for what cannot be textured."""
    from ..blender_io.material import object_mesh_and_slots
    from ..blender_io.scene_asset import scene_mesh

    objects = asset_objects(context)
    depsgraph = context.evaluated_depsgraph_get()
    active = context.active_object
    name = active.name if active in objects else objects[0].name
    if len(objects) == 1:
        obj = objects[0]
        mesh, used = object_mesh_and_slots(obj, depsgraph)
        materials, slots = [obj.material_slots[s].material for s in used], [[(obj.name, s)] for s in used]
        return AssetLayout(name, [obj.name], mesh, materials, slots, artists_materials(context, materials, slots))
    try:
        scene = scene_mesh(objects, depsgraph, name, strict=True)
    except InputError as error:
        raise InputError(f"The selection cannot be textured as one asset: {error}") from None
    index = {m.name: i for i, m in enumerate(scene.materials)}
    slots: list[list[tuple[str, int]]] = [[] for _ in scene.materials]
    for obj in objects:   # every slot holding one of the asset's materials gets its result
        for number, slot in enumerate(obj.material_slots):
            if slot.material is not None and slot.material.name in index:
                slots[index[slot.material.name]].append((obj.name, number))
    materials = list(scene.materials)
    return AssetLayout(name, [o.name for o in objects], scene.mesh, materials, slots,
                       artists_materials(context, materials, slots))


def scene_layout(op, context, refusal: str):
    """(photo, AssetLayout) for Run All, which fits the asset (any number of materials and objects) into
    the photo (mode Scene); `refusal` ends the one sentence said in another mode."""
    settings = context.scene.scenefit
    if settings.mode != "scene":
        raise InputError(f"{refusal} (mode Scene); mode '{settings.mode}' does not.")
    photo = photo_path(context)
    layout = asset_layout(context)
    op._object_name = layout.name
    return photo, layout


class OnMesh:
    """Operator mixin: available when the active object is a mesh (what every stage works on)."""

    @classmethod
    def poll(cls, context) -> bool:
        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            return True
        cls.poll_message_set("Select the asset: a mesh object")
        return False


def needs_setting(name: str, why: str) -> classmethod:
    """An operator poll: available when the scene's SceneFit setting `name` is filled in."""

    def poll(cls, context) -> bool:
        settings = getattr(context.scene, "scenefit", None)
        if settings is not None and bool(getattr(settings, name).strip()):
            return True
        cls.poll_message_set(why)
        return False

    return classmethod(poll)


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
    """The PhotoCamera the Cycles set-up uses when no job hands one back: the view's, else the camera the
    World's light map was estimated with (its report.json), else the estimate from the photo."""
    from ..core.stages.compose import light_camera
    from ..core.stages.camera import photo_camera_estimate
    from ..core.scene.camera import PhotoCamera

    if view["camera"] is not None:
        return PhotoCamera(**view["camera"])
    light = context.scene.scenefit.light_path
    if light and (Path(bpy.path.abspath(light)).parent / "report.json").is_file():
        return light_camera(bpy.path.abspath(light), {}, 1, 1)[0]
    return photo_camera_estimate(photo).photo_camera()


# -- preferences -------------------------------------------------------------------------------------
def preferences(context=None):
    """The add-on preferences, or None when SceneFit was registered without being enabled as an add-on."""
    addon = (context or bpy.context).preferences.addons.get(ADDON_PACKAGE)
    return addon.preferences if addon is not None else None


def offline(context=None) -> bool:
    """No downloads when the artist asked for it or Blender's online access is off."""
    prefs = preferences(context)
    return bool(prefs.offline if prefs is not None else False) or not bpy.app.online_access


def model_cache(context=None) -> str | None:
    """The preference's folder, else None: the Hugging Face cache (HF_HUB_CACHE / HF_HOME), where weights other
    tools fetched are found, and which outlives the extension (its user folder is deleted with it)."""
    prefs = preferences(context)
    if prefs is not None and prefs.model_cache:
        return bpy.path.abspath(prefs.model_cache)
    return None


def depth_model_preference(context=None) -> str | None:
    """The preferences' depth model (hub id or folder), None for the default: what a run's RunConfig/Job takes."""
    prefs = preferences(context)
    return (prefs.depth_model or None) if prefs is not None else None


def model_settings(context=None):
    """(ModelConfig, DepthConfig) from the preferences: hub ids or folders, cache, offline, device."""
    from ..core.guidance import ModelConfig
    from ..core.stages.light.depth import depth_config_for

    prefs = preferences(context)
    cache, local_only = model_cache(context), offline(context)
    device = prefs.device if prefs is not None else "auto"
    kwargs = {}
    if prefs is not None:
        kwargs = {"base_model": prefs.base_model, "inpaint_model": prefs.inpaint_model,
                  "attention_slicing": prefs.attention_slicing, "vae_tiling": prefs.vae_tiling,
                  "cpu_offload": prefs.cpu_offload}
    models = ModelConfig(cache_dir=cache, local_files_only=local_only, device_type=device, **kwargs)
    return models, depth_config_for(models, model=prefs.depth_model if prefs is not None else None)


# -- where results go --------------------------------------------------------------------------------
def _forbidden_roots() -> list[Path]:
    """Blender deletes its temp dir on exit; the add-on folder is replaced on every update."""
    roots = [Path(__file__).resolve().parent.parent]
    if bpy.app.tempdir:
        roots.append(Path(bpy.app.tempdir).resolve())
    return roots


def _unsaved_root() -> Path:
    """Where an unsaved file's runs go (its images are also packed into the .blend)."""
    try:
        return Path(bpy.utils.extension_path_user(ADDON_PACKAGE, path="unsaved", create=True))
    except (ValueError, KeyError):  # not installed as an extension
        return Path(tempfile.gettempdir()) / "scenefit-unsaved"


def output_root(context) -> Path:
    """The panel's Output folder resolved against the .blend ('//'), or the unsaved-file folder."""
    text = context.scene.scenefit.output_dir or "//scenefit/"
    if text.startswith("//") and not bpy.data.is_saved:
        return _unsaved_root()
    return Path(bpy.path.abspath(text))


def run_folder(context, stage: str, name: str = "") -> Path:
    """A NEW folder for one run of `stage` (never an earlier run's): <output>/<name>/<stage>-<time>[-n].

    Only its path: the run writes beside it and swaps it in whole (core.output_folder), so a
    cancelled or failed run leaves no folder behind."""
    from ..core.base.output_folder import check_output_folder, staging_path

    root = output_root(context).resolve()
    for forbidden in _forbidden_roots():
        if root == forbidden or forbidden in root.parents:
            raise InputError(f"SceneFit does not write into '{root}' (Blender's temporary or the add-on's own "
                             "folder); set the Output folder in the SceneFit panel.")
    parent = root / bpy.path.clean_name(name) if name else root
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in range(1, 1000):
        folder = parent / (f"{stage}-{stamp}" if n == 1 else f"{stage}-{stamp}-{n}")
        if not folder.exists() and not staging_path(folder).exists():
            try:
                return check_output_folder(folder)
            except InputError:  # the command line's wording names --out; the panel names its field
                raise InputError(f"Cannot write into '{parent}'; choose another Output folder in the SceneFit "
                                 "panel.") from None
    raise InputError(f"Too many runs in '{parent}' this second; try again.")


def last_finished_run(folder: Path) -> Path | None:
    """The latest finished run beside the new run `folder` (run_folder's <output>/<name>/<stage>-<time>): the
    one whose report.json was written last; its stages with the new run's keys are reused (copied in)."""
    stage = folder.name.split("-", 1)[0]
    finished = [d for d in folder.parent.glob(f"{stage}-*") if d != folder and (d / "report.json").is_file()]
    return max(finished, key=lambda d: (d / "report.json").stat().st_mtime_ns, default=None)


def keep_image(image) -> None:
    """An unsaved file cannot refer to files next to it: pack the image into the .blend instead."""
    if not bpy.data.is_saved and image.packed_file is None:
        image.pack()


def relative_if_saved(path: str | os.PathLike) -> str:
    """'//…' relative to the .blend when it is saved (the file and its run folders move together)."""
    path = str(path)
    if bpy.data.is_saved:
        try:
            return bpy.path.relpath(path)
        except ValueError:  # another drive on Windows
            return path
    return path
