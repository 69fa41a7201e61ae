"""Blender's side of workers/background.py: the modal operator base, runtime state, previews, the status bar.

An operator subclassing JobOperator says how to gather its inputs (`prepare`, main thread, returns
the work function and plain data) and how to write results back (`apply`, main thread). Invoked
from the UI it runs as a background job polled by a timer, with Esc, a Cancel button and
`cancel()`; called with EXEC_DEFAULT (scripts, `blender -b`) it runs the same work inline.

Runtime state lives on the WindowManager (never saved into the .blend); the live preview is a
`bpy.utils.previews` icon (not a datablock either). Loading another file ends the job first.
"""
from __future__ import annotations

import atexit
import time
from typing import TYPE_CHECKING

import bpy
import numpy as np
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, FloatProperty, PointerProperty, StringProperty

from ..workers import background
from ..workers.job_control import (CONFIRM_CANCEL_AFTER, END_JOB_SECONDS, esc_action, for_the_worker, job_out,
                                   owed_bakes, time_left, whole_run)
from ..core.base.errors import SceneFitError
from ..core.pipeline.registry import RUN_ORDER
from ..core.base.progress import TerminalProgress
from .dependencies import check_dependencies

if TYPE_CHECKING:
    from ..workers.time_model import LocalWork

TIMER_SECONDS = 0.25
_previews = None  # bpy.utils.previews collection, made on register
_preview_serial = (None, 0)  # (job, serial) of the preview shown
_gathering = None  # the operator whose inputs are still being gathered (its bakes between redraws), or None


class SceneFitRuntime(bpy.types.PropertyGroup):
    """What the panel and the status bar show while a job runs (WindowManager: not saved)."""

    running: BoolProperty(default=False, description="Whether a SceneFit job is running")
    job: StringProperty(name="Job", description="The running job")
    stage: StringProperty(name="Stage", description="The step the job is at")
    status: StringProperty(name="Status", description="What the job is doing, or how it ended")
    progress: FloatProperty(name="Progress", min=0.0, max=1.0, subtype="FACTOR", description="How far the job is")
    has_preview: BoolProperty(default=False, description="Whether the job has shown a preview")
    details: StringProperty(name="Details", description="What went wrong in the last job, in full (Copy Details)")
    expected_seconds: FloatProperty(name="Expected", min=0.0, description="How long the job was projected to take "
                                                                          "from the bench's timings (0: unknown)")


def runtime(context=None) -> SceneFitRuntime:
    return (context or bpy.context).window_manager.scenefit_runtime


def preview_icon_id() -> int:
    """The live preview's icon id (0 when there is none)."""
    if _previews is None or "live" not in _previews:
        return 0
    return _previews["live"].icon_id


def show_preview(image: np.ndarray) -> None:
    """Put a (h, w, 3) sRGB uint8 preview into the panel's icon (main thread)."""
    if _previews is None:
        return
    item = _previews["live"] if "live" in _previews else _previews.new("live")
    h, w = image.shape[:2]
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = np.asarray(image, np.float32)[..., :3] / 255.0
    item.image_size = (w, h)
    item.image_pixels_float = rgba[::-1].ravel()  # Blender's first row is the bottom one
    preview_image(rgba[::-1])


# The job's latest preview as an image the artist can open in an Image Editor (no users: not saved).
PREVIEW_IMAGE = "SceneFit Preview"


def preview_image(rgba_bottom_up: np.ndarray):
    """Write a preview (rows bottom first, RGBA in [0, 1], sRGB) into the PREVIEW_IMAGE datablock, made once
    and resized in place, so an Image Editor showing it follows the job."""
    from ..blender_io.tag import TAG

    h, w = rgba_bottom_up.shape[:2]
    image = bpy.data.images.get(PREVIEW_IMAGE)
    if image is None or TAG not in image:
        image = bpy.data.images.new(PREVIEW_IMAGE, w, h)
        image[TAG] = "preview"
    elif tuple(image.size) != (w, h):
        image.scale(w, h)
    image.pixels.foreach_set(np.ascontiguousarray(rgba_bottom_up, np.float32).ravel())
    image.update()
    return image


