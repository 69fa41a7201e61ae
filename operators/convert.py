"""Convert: fit a neural texture to the active object's own maps, in a worker thread.

The operator is modal: it gathers the asset on the main thread, starts the job in a thread, polls
a queue on a timer (progress into the panel and the status bar), sets a cancel event on Esc, and
writes the baked maps back as a new material on the main thread when the job ends.
"""
from __future__ import annotations

import queue
import threading
from pathlib import Path

import bpy

from ..blender_io import write_result_material
from ..core.errors import Cancelled, SceneFitError
from ..core.progress import check_cancel
from .common import gather_asset, output_dir, poll_mesh

def run_conversion(mesh, maps, preset: str, out_dir: Path, progress, cancel=None) -> dict:
    """The one place that calls core's conversion (worker thread: no bpy here).

    Returns {"base_color": path, "roughness": path, "metallic": path} of the baked maps.
    """
    from ..core.convert import convert_preset
    from ..core.pipeline import convert_and_bake, write_report

    _, report = convert_and_bake(mesh, maps, out_dir, convert_preset(preset), progress=progress, cancel=cancel)
    write_report(Path(out_dir) / "report.json", report)
    outputs = report["outputs"]  # a constant roughness/metallic is a float, not a map
    return {key: outputs[key] if isinstance(outputs[key], float) else Path(outputs[key])
            for key in ("base_color", "roughness", "metallic")}


class SCENEFIT_OT_convert(bpy.types.Operator):
    """Fit SceneFit's neural texture to the active object's material maps (Esc cancels)"""

    bl_idname = "scenefit.convert"
    bl_label = "Convert"
    bl_options = {"REGISTER"}

    _timer = None
    _thread: threading.Thread | None = None

    @classmethod
    def poll(cls, context):
        return poll_mesh(context)

    def invoke(self, context, event):
        settings = context.scene.scenefit
        try:
            obj, mesh, maps = gather_asset(context)
            out = output_dir(context, "convert")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self._object_name = obj.name
        preset = settings.preset  # read bpy data here; the worker never touches it
        self._events: queue.Queue = queue.Queue()
        self._cancel = threading.Event()

        def progress(event) -> None:  # called from the worker thread: no bpy here
            check_cancel(self._cancel)
            self._events.put(("progress", event))

        def work() -> None:
            try:
                self._events.put(("done", run_conversion(mesh, maps, preset, out, progress, self._cancel)))
            except Cancelled as error:
                self._events.put(("cancelled", str(error)))
            except SceneFitError as error:
                self._events.put(("error", str(error)))
            except Exception as error:  # an unexpected failure still ends the modal loop
                self._events.put(("error", f"Conversion failed: {error!r}"))

        settings.progress, settings.status = 0.0, "Starting…"
        self._thread = threading.Thread(target=work, name="scenefit-convert", daemon=True)
        self._thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        """Synchronous run for scripts and `blender -b` (no window, so no modal timer)."""
        try:
            obj, mesh, maps = gather_asset(context)
            out = output_dir(context, "convert")
            maps_paths = run_conversion(mesh, maps, context.scene.scenefit.preset, out, progress=None)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        mat = write_result_material(obj, maps_paths)
        self.report({"INFO"}, f"Done: material '{mat.name}'")
        return {"FINISHED"}

    def modal(self, context, event):
        settings = context.scene.scenefit
        if event.type == "ESC":
            self._cancel.set()
            settings.status = "Cancelling…"
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        while True:
            try:
                kind, payload = self._events.get_nowait()
            except queue.Empty:
                break
            if kind == "progress":
                settings.progress = 100.0 * payload.fraction
                settings.status = f"{payload.stage} {payload.step}/{payload.total} {payload.message}".strip()
                continue
            return self._finish(context, kind, payload)
        for area in context.screen.areas if context.screen else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()
        return {"RUNNING_MODAL"}

    def _finish(self, context, kind: str, payload):
        context.window_manager.event_timer_remove(self._timer)
        settings = context.scene.scenefit
        settings.progress = 100.0 if kind == "done" else settings.progress
        if kind == "done":
            obj = bpy.data.objects.get(self._object_name)
            if obj is None:
                self.report({"WARNING"}, "The object was deleted while converting; maps are on disk only.")
                return {"FINISHED"}
            mat = write_result_material(obj, payload)
            settings.status = f"Done: material '{mat.name}'"
            self.report({"INFO"}, settings.status)
            return {"FINISHED"}
        settings.status = payload
        self.report({"WARNING"} if kind == "cancelled" else {"ERROR"}, payload)
        return {"CANCELLED"}


classes = (SCENEFIT_OT_convert,)

register, unregister = bpy.utils.register_classes_factory(classes)
