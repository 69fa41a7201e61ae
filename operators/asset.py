"""The asset an operator works on (main thread): its objects, mesh and materials as the artist made them
(AssetLayout), its maps planned for the job, the SceneFitAsset that owns its runs, and its texture."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import bpy

from ..blender_io.tag import TAG
from ..core.base.errors import InputError
from ..core.data.map_plan import PendingAsset
from ..core.data.materials import AssetMaterials
from .photo import photo_path

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
    from ..core.data.materials import mesh_digest

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


def asset_layout(context, objects: list | None = None, owner: str = "") -> AssetLayout:
    """The asset of Run All and Bake Asset: the selected objects in world space, or the active object with
    all its material slots (`objects` and `owner`, its name: another asset than the selection's, such as the
    one a resumed run was clicked on). One sentence (InputError) for what cannot be textured."""
    from ..blender_io.material import object_mesh_and_slots
    from ..blender_io.scene_asset import scene_mesh

    objects = objects or asset_objects(context)
    depsgraph = context.evaluated_depsgraph_get()
    active = context.active_object
    name = owner or (active.name if active in objects else objects[0].name)
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