def show_time_left(rt, state: background.JobState, cancelling: bool) -> None:
    """The status's time left from the job's first moment: the bench's projection for this preset and device
    (rt.expected_seconds, set when the job starts), refined by the job's own pace as it goes."""
    from ..panels.quality import duration_text

    if cancelling or state.finished or rt.expected_seconds <= 0.0:
        return
    left = time_left(rt.expected_seconds, state, RUN_ORDER)
    if left is None:
        return
    said = state.status_line()
    stage_eta = said.rfind(", about ")
    if state.eta_seconds is not None and stage_eta >= 0 and rt.status.endswith(said[stage_eta:]):
        rt.status = rt.status[:len(rt.status) - (len(said) - stage_eta)]   # the stage's own guess gives way
    rt.status = "{}, {}".format(rt.status, bpy.app.translations.pgettext_iface("about {} left").format(
        duration_text(left)))


def update_runtime(context, state: background.JobState, cancelling: bool = False) -> None:
    """The panel's and status bar's copy of a job's state; "cancelling…" stays until the worker has stopped.
    Run All shows one bar for the whole run (stage k of n)."""
    global _preview_serial
    rt = runtime(context)
    rt.running = not state.finished
    rt.job, rt.stage = state.name, state.stage
    rt.status = f"{state.name}: cancelling…" if cancelling and not state.finished else state.status_line()
    rt.progress = state.fraction
    whole = None if cancelling else whole_run(state, RUN_ORDER)
    if whole is not None:
        rt.progress = whole[0]
        rt.status = f"{state.name}: {whole[1]}, {state.status_line().split(': ', 1)[-1]}"
    show_time_left(rt, state, cancelling)
    if state.preview is not None and _preview_serial != (id(state), state.preview_serial):
        show_preview(state.preview)
        _preview_serial = (id(state), state.preview_serial)
        rt.has_preview = True


