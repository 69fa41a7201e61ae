"""Each asset's runs (the Results section's list): recorded when a run ends, finished or not; Apply puts a
run's materials in the asset's slots and its World in the scene, Open Folder shows its files, Delete takes
its datablocks out of the file (and, on confirmation, its folder off the disk), Resume continues a
cancelled adaptation from its checkpoint."""
from __future__ import annotations

import shutil
import time
from pathlib import Path

import bpy
from bpy.props import BoolProperty, IntProperty

from ..blender_io.world import assign_world
from ..core.base.errors import InputError, SceneFitError
from ..blender_io.tag import TAG
from .folders import relative_if_saved
from .asset import asset_owner, asset_state
from .results import put_in_slots


def record_run(op, context, state: str, result) -> None:
    """The run `op` (a job operator that records runs) just ended, in its asset's history: its folder, preset,
    prompt, time and state as the click asked for them (the request of a Run All: a rename, another selection
    or an edited prompt meanwhile changes nothing); for a finished run, the materials in its slots, its World
    and composite. An asset deleted meanwhile: the run goes to the scene's list of runs without an asset."""
    from .identity import object_by_id

    settings = context.scene.scenefit
    request = getattr(op, "_request", None)
    layout = getattr(op, "_layout", None) or {}
    owner_id = layout.get("owner_id")
    obj = object_by_id(owner_id) if owner_id else bpy.data.objects.get(getattr(op, "_object_name", "") or "")
    names = [o.name for o in (object_by_id(i) for i in layout.get("object_ids", ())) if o is not None] or \
        ([obj.name] if obj is not None else [])
    runs = asset_state(obj).runs if obj is not None else settings.runs_without_asset
    folder = relative_if_saved(op._out)
    run = next((r for r in runs if r.folder == folder), None) or runs.add()   # a resumed run updates its entry
    run.folder, run.stage, run.state = folder, op.job_name, state
    if request is not None:
        run.preset, run.prompt = request.config.preset, request.config.prompt
    else:
        run.preset = op.run_preset(context) if hasattr(op, "run_preset") else settings.preset   # (Draft at the question)
        run.prompt = settings.prompt
    run.when = time.strftime("%Y-%m-%d %H:%M")
    run.mesh_digest = layout.get("digest", "")
    for name in ("iterations", "model_resolution", "render_size"):
        setattr(run, name, int(getattr(op, name, 0) or 0))
    if obj is not None:
        asset_state(obj).run_index = list(runs).index(run)
    if state != "finished" or result is None:
        return
    run.texture_path = relative_if_saved(result.texture) if result.texture else ""
    made = getattr(op, "_made", {})
    run.world, run.composite = made.get("world"), made.get("composite")
    if run.composite is not None:
        run.composite.preview_ensure()   # the list's thumbnail, made now rather than while drawing
    run.slots.clear()
    last = max((e.job for e in settings.result_slots), default=None)
    for entry in settings.result_slots:
        if entry.job == last and entry.asset_object is not None and entry.asset_object.name in names:
            kept = run.slots.add()
            kept.asset_object, kept.slot, kept.original, kept.result, kept.job = (
                entry.asset_object, entry.slot, entry.original, entry.result, entry.job)


def chosen_run(context, index: int):
    """(asset state, run) of the active asset's run `index`; one sentence when there is none. A duplicate of an
    asset is told apart here first (operators/identity.py): its copied history is emptied."""
    from .identity import object_id

    owner = asset_owner(context.scene)
    if owner is not None:
        object_id(owner)
    state = owner.scenefit_asset if owner is not None else None
    if state is None or not 0 <= index < len(state.runs):
        raise InputError("There is no such run; choose one in the Results section's list.")
    return state, state.runs[index]


def run_folder_path(run) -> Path:
    return Path(bpy.path.abspath(run.folder))


class _RunOperator:
    index: IntProperty(name="Run", min=0, options={"SKIP_SAVE"}, description="Which run of the list")

    @classmethod
    def poll(cls, context):
        owner = asset_owner(context.scene)
        if owner is not None and len(owner.scenefit_asset.runs) > 0:
            return True
        cls.poll_message_set("The active asset has no runs yet")
        return False


