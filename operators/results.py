"""Results written back into Blender as NEW datablocks, and switching between them and the originals.

Every material, World and image SceneFit makes is tagged `["scenefit"] = <stage>`; the artist's own
are never modified (they get a fake user while replaced, so saving keeps them). Images refer to
files in the run folder next to the .blend ('//' paths), or are packed when the file is unsaved.
"""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import EnumProperty

from ..blender_io import write_result_material
from ..blender_io.world import assign_world, world_from_hdr
from ..core.base.errors import InputError
from ..blender_io.tag import TAG
from .asset import ORIGINAL_PROPERTY, artists_material_behind, asset_state, recorded_originals
from .folders import keep_image, relative_if_saved
from .polls import needs_setting
from ..workers.job_seam import TextureOutcome



def _settle_image(image, stage: str) -> None:
    image[TAG] = stage
    image.filepath = relative_if_saved(bpy.path.abspath(image.filepath))
    keep_image(image)


def material_images(material) -> list:
    tree = material.node_tree
    return [n.image for n in tree.nodes if n.type in ("TEX_IMAGE", "TEX_ENVIRONMENT") and n.image] if tree else []


def apply_result_material(context, object_name: str, result: TextureOutcome, stage: str):
    """A new material from result.maps in the object's active slot; the artist's material is kept as the original."""
    obj = bpy.data.objects.get(object_name)
    if obj is not None and not obj.material_slots:   # (a generated texture on an object without material)
        obj.data.materials.append(None)
    slot = obj.active_material_index if obj is not None else 0
    return apply_result_materials(context, [[(object_name, slot)]], [dict(result.maps)], result, stage,
                                  names=[f"{object_name} SceneFit {stage}"])[0]


def apply_result_materials(context, slots: list[list[tuple[str, int]]], maps: list[dict], result: TextureOutcome,
                           stage: str,
                           names: list[str] | None = None, wraps: list | None = None, digest: str = "",
                           owner: str = "") -> list:
    """A new material per material of the asset, from maps[i], in every slot slots[i] names ((object name,
    slot number) pairs); returns them. What each slot held is kept as its original (a fake user, so saving
    keeps it) for the Results section's switch; a slot that held an earlier SceneFit result keeps the
    artist's material it replaced as its original. Nothing is changed when an object or slot is gone."""
    settings = context.scene.scenefit
    where = Path(result.report).parent
    targets = []
    for pairs in slots:
        found = []
        for name, number in pairs:
            obj = bpy.data.objects.get(name)
            if obj is None or number >= len(obj.material_slots):
                raise InputError(f"The object '{name}' (or its material slot {number + 1}) was deleted while SceneFit "
                                 f"ran; the maps are in '{where}'.")
            found.append((obj, number))
        targets.append(found)
    previous = recorded_originals(settings)
    records, made = [], []
    for index, (found, paths) in enumerate(zip(targets, maps)):
        first, number = found[0]
        held = first.material_slots[number].material
        artists = artists_material_behind(held, previous.get((first.name, number)))
        name = names[index] if names else f"{artists.name if artists else first.name} SceneFit {stage}"
        mat = write_result_material(first, paths, name=name, assign=False, wrap=wraps[index] if wraps else None)
        mat[TAG] = stage
        if artists is not None:
            mat[ORIGINAL_PROPERTY] = artists
        for image in material_images(mat):
            _settle_image(image, stage)
        for obj, number in found:
            current = obj.material_slots[number].material
            original = artists_material_behind(current, previous.get((obj.name, number)))
            if current is not None and TAG not in current:
                current.use_fake_user = True   # the artist's, swapped out, survives saving (a result: its run holds it)
            obj.material_slots[number].material = mat
            records.append((obj, number, original, mat))
        made.append(mat)
    # Every slot that ever got a result keeps its entry (the latest result there), so the switch can act
    # on an earlier asset: a slot of this job's replaces its own entry, and a deleted object's goes.
    job = 1 + max((e.job for e in settings.result_slots), default=0)
    done = {(obj.name, number) for obj, number, _, _ in records}
    for index in reversed(range(len(settings.result_slots))):
        entry = settings.result_slots[index]
        if entry.asset_object is None or (entry.asset_object.name, entry.slot) in done:
            settings.result_slots.remove(index)
    for obj, number, original, mat in records:
        entry = settings.result_slots.add()
        entry.asset_object, entry.slot, entry.original, entry.result, entry.job = obj, number, original, mat, job
    settings.result_material, settings.result_object = made[0], records[0][0]
    if records[0][2] is not None:
        settings.original_material = records[0][2]
    if result.texture:   # the asset's own texture, and the mesh it was made for (digest)
        state = asset_state(bpy.data.objects.get(owner) or records[0][0])   # the asset's (its active object's)
        state.texture_path = relative_if_saved(result.texture)
        state.texture_mesh = digest
    return made