def redraw(context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in ("VIEW_3D", "STATUSBAR"):
                area.tag_redraw()


def long_work_warning(context, label: str, work: LocalWork | None, runs_remotely: bool) -> str | None:
    """One sentence when a job would run here for longer than LONG_LOCAL_SECONDS; None when it is short,
    unknown, or goes to the worker environment the preferences name for every job."""
    from ..workers.time_model import LONG_LOCAL_SECONDS

    if work is None or work.seconds < LONG_LOCAL_SECONDS:
        return None
    if runs_remotely:
        from .remote import sends_every_job

        try:
            if sends_every_job(context):
                return None
        except SceneFitError:
            pass   # a worker set up wrongly: the job's start says so
        if offers_worker(context, runs_remotely):
            return f"{label} would run {work.where(bpy.app.translations.pgettext_iface)}; the worker set in the preferences runs it sooner."
    if work.on_gpu:
        return (f"{label} would run {work.where(bpy.app.translations.pgettext_iface)}; a worker environment with more GPUs, set in the add-on's "
                "preferences (Jobs), runs it sooner.")
    return (f"{label} would run {work.where(bpy.app.translations.pgettext_iface)}; a GPU, or a worker environment set in the add-on's "
            "preferences (Jobs), runs it far sooner.")


def pointer_over_progress(context, event) -> bool:
    """Whether the pointer is over a place SceneFit's progress shows: the status bar, or a 3D Viewport's
    sidebar (where the SceneFit panel is)."""
    x, y = event.mouse_x, event.mouse_y
    screen = context.window.screen if context.window is not None else None
    for area in screen.areas if screen is not None else ():
        if area.type == "STATUSBAR":
            boxes = [area]
        elif area.type == "VIEW_3D":
            boxes = [r for r in area.regions if r.type == "UI" and r.width > 1]
        else:
            continue
        if any(b.x <= x < b.x + b.width and b.y <= y < b.y + b.height for b in boxes):
            return True
    return False


def has_ui(context) -> bool:
    """Whether a job runs in the background with a bar (a window), rather than inline (`blender -b`, scripts)."""
    return context.window is not None and not bpy.app.background


def job_seconds(job: background.Job) -> float:
    """How long `job` has run so far."""
    return time.perf_counter() - job.state.started


class JobSteps:
    """What a job operator does, apart from Blender's Operator type (so it can be driven without a window).

    invoke returns to Blender at once: the long-work question (from the bench's tables, no model lookup,
    no network) or the job's bar; gathering the inputs (`prepare`) happens on the first tick after, and
    the model lookup inside the job. execute with a window starts the same background job
    (Repeat Last never freezes Blender); only without one (scripts under `blender -b`) is it inline."""

    job_name = "job"
    # True: when the preferences name a worker environment, the job runs there (operators/remote.py).
    runs_remotely = False
    # True: each run is kept in the asset's run history (operators/history.py), finished or not.
    records_runs = False
    # True: the operator's options are shown in a dialog before the job starts (never in a redo panel).
    asks_options = False

    # -- to override ---------------------------------------------------------------------------------
    def prepare(self, context) -> tuple:
        """(work function, plain data) gathered from Blender on the main thread."""
        raise NotImplementedError

    def apply(self, context, result) -> str:
        """Write the job's result back into Blender (main thread); returns the line to report."""
        raise NotImplementedError

    def job_work(self, context) -> tuple:
        """(work, data): the operator's own, or the hand-off to the worker environment when one is chosen."""
        self._remote = False
        if self.runs_remotely:
            from .remote import remote_work, sends_every_job, worker_address

            address = worker_address(context)
            if address is not None and (sends_every_job(context) or getattr(self, "choice", "") == "worker"):
                self._remote = True
                return remote_work(self, context, address)
        return self.prepare(context)

    def long_local_work(self, context) -> LocalWork | None:
        """Projected work this job does when it runs here (None: short, or unknown). Never looks models up."""
        return None

    def long_work_warning(self, context) -> str | None:
        return long_work_warning(context, self.bl_label, self.long_local_work(context), self.runs_remotely)

    def apply_result(self, context, result) -> str:
        if getattr(self, "_remote", False):
            from .remote import apply_remote

            return apply_remote(self, context, result)
        return self.apply(context, result)

    # -- inline: scripts and `blender -b` ------------------------------------------------------------
    def execute(self, context):
        if has_ui(context):
            return self._begin(context)   # Repeat Last, a dialog's confirmation: the background job
        try:
            check_dependencies()
            warning = self.long_work_warning(context)
            if warning:
                self.report({"WARNING"}, warning)
            work, data = self.job_work(context)
            self._out = job_out(data)
            for bake in owed_bakes(data):
                bake.run()
            result = background.run_inline(work, for_the_worker(data), TerminalProgress())
            message = self.apply_result(context, result)
            self.keep_run(context, "finished", result)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, message)
        return {"FINISHED"}

    # -- background job from the UI ------------------------------------------------------------------
    def invoke(self, context, event):
        if not has_ui(context):
            return self.execute(context)
        try:
            warning = self.long_work_warning(context)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if warning and getattr(self, "choice", "ask") == "ask":   # the cost before the click, with real choices
            self._warning = warning
            return context.window_manager.invoke_popup(self, width=480)
        if warning and not hasattr(self, "choice"):   # the dialog's confirmation calls execute, which starts the job
            return context.window_manager.invoke_confirm(self, event, title=f"{self.bl_label}: hours of work",
                                                         message=warning, confirm_text="Start here",
                                                         icon="WARNING")
        if self.asks_options:   # its OK calls execute, which starts the job
            return context.window_manager.invoke_props_dialog(self, title=self.bl_label, confirm_text="Start")
        return self._begin(context)

    def _begin(self, context):
        """The bar at once; the inputs are gathered on the first timer tick (`_gather`), a procedural chain's
        bake on each tick after (`_bake_one`), and the worker started once they are (`_start_job`)."""
        global _gathering
        active = background.active_job()
        if _gathering is not None and _gathering is not self and runtime(context).running:
            self.report({"ERROR"}, f"SceneFit's {_gathering.bl_label} is reading its asset; wait for it or cancel it "
                                   "first.")
            return {"CANCELLED"}
        if active is not None and not active.state.finished:
            self.report({"ERROR"}, f"A SceneFit job ('{active.name}') is already running; wait for it or cancel it "
                                   "first.")
            return {"CANCELLED"}
        _gathering = self   # from the click: a second click before the first tick is refused, not started beside
        self._job, self._gathered, self._owed, self._cancel_gathering = None, None, [], False
        rt = runtime(context)
        rt.running, rt.job, rt.stage, rt.progress = True, self.job_name, "prepare", 0.0
        try:   # the bench's projection (no model lookup): the time left shows from the first moment
            work = self.long_local_work(context)
        except SceneFitError:
            work = None
        rt.expected_seconds = work.seconds if work is not None else 0.0
        rt.status, rt.has_preview = f"{self.bl_label}: reading the asset…", False
        rt.details = ""
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _gather_tick(self, context) -> set:
        """One tick before the worker runs: gather the inputs (the first), else run one owed bake; then the
        worker starts once nothing is owed. Each tick holds the main thread for one step only."""
        global _gathering
        try:
            if getattr(self, "_cancel_gathering", False):
                return self._end_gathering(context, None)
            if getattr(self, "_gathered", None) is None:
                check_dependencies()
                work, data = self.job_work(context)
                self._out = job_out(data)
                self._gathered, self._owed, self._baked = (work, data), owed_bakes(data), 0
            elif self._owed:
                self._owed.pop(0).run()
                self._baked += 1
            if self._owed:
                _gathering = self
                self._show_baking(context)
                redraw(context)
                return {"RUNNING_MODAL"}
            _gathering = None
            return {"RUNNING_MODAL"} if self._start_job(context) else {"CANCELLED"}
        except SceneFitError as error:
            return self._end_gathering(context, error)

    def _show_baking(self, context) -> None:
        rt = runtime(context)
        n = self._baked + len(self._owed)
        rt.stage, rt.progress = "prepare", self._baked / n
        rt.status = f"{self.bl_label}: baking material {self._baked + 1} of {n} ({self._owed[0].words})…"

    def _end_gathering(self, context, error: SceneFitError | None) -> set:
        """Stop before the worker started: refused (`error`, said) or cancelled between bakes."""
        global _gathering
        _gathering = None
        self._remove_timer(context)
        rt = runtime(context)
        rt.running = False
        rt.status = rt.details = str(error) if error is not None else f"{self.bl_label}: cancelled"
        if error is None:
            rt.details = ""
        self.report({"ERROR"} if error is not None else {"WARNING"}, rt.status)
        return {"CANCELLED"}

    def _start_job(self, context) -> bool:
        """Start the worker on the gathered inputs; False (said) when they are refused."""
        work, data = self._gathered
        try:
            self._job = background.start_job(background.Job(self.job_name, work, for_the_worker(data)))
            if getattr(self, "_remote", False):   # the projection is this machine's, not the worker's
                runtime(context).expected_seconds = 0.0
        except SceneFitError as error:
            self._end_gathering(context, error)
            return False
        update_runtime(context, self._job.state)
        return True

    def modal(self, context, event):
        job = getattr(self, "_job", None)
        if event.type == "ESC" and event.value == "PRESS" and job is None and getattr(self, "_owed", None):
            if not pointer_over_progress(context, event):
                return {"PASS_THROUGH"}
            self._cancel_gathering = True   # between bakes: the next tick ends it
            runtime(context).status = f"{self.bl_label}: cancelling…"
            return {"RUNNING_MODAL"}
        if event.type == "ESC" and event.value == "PRESS" and job is not None:
            action = esc_action(pointer_over_progress(context, event), job_seconds(job))
            if action == "pass":
                return {"PASS_THROUGH"}
            if action == "ask":
                bpy.ops.scenefit.cancel_job("INVOKE_DEFAULT")
            else:
                job.cancel()
            update_runtime(context, job.state, job.cancel_requested)
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if job is None:   # gather the inputs, bake what needs Blender's bake, start the worker
            return self._gather_tick(context)
        state = job.poll()
        update_runtime(context, state, job.cancel_requested)
        redraw(context)
        if not state.finished:
            return {"RUNNING_MODAL"}
        return self._finish(context, state)

    def cancel(self, context):
        """Blender ends the modal (file load, window closed): stop the worker, keep Blender's data as is."""
        global _gathering
        if _gathering is self:
            _gathering = None
        job = getattr(self, "_job", None)
        if job is not None:
            job.cancel()
        self._remove_timer(context)
        runtime(context).running = False

    def _remove_timer(self, context) -> None:
        timer = getattr(self, "_timer", None)
        if timer is not None:
            context.window_manager.event_timer_remove(timer)
            self._timer = None

    def _finish(self, context, state: background.JobState):
        self._remove_timer(context)
        background.release_job(self._job)
        rt = runtime(context)
        rt.running = False
        if state.status == background.DONE:
            try:
                message = self.apply_result(context, state.result)
            except SceneFitError as error:   # (its asset deleted meanwhile): the run and its folder are kept
                self.keep_run(context, "failed", None)
                rt.status = rt.details = str(error)
                self.report({"ERROR"}, rt.status)
                return {"CANCELLED"}
            self.keep_run(context, "finished", state.result)
            rt.status = message
            self.report({"INFO"}, message)
            undo_step(f"SceneFit {self.bl_label}")
            return {"FINISHED"}
        self.keep_run(context, "cancelled" if state.status == background.CANCELLED else "failed", None)
        if state.details:
            print(state.details)  # the traceback of an unexpected failure, for the console
        rt.status = state.status_line()
        # The whole story for Copy Details; the report below puts the line in the Info editor.
        rt.details = "" if state.status == background.CANCELLED else "\n".join(
            part for part in (rt.status, state.details or "") if part)
        self.report({"WARNING"} if state.status == background.CANCELLED else {"ERROR"}, rt.status)
        return {"CANCELLED"}

    def keep_run(self, context, state: str, result) -> None:
        """The run in the asset's history (finished, cancelled or failed), for operators that record runs."""
        if self.records_runs and not getattr(self, "_remote", False) and getattr(self, "_out", ""):
            from .history import record_run

            record_run(self, context, state, result)