class SCENEFIT_OT_apply_run(_RunOperator, bpy.types.Operator):
    """Put this run's materials back in the asset's slots and its World in the scene (the originals stay in the
    file; the Results switch brings them back)"""

    bl_idname = "scenefit.apply_run"
    bl_label = "Apply Run"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        try:
            state, run = chosen_run(context, self.index)
            if run.state != "finished":
                raise InputError(f"The run of {run.when} was {run.state}; it made no materials to apply.")
            switched = put_in_slots(run.slots)
            if not switched and run.world is None:
                raise InputError(f"The run of {run.when} has no materials or World left in this file.")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        settings = context.scene.scenefit
        if run.world is not None:
            if context.scene.world is not None and TAG not in context.scene.world:
                settings.original_world = context.scene.world
            assign_world(context.scene, run.world)
            settings.result_world = run.world
        if run.texture_path:
            state.texture_path, state.texture_mesh = run.texture_path, run.mesh_digest
        self.report({"INFO"}, f"The run of {run.when}: {switched} material slot{'s' * (switched != 1)}"
                              + (f", World '{run.world.name}'" if run.world is not None else ""))
        return {"FINISHED"}


def compared_slots(run) -> list[tuple[str, object, object]]:
    """(slot label, the artist's material, this run's) for each slot the run filled, each slot once."""
    seen, rows = set(), []
    for entry in run.slots:
        if entry.asset_object is None or entry.result is None or (entry.asset_object.name, entry.slot) in seen:
            continue
        seen.add((entry.asset_object.name, entry.slot))
        rows.append((f"{entry.asset_object.name} · {entry.slot + 1}", entry.original, entry.result))
    return rows


class SCENEFIT_OT_compare_run(_RunOperator, bpy.types.Operator):
    """Show this run's composite, and each of the asset's materials before and after it, side by side"""

    bl_idname = "scenefit.compare_run"
    bl_label = "Compare"
    bl_options = {"REGISTER"}

    def invoke(self, context, event):
        try:
            _, run = chosen_run(context, self.index)
            self._rows = compared_slots(run)
            if not self._rows and run.composite is None:
                raise InputError(f"The run of {run.when} left no materials or composite in this file to compare.")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        for _, original, result in self._rows:   # Blender renders the previews; the popup shows them as they come
            for material in (original, result):
                if material is not None:
                    material.preview_ensure()
        self._composite = run.composite
        return context.window_manager.invoke_popup(self, width=520)

    def draw(self, context):
        layout = self.layout
        if self._composite is not None and self._composite.preview is not None:
            layout.label(text="Composite")
            layout.template_icon(icon_value=self._composite.preview.icon_id, scale=10.0)
        grid = layout.grid_flow(columns=3, even_columns=True, align=True)
        for text in ("Slot", "Original", "Result"):
            grid.label(text=text)
        for label, original, result in self._rows:
            grid.label(text=label, translate=False)
            for material in (original, result):
                column = grid.column(align=True)
                if material is None:
                    column.label(text="(empty)")
                    continue
                column.template_icon(icon_value=material.preview.icon_id, scale=5.0)
                column.label(text=material.name, translate=False)

    def execute(self, context):
        return {"FINISHED"}


class SCENEFIT_OT_open_run_folder(_RunOperator, bpy.types.Operator):
    """Open this run's folder in the system's file browser"""

    bl_idname = "scenefit.open_run_folder"
    bl_label = "Open Folder"
    bl_options = {"REGISTER"}

    def execute(self, context):
        from ..core.base.output_folder import staging_path

        try:
            _, run = chosen_run(context, self.index)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        folder = run_folder_path(run)
        shown = folder if folder.is_dir() else staging_path(folder) if staging_path(folder).is_dir() else None
        if shown is None:
            self.report({"ERROR"}, f"The run's folder '{folder}' is gone.")
            return {"CANCELLED"}
        bpy.ops.wm.path_open(filepath=str(shown))
        return {"FINISHED"}


def run_datablocks(run, runs) -> list:
    """The datablocks only this run made: its materials (and their images), World, composite; what another
    kept run also holds stays."""
    others = {x.as_pointer() for r in runs if r != run for x in
              [e.result for e in r.slots] + [r.world, r.composite] if x is not None}
    made = [e.result for e in run.slots if e.result is not None] + [b for b in (run.world, run.composite) if b]
    unique = []
    for block in made:
        if TAG in block and block.as_pointer() not in others and block not in unique:
            unique.append(block)
    return unique