def materials_words(materials: list) -> str:
    """The result materials as a status line names them."""
    return f"material{'s' if len(materials) > 1 else ''} {', '.join(repr(m.name) for m in materials)}"


def result_targets(layout) -> dict:
    """Where a job's result goes, as plain data kept on the operator while the job runs: an
    operators.asset.AssetLayout's objects and slots by their ids (operators/identity.py: a rename while the
    job runs keeps them), the wrap of each material's maps, and whether the result is named after the
    object (one object with one material: '<object> SceneFit <stage>'; else each is named after the
    artist's material it replaces). targets_now gives the names they have when the job ends."""
    from ..blender_io.material import material_wrap

    from .asset import asset_digest
    from .identity import object_id

    ids = {name: object_id(bpy.data.objects[name]) for name in layout.objects}
    if layout.name not in ids:
        ids[layout.name] = object_id(bpy.data.objects[layout.name])
    one = len(layout.objects) == 1 and len(layout.materials) == 1
    return {"object_ids": [ids[name] for name in layout.objects],
            "slots": [[(ids[name], number) for name, number in pairs] for pairs in layout.slots],
            "wraps": [material_wrap(m) for m in layout.artists], "named_after_object": one,
            "digest": asset_digest(layout), "owner_id": ids[layout.name], "names": dict(map(reversed, ids.items()))}


def targets_now(targets: dict) -> dict:
    """result_targets with the objects' names as they are now: objects, slots (object name, slot number),
    owner and the result's name; an object deleted meanwhile keeps its name at the click (and its slot is
    refused in one sentence when the result is applied)."""
    from .identity import object_by_id

    def name(value: str) -> str:
        obj = object_by_id(value)
        return obj.name if obj is not None else targets["names"].get(value, value)

    objects = [name(i) for i in targets["object_ids"]]
    return dict(targets, objects=objects, slots=[[(name(i), n) for i, n in pairs] for pairs in targets["slots"]],
                owner=name(targets["owner_id"]), name=objects[0] if targets["named_after_object"] else None)


def apply_layout_results(context, targets: dict, result: TextureOutcome, stage: str) -> list:
    """The job's maps into every slot of `targets` (result_targets): result.material_maps has each
    material's own (several materials), else result.maps goes to the one material's slots."""
    now = targets_now(targets)
    per_material = result.material_maps or [result.maps]
    maps = [{k: m[k] for k in ("base_color", "roughness", "metallic")} for m in per_material]
    names = [f"{now['name']} SceneFit {stage}"] if now["name"] else None
    return apply_result_materials(context, now["slots"], maps, result, stage, names=names, wraps=targets["wraps"],
                                  digest=targets.get("digest", ""), owner=now["owner"])


def apply_result_world(context, hdr_path: str, stage: str = "light", scene=None):
    """A new World lit by the HDR map (rotation and strength editable) in `scene` (the job's, else the
    current one); the artist's World is kept."""
    scene = scene or context.scene
    settings = scene.scenefit
    world = world_from_hdr(hdr_path, name="SceneFit Light")
    world[TAG] = stage
    for node in world.node_tree.nodes:
        if node.type == "TEX_ENVIRONMENT" and node.image is not None:
            _settle_image(node.image, stage)
    if scene.world is not None and TAG not in scene.world:
        settings.original_world = scene.world
    assign_world(scene, world)
    settings.result_world = world
    settings.light_path = relative_if_saved(hdr_path)
    return world


def apply_composite_image(context, path: str, stage: str):
    """The composite render as an image (tagged, kept like every result image) and the panel's path to it."""
    image = bpy.data.images.load(str(Path(path).resolve()), check_existing=False)
    image.name = "SceneFit Composite"
    image.use_fake_user = True  # no material uses it: without a user, saving would drop it
    _settle_image(image, stage)
    context.scene.scenefit.composite_path = relative_if_saved(path)
    return image