def undo_step(message: str) -> None:
    """One undo step for what a job wrote into the file (job operators carry no UNDO flag: Blender would
    redo them by calling execute), so Ctrl+Z takes the results out again."""
    try:
        bpy.ops.ed.undo_push(message=message)
    except RuntimeError:   # no undo stack in this context
        pass


CHOICES = (("ask", "Ask", "Ask before long work (the button's own)"),
           ("draft", "Draft", "Run at the Draft preset this time (the panel's preset stays)"),
           ("skip", "Skip adaptation", "Estimate the light and compose now, without adapting the texture"),
           ("worker", "Send to worker", "Run it in the worker environment set in the preferences (Jobs)"),
           ("start", "Start anyway", "Run as set, however long it takes here"))


def offers_worker(context, runs_remotely: bool) -> bool:
    """Whether the question before long work offers Send to Worker: the operator can run there and the
    preferences name a worker that takes jobs when asked."""
    if not runs_remotely:
        return False
    from .remote import worker_address

    try:
        return worker_address(context) is not None
    except SceneFitError:
        return False


class CostFirst:
    """Operator mixin: long local work asks first, offering what the run could be instead (Draft, Skip
    adaptation where the operator can skip it, Start anyway); each button runs the operator again with its
    `choice`, which its prepare honours (`run_preset`, and Run All's guidance)."""

    skippable = False   # True: the operator can run without adapting (Run All)

    def run_preset(self, context) -> str:
        return "draft" if getattr(self, "choice", "ask") == "draft" else context.scene.scenefit.preset

    def draw(self, context):
        layout = self.layout
        layout.label(text=f"{self.bl_label}: long work here", icon="WARNING")
        col = layout.column(align=True)
        for line in wrapped(getattr(self, "_warning", "") or "", 80):
            col.label(text=line)
        row = layout.row(align=True)
        shown = [c for c in CHOICES if c[0] != "ask" and (c[0] != "skip" or self.skippable)
                 and (c[0] != "worker" or offers_worker(context, self.runs_remotely))]
        if context.scene.scenefit.preset == "draft":
            shown = [c for c in shown if c[0] != "draft"]
        for key, text, _ in shown:
            row.operator(self.bl_idname, text=text).choice = key