def remove_datablocks(context, blocks: list, run) -> int:
    """Take the run's datablocks out of the file: a slot or World showing one gets the artist's back first."""
    from .results import material_images

    for entry in run.slots:
        obj = entry.asset_object
        if obj is not None and entry.slot < len(obj.material_slots) and \
                obj.material_slots[entry.slot].material in blocks:
            obj.material_slots[entry.slot].material = entry.original
    settings = context.scene.scenefit
    if context.scene.world in blocks:
        assign_world(context.scene, settings.original_world)
    images = []
    for block in blocks:
        if isinstance(block, bpy.types.Material):
            images += [i for i in material_images(block) if TAG in i]
        elif isinstance(block, bpy.types.World) and block.node_tree is not None:
            images += [n.image for n in block.node_tree.nodes if n.type == "TEX_ENVIRONMENT" and n.image and TAG in n.image]
    removed = 0
    for block in blocks:
        collection = (bpy.data.materials if isinstance(block, bpy.types.Material) else
                      bpy.data.worlds if isinstance(block, bpy.types.World) else bpy.data.images)
        collection.remove(block)
        removed += 1
    for image in images:
        if image.users == 0 or (image.users == 1 and image.use_fake_user):
            bpy.data.images.remove(image)
            removed += 1
    return removed


class SCENEFIT_OT_delete_run(_RunOperator, bpy.types.Operator):
    """Take this run's materials, World and composite out of the file (the artist's materials go back in their
    slots); with Folder, also delete the run's folder from the disk, after asking"""

    bl_idname = "scenefit.delete_run"
    bl_label = "Delete Run"
    bl_options = {"REGISTER", "UNDO"}

    folder: BoolProperty(name="Folder", default=False, options={"SKIP_SAVE"},
                         description="Also delete the run's folder (its files) from the disk")

    def invoke(self, context, event):
        if self.folder:
            return context.window_manager.invoke_confirm(self, event, title="Delete the run and its folder?",
                                                         message="Its files are deleted from the disk.",
                                                         confirm_text="Delete", icon="TRASH")
        return self.execute(context)

    def execute(self, context):
        from ..core.base.output_folder import is_run_folder, staging_path

        try:
            state, run = chosen_run(context, self.index)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        removed = remove_datablocks(context, run_datablocks(run, state.runs), run)
        said = f"{removed} datablock{'s' * (removed != 1)} removed"
        if self.folder:
            folder = run_folder_path(run)
            gone = [f for f in (folder, staging_path(folder)) if f.is_dir() and is_run_folder(f)]
            for f in gone:   # only SceneFit's own run folders (they carry its marker)
                shutil.rmtree(f)
            said += f"; folder '{folder}' deleted" if gone else f"; '{folder}' is not a SceneFit run folder, kept"
        state.runs.remove(self.index)
        state.run_index = min(state.run_index, max(0, len(state.runs) - 1))
        self.report({"INFO"}, said)
        return {"FINISHED"}


class SCENEFIT_OT_resume_run(_RunOperator, bpy.types.Operator):
    """Continue this unfinished run from what it kept: its finished stages and the adaptation's last checkpoint
    (the step count goes on), with the settings it was started with"""

    bl_idname = "scenefit.resume_run"
    bl_label = "Resume"
    bl_options = {"REGISTER"}

    def invoke(self, context, event):
        return self._resume(context, "INVOKE_DEFAULT")

    def execute(self, context):
        return self._resume(context, "EXEC_DEFAULT")

    def _resume(self, context, how: str):
        try:
            _, run = chosen_run(context, self.index)
            if run.stage not in RESUMABLE or run.state == "finished":
                raise InputError(f"Only an unfinished Run All or adaptation can be resumed; the run of {run.when} is "
                                 f"a {run.state} {run.stage}.")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if run.stage == "run":   # as it was clicked (its request.json): its stages and checkpoint go on
            return bpy.ops.scenefit.run(how, resume=bpy.path.abspath(run.folder), choice="start")
        return bpy.ops.scenefit.adapt(how, resume=bpy.path.abspath(run.folder), iterations=run.iterations,
                                      model_resolution=run.model_resolution, render_size=run.render_size)


# The jobs whose unfinished runs go on from their folder (finished stages, the adaptation's checkpoint).
RESUMABLE = ("run", "adapt")


classes = (SCENEFIT_OT_apply_run, SCENEFIT_OT_compare_run, SCENEFIT_OT_open_run_folder, SCENEFIT_OT_delete_run,
           SCENEFIT_OT_resume_run)

register, unregister = bpy.utils.register_classes_factory(classes)