def switched_entries(context, entries) -> tuple[list, str]:
    """The recorded result slots the Results switch acts on, and whose they are in words: those of the
    selected objects that have any, else the last job's."""
    chosen = set(context.selected_objects)
    mine = [e for e in entries if e.asset_object is not None and e.asset_object in chosen]
    if mine:
        names = sorted({e.asset_object.name for e in mine})
        return mine, f"the selected object{'s' * (len(names) > 1)} {', '.join(names)}"
    last = max(e.job for e in entries)
    return [e for e in entries if e.job == last], "the last result's asset"


def put_in_slots(entries, result: bool = True) -> int:
    """Each entry's result (or original) material into its object's slot; how many were switched. Whichever
    material is swapped out gets a fake user, so it survives saving."""
    switched = 0
    for entry in entries:
        obj, mat = entry.asset_object, entry.result if result else entry.original
        if obj is None or mat is None or entry.slot >= len(obj.material_slots):
            continue
        current = obj.material_slots[entry.slot].material
        if current is not None and TAG not in current:   # (a result swapped out: its entry holds it)
            current.use_fake_user = True
        obj.material_slots[entry.slot].material = mat
        switched += 1
    return switched


class SCENEFIT_OT_use_result(bpy.types.Operator):
    """Switch the materials of the selected objects (else of the last result's asset) or the scene's World
    between SceneFit's result and the original"""

    bl_idname = "scenefit.use_result"
    bl_label = "Use Result"
    bl_options = {"REGISTER", "UNDO"}

    target: EnumProperty(name="What", default="MATERIAL", description="The asset's materials or the scene's World",
                         items=(("MATERIAL", "Material", "The asset's materials"),
                                ("WORLD", "World", "The scene's World (its light)")))
    which: EnumProperty(name="Show", default="RESULT", description="SceneFit's result or what was there before",
                        items=(("RESULT", "SceneFit", "SceneFit's result"), ("ORIGINAL", "Original", "The artist's")))

    def execute(self, context):
        settings = context.scene.scenefit
        if self.target == "WORLD":
            world = settings.result_world if self.which == "RESULT" else settings.original_world
            if world is None:
                self.report({"ERROR"}, "There is no such World; estimate the light first.")
                return {"CANCELLED"}
            assign_world(context.scene, world)
            return {"FINISHED"}
        if settings.result_slots:
            entries, whose = switched_entries(context, settings.result_slots)
            switched = put_in_slots(entries, result=self.which == "RESULT")
            if not switched:
                self.report({"ERROR"}, "There is no such material; convert or adapt the asset first.")
                return {"CANCELLED"}
            shown = "SceneFit's results" if self.which == "RESULT" else "the original materials"
            self.report({"INFO"}, f"{shown.capitalize()} in {switched} material slot{'s' * (switched != 1)} of {whose}.")
            return {"FINISHED"}
        obj = settings.result_object
        mat = settings.result_material if self.which == "RESULT" else settings.original_material
        if obj is None or mat is None:
            self.report({"ERROR"}, "There is no such material; convert or adapt the asset first.")
            return {"CANCELLED"}
        if obj.active_material is not None and TAG not in obj.active_material:
            obj.active_material.use_fake_user = True  # the artist's, swapped out, survives saving
        obj.active_material = mat
        return {"FINISHED"}


class SCENEFIT_OT_open_composite(bpy.types.Operator):
    """Open the last composite in an Image Editor (or load it as an image)"""

    poll = needs_setting("composite_path", "No composite yet: Run All or Compose makes one")
    bl_idname = "scenefit.open_composite"
    bl_label = "Open Composite"
    bl_options = {"REGISTER"}

    def execute(self, context):
        path = Path(bpy.path.abspath(context.scene.scenefit.composite_path))
        if not path.is_file():
            self.report({"ERROR"}, f"The composite '{path}' is gone; compose again.")
            return {"CANCELLED"}
        image = bpy.data.images.load(str(path), check_existing=True)
        image.reload()
        for area in context.screen.areas if context.screen else ():
            if area.type == "IMAGE_EDITOR":
                area.spaces.active.image = image
                break
        else:
            if context.window is not None and not bpy.app.background:
                bpy.ops.render.view_show("INVOKE_DEFAULT")
                for area in context.window_manager.windows[-1].screen.areas:
                    if area.type == "IMAGE_EDITOR":
                        area.spaces.active.image = image
        return {"FINISHED"}


classes = (SCENEFIT_OT_use_result, SCENEFIT_OT_open_composite)

register, unregister = bpy.utils.register_classes_factory(classes)