def wrapped(text: str, width: int) -> list[str]:
    """`text` in lines of at most `width` characters, broken between words (labels do not wrap)."""
    import textwrap

    return textwrap.wrap(text, width) or [""]


class JobOperator(JobSteps, bpy.types.Operator):
    """Base of the operators that run a long stage. Subclasses set job_name and define prepare/apply.
    REGISTER without UNDO: Adjust Last Operation would redo a job by calling execute."""

    bl_options = {"REGISTER"}


class SCENEFIT_OT_cancel_job(bpy.types.Operator):
    """Stop the running SceneFit job within seconds; a Run All or Adapt keeps its finished stages and the
    adaptation's checkpoint, and Resume in the Results section continues it"""

    bl_idname = "scenefit.cancel_job"
    bl_label = "Cancel"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        job = background.active_job()
        if (job is not None and not job.state.finished) or _gathering is not None:
            return True
        cls.poll_message_set("No SceneFit job is running")
        return False

    def invoke(self, context, event):
        job = background.active_job()
        if job is not None and not job.state.finished and job_seconds(job) > CONFIRM_CANCEL_AFTER:
            return context.window_manager.invoke_confirm(self, event, title=f"Cancel {job.name}?",
                                                         message="It has run for a while; Resume continues it "
                                                                 "later from its finished stages.", confirm_text="Cancel it")
        return self.execute(context)

    def execute(self, context):
        job = background.active_job()
        if _gathering is not None and (job is None or job.state.finished):   # between bakes, before the worker
            _gathering._cancel_gathering = True
            runtime(context).status = f"{_gathering.bl_label}: cancelling…"
            return {"FINISHED"}
        job.cancel()
        runtime(context).status = f"{job.name}: cancelling…"
        return {"FINISHED"}


def draw_status_bar(self, context) -> None:
    rt = context.window_manager.scenefit_runtime
    if rt.running:
        row = self.layout.row(align=True)
        row.progress(factor=rt.progress, type="BAR", text=rt.status)
        row.operator("scenefit.cancel_job", text="", icon="X")


@persistent
def _end_job_before_load(*_args) -> None:
    """Loading a file frees the data a job would write into: cancel it and wait for its worker to stop (it
    writes only into its own run folder, which keeps its finished stages, and stops at its next check)."""
    state = background.end_active_job(timeout=END_JOB_SECONDS)
    if state is not None:
        print(f"SceneFit: '{state.name}' was stopped because another file is being loaded ({state.status}); "
              "Resume in the Results section continues a Run All or Adapt from what it kept.")


@persistent
def _reset_after_load(*_args) -> None:
    from ..panels.thumbnail import load_thumbnail
    from .photo import remember_photo_size

    wm = bpy.context.window_manager
    if wm is not None and hasattr(wm, "scenefit_runtime"):
        wm.scenefit_runtime.running = False
    for scene in bpy.data.scenes:   # the panel draws the photo's camera from sizes read here, not in draw()
        if getattr(scene, "scenefit", None) is not None and scene.scenefit.photo_path:
            remember_photo_size(scene.scenefit.photo_path)
            load_thumbnail(scene.scenefit.photo_path)


classes = (SceneFitRuntime, SCENEFIT_OT_cancel_job)


def _end_job_at_exit() -> None:
    """Quitting Blender during a job: stop its worker within END_JOB_SECONDS (its folder keeps what it wrote)."""
    state = background.end_active_job(timeout=END_JOB_SECONDS)
    if state is not None:
        print(f"SceneFit: '{state.name}' was stopped because Blender is quitting ({state.status}).")


def register() -> None:
    global _previews
    import bpy.utils.previews

    atexit.register(_end_job_at_exit)
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.WindowManager.scenefit_runtime = PointerProperty(type=SceneFitRuntime)
    _previews = bpy.utils.previews.new()
    bpy.types.STATUSBAR_HT_header.append(draw_status_bar)
    bpy.app.handlers.load_pre.append(_end_job_before_load)
    bpy.app.handlers.load_post.append(_reset_after_load)


def unregister() -> None:
    global _previews
    import bpy.utils.previews

    atexit.unregister(_end_job_at_exit)
    background.end_active_job(timeout=END_JOB_SECONDS)
    bpy.app.handlers.load_post.remove(_reset_after_load)
    bpy.app.handlers.load_pre.remove(_end_job_before_load)
    bpy.types.STATUSBAR_HT_header.remove(draw_status_bar)
    if _previews is not None:
        bpy.utils.previews.remove(_previews)
        _previews = None
    del bpy.types.WindowManager.scenefit_runtime
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
