"""The job operators as an artist meets them, on corpus assets, driven through their own invoke / modal code
with a stand-in window (bpy has none): a click returns at once without touching the network or loading
a model; Esc elsewhere is the artist's, Esc over SceneFit's progress cancels within seconds and
"cancelling…" stays until the worker stops; a cancelled adaptation keeps its checkpoint and Resume
continues its step count; loading a file or quitting stops a job within 2 s; each asset keeps its own
prompt and texture (another mesh's is refused); runs are listed, applied and deleted with their folder."""
import json
import os
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import PythonSession

pytestmark = pytest.mark.blender

CORPUS = Path(os.environ.get("SCENEFIT_CORPUS", Path(__file__).resolve().parents[2].parent / "shared" / "corpus")) / "assets"
ASSETS = (CORPUS / "kenney_blocky_character" / "character.glb", CORPUS / "kenney_cube_pets_obj" / "animal-fox.obj")

SETUP = r"""
import json, math, socket, sys, time, threading
from importlib import import_module
from pathlib import Path
from types import SimpleNamespace
import numpy as np
import bpy, addon_utils

tmp = Path(TMP)
bpy.ops.wm.read_factory_settings(use_empty=True)
addon_utils.enable("scenefit", default_set=True)
MODULE = "scenefit"
jobs, background = import_module(MODULE + ".operators.jobs"), import_module(MODULE + ".workers.background")
history = import_module(MODULE + ".operators.history")
prefs = bpy.context.preferences.addons[MODULE].preferences
bpy.context.preferences.system.use_online_access = True
# Online access on, the default hub ids and an empty model cache: a click must not look for them.
prefs.base_model, prefs.inpaint_model = "stabilityai/stable-diffusion-2-base", "stabilityai/stable-diffusion-2-inpainting"
prefs.model_cache, prefs.offline = str(tmp / "empty_cache"), False
(tmp / "empty_cache").mkdir(exist_ok=True)
import_module(MODULE + ".core.data.imageio").write_image(
    tmp / "photo.png", np.random.default_rng(1).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32))
roots = []
for path in ASSETS:
    before = set(bpy.data.objects)
    bpy.ops.scenefit.import_asset(filepath=path)
    made = [o for o in bpy.data.objects if o not in before]
    meshes = sorted((o for o in made if o.type == "MESH"), key=lambda o: -len(o.data.vertices))
    roots.append(meshes[0].name)
settings = bpy.context.scene.scenefit
settings.photo_path, settings.preset = str(tmp / "photo.png"), "draft"
bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "scene.blend"))

def select(name):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj = bpy.data.objects[name]
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj

class FakeWM:   # the window manager's calls a job operator makes; the runtime is Blender's own
    def __init__(self): self.timers, self.handlers, self.dialogs = [], [], []
    scenefit_runtime = property(lambda self: bpy.context.window_manager.scenefit_runtime)
    windows = ()
    def event_timer_add(self, seconds, window=None): self.timers.append(seconds); return len(self.timers)
    def event_timer_remove(self, timer): self.timers.pop()
    def modal_handler_add(self, op): self.handlers.append(op)
    def invoke_confirm(self, op, event, **kw): self.dialogs.append(kw.get("message", "")); return {"RUNNING_MODAL"}
    def invoke_props_dialog(self, op, **kw): self.dialogs.append("options"); return {"RUNNING_MODAL"}
    def invoke_popup(self, op, **kw): self.dialogs.append(getattr(op, "_warning", "popup")); return {"RUNNING_MODAL"}

class Layout:   # what a dialog draws, recorded
    def __init__(self): self.buttons, self.icons, self.texts = [], [], []
    def column(self, **kw): return self
    def row(self, **kw): return self
    def grid_flow(self, **kw): return self
    def label(self, text="", **kw): self.texts.append(text)
    def template_icon(self, icon_value=0, scale=1.0): self.icons.append(icon_value)
    def operator(self, idname, text=""):
        button = SimpleNamespace(idname=idname, text=text)
        self.buttons.append(button)
        return button

class Ctx:      # bpy.context with a window: a status bar along the bottom, a 3D Viewport with its sidebar
    def __init__(self):
        bar = SimpleNamespace(type="STATUSBAR", x=0, y=0, width=1000, height=20, regions=())
        side = SimpleNamespace(type="UI", x=700, y=20, width=300, height=600)
        view = SimpleNamespace(type="VIEW_3D", x=0, y=20, width=1000, height=600, regions=(side,))
        self.window, self.window_manager = SimpleNamespace(screen=SimpleNamespace(areas=(bar, view))), FakeWM()
    def __getattr__(self, name): return getattr(bpy.context, name)

from scenefit.devtools.stand_in_window import probe   # the operator's own methods on a plain object

def event(kind, x=0, y=0):
    return SimpleNamespace(type=kind, value="PRESS", mouse_x=x, mouse_y=y)

real_has_ui = jobs.has_ui

def ui_invoke(op, ctx, ev):
    jobs.has_ui = lambda context: True   # the stand-in window counts as one
    try:
        return op.invoke(ctx, ev)
    finally:
        jobs.has_ui = real_has_ui
out["roots"] = roots
"""

INVOKE = r"""
ops = import_module(MODULE + ".operators")
# (torch.cuda.is_available, once torch is imported, is allowed: it loads nothing)
FORBIDDEN = ("torch.serialization", "torch.hub", "diffusers", "transformers", "huggingface_hub", "socket", "http.",
             "urllib.request", "requests", "safetensors", "OpenImageIO")
touched = []
def guard(frame, kind, arg):
    if kind == "call":
        name = frame.f_globals.get("__name__", "") or ""
    elif kind == "c_call":
        name = getattr(arg, "__module__", None) or type(getattr(arg, "__self__", None)).__module__ or ""
    else:
        return
    if name.startswith(FORBIDDEN):
        touched.append(name)
def no_connect(*args):
    raise RuntimeError("invoke touched the network")
socket.socket.connect = no_connect
had_torch = "torch" in sys.modules
seconds, dialogs, results = {}, {}, {}
from scenefit.operators import adapt, bake, convert, light, run
classes = {"run": (run.SCENEFIT_OT_run, {"choice": "ask", "guidance": "auto"}),
           "adapt": (adapt.SCENEFIT_OT_adapt, {"iterations": 0, "model_resolution": 0, "render_size": 0, "resume": "",
                                               "choice": "ask"}), "convert": (convert.SCENEFIT_OT_convert, {"iterations": 0}),
           "light": (light.SCENEFIT_OT_estimate_light, {})}
settings.preset = "balanced"   # (at Draft, Draft is not offered)
# The panel an artist clicks in has been drawn: its expected time (the Quality section, the cost beside Run
# All) has read the preset tables once, as every redraw does, before any click.
import_module(MODULE + ".panels.quality").expected_line("adapt", settings.preset)
for name in roots:
    select(name)
    settings.prompt = "a mossy figure"   # (each asset its own)
    for label, (cls, props) in classes.items():
        op, ctx = probe(cls, **props), Ctx()
        sys.setprofile(guard)
        t = time.perf_counter()
        try:
            results[f"{name}/{label}"] = sorted(ui_invoke(op, ctx, event("LEFTMOUSE")))
        finally:
            sys.setprofile(None)
        seconds[f"{name}/{label}"] = round(time.perf_counter() - t, 4)
        dialogs[f"{name}/{label}"] = ctx.window_manager.dialogs
        if label in ("run", "adapt"):   # the question's buttons
            op.layout = Layout()
            op.draw(bpy.context)
            dialogs[f"{name}/{label}/buttons"] = [(b.text, b.choice) for b in op.layout.buttons]
        bpy.context.window_manager.scenefit_runtime.running = False
# Run All's one bar: stage k of n from the stage running and its own fraction
JobState = background.JobState
stages = import_module(MODULE + ".core.pipeline.registry").RUN_ORDER   # what update_runtime gives it
out["whole_run"] = [jobs.whole_run(JobState("run", stage="adapt", step=3, total=4, fraction=0.75), stages),
                    jobs.whole_run(JobState("run", stage="run", step=1, total=5, fraction=0.2), stages),
                    jobs.whole_run(JobState("adapt", stage="adapt", step=3, total=4, fraction=0.75), stages)]
settings.preset = "draft"
out["invoke"] = {"seconds": seconds, "results": results, "dialogs": dialogs, "touched": sorted(set(touched)),
                 "torch_before": had_torch, "online": bpy.app.online_access}
"""

# A worker set to take jobs when asked: long work asks and offers Send to Worker, which hands the job to it;
# a worker that takes every job is used without asking.
WORKER = r"""
from scenefit.operators import run as run_ops
select(roots[1])
settings.preset, settings.prompt = "balanced", "a mossy fox"
prefs.worker_type, prefs.worker_python, prefs.worker_when = "INSTALL", sys.executable, "ASK"
seen = {}
try:
    op, ctx = probe(run_ops.SCENEFIT_OT_run, choice="ask", guidance="auto"), Ctx()
    seen["ask"] = [sorted(ui_invoke(op, ctx, event("LEFTMOUSE"))), len(ctx.window_manager.dialogs)]
    op.layout = Layout()
    op.draw(bpy.context)
    seen["buttons"] = [b.choice for b in op.layout.buttons]
    bpy.context.window_manager.scenefit_runtime.running = False
    sent = probe(run_ops.SCENEFIT_OT_run, choice="worker", guidance="auto")
    work, data = sent.job_work(bpy.context)
    here = probe(run_ops.SCENEFIT_OT_run, choice="start", guidance="auto")
    here_work, _ = here.job_work(bpy.context)
    seen["sent"] = [sent._remote, work.__module__, data.worker, here._remote, here_work.__module__]
    prefs.worker_when = "ALWAYS"
    op, ctx = probe(run_ops.SCENEFIT_OT_run, choice="ask", guidance="auto"), Ctx()
    ui_invoke(op, ctx, event("LEFTMOUSE"))
    seen["always"] = [len(ctx.window_manager.dialogs), op.long_work_warning(bpy.context)]
    bpy.context.window_manager.scenefit_runtime.running = False
    prefs.worker_type = "LOCAL"
    op.layout = Layout()
    op.draw(bpy.context)
    seen["no_worker_buttons"] = [b.choice for b in op.layout.buttons]
finally:
    prefs.worker_type, prefs.worker_when = "LOCAL", "ALWAYS"
    settings.preset = "draft"
    bpy.context.window_manager.scenefit_runtime.running = False
out["worker"] = seen
"""

MODAL = r"""
from scenefit.operators import adapt as adapt_ops
prefs.base_model, prefs.inpaint_model = str(tiny[0]), str(tiny[1])
prefs.offline = True
fox = select(roots[1])
settings.prompt = "a mossy fox"
out["convert"] = sorted(bpy.ops.scenefit.convert(iterations=3))
rt = bpy.context.window_manager.scenefit_runtime
ADAPT = {"iterations": 6, "model_resolution": 32, "render_size": 16, "resume": "", "choice": "ask"}

def started(props):
    op, ctx = probe(adapt_ops.SCENEFIT_OT_adapt, **props), Ctx()
    t = time.perf_counter()
    first = sorted(ui_invoke(op, ctx, event("LEFTMOUSE")))
    invoke_s = time.perf_counter() - t
    t = time.perf_counter()
    tick = sorted(op.modal(ctx, event("TIMER")))
    return op, ctx, first, invoke_s, tick, time.perf_counter() - t

op, ctx, first, invoke_s, tick, tick_s = started(ADAPT)
steps = []
while not (op._job.poll().stage == "adapt" and op._job.state.step >= 2) and not op._job.state.finished:
    op.modal(ctx, event("TIMER")); time.sleep(0.05)
steps.append(op._job.state.step)
elsewhere = sorted(op.modal(ctx, event("ESC", 300, 300)))       # over the viewport: the artist's Esc
still = not op._job.cancel_requested
t_cancel = time.perf_counter()
over_bar = sorted(op.modal(ctx, event("ESC", 500, 10)))          # over the status bar's progress
statuses = [rt.status]
result = None
while result is None or result == ["RUNNING_MODAL"]:
    time.sleep(0.05)
    result = sorted(op.modal(ctx, event("TIMER")))
    if result == ["RUNNING_MODAL"]:
        statuses.append(rt.status)
stopped_s = time.perf_counter() - t_cancel
runs = fox.scenefit_asset.runs
run = runs[len(runs) - 1]
folder = Path(bpy.path.abspath(run.folder))
partial = folder.parent / f".{folder.name}.partial"
checkpoint = partial / "adapt" / "checkpoint" / "adapt_checkpoint.pt"   # the pipeline's adapt stage folder
import torch
done = int(torch.load(checkpoint, map_location="cpu", weights_only=True)["iteration"]) if checkpoint.is_file() else -1
out["modal"] = {"first": first, "invoke_s": round(invoke_s, 4), "tick": tick, "tick_s": round(tick_s, 2),
                "esc_elsewhere": [elsewhere, still], "esc_over_bar": over_bar, "statuses": sorted(set(statuses)),
                "end": result, "stopped_s": round(stopped_s, 2), "steps_seen": steps,
                "run": [run.stage, run.state, len(runs)], "checkpoint_iteration": done,
                "folder_exists": folder.exists(), "partial_exists": partial.is_dir()}
# Resume (inline here: no window) continues the count from the checkpoint and finishes the same entry.
index = len(runs) - 1
out["resume"] = sorted(bpy.ops.scenefit.resume_run(index=index))
adapted = json.loads((folder / "report.json").read_text())["stages"]["adapt"]["report"]   # the run's report
out["resumed"] = {"resumed_from": adapted["resumed_from"], "iterations": adapted["iterations"],
                  "run": [runs[index].state, len(runs)],
                  "partial_left": partial.exists()}
"""

# Each answer to the question runs what it says: Skip adaptation runs Run All without adapting, Draft at the
# draft preset (the panel's stays).
CHOICES = r"""
from scenefit.operators import run as run_ops
fox = select(roots[1])
settings.prompt, settings.guidance = "a mossy fox", "auto"

def finished(props):
    op, ctx = probe(run_ops.SCENEFIT_OT_run, **props), Ctx()
    first = sorted(ui_invoke(op, ctx, event("LEFTMOUSE")))
    result = ["RUNNING_MODAL"]
    while result == ["RUNNING_MODAL"]:
        result = sorted(op.modal(ctx, event("TIMER")))
        time.sleep(0.05)
    report = json.loads((Path(op._out) / "report.json").read_text()) if result == ["FINISHED"] else {}
    return first, result, report, op.reported

settings.preset = "draft"
first, result, report, said = finished({"choice": "skip", "guidance": "auto"})
out["skip"] = [first, result, report.get("stages", {}).get("adapt", {}).get("status"),
               report.get("stages", {}).get("adapt", {}).get("why"), said[-1:]]
settings.preset, settings.guidance = "final", "none"
first, result, report, said = finished({"choice": "draft"})
out["draft"] = [first, result, report.get("config", {}).get("preset"), settings.preset, said[-1:],
                fox.scenefit_asset.runs[len(fox.scenefit_asset.runs) - 1].preset]
settings.preset = "draft"
"""

# Ctrl+Z after a job takes its results out of the file (the job's one undo step), and after Apply puts the
# asset's slots and World back. Undo replaces Blender's data, so names are looked up again afterwards.
UNDO = r"""
def snapshot():
    obj = bpy.data.objects[roots[1]]
    scene = bpy.data.scenes[artist_scene]
    return {"slots": [s.material.name if s.material else None for s in obj.material_slots],
            "world": scene.world.name if scene.world else None, "scenes": sorted(s.name for s in bpy.data.scenes),
            "materials": sorted(m.name for m in bpy.data.materials), "worlds": sorted(w.name for w in bpy.data.worlds),
            "images": sorted(i.name for i in bpy.data.images), "runs": len(obj.scenefit_asset.runs)}

artist_scene = bpy.context.scene.name
select(roots[1])
settings.preset, settings.guidance = "draft", "auto"
bpy.ops.ed.undo_push(message="the artist's last action")
before = snapshot()
first, result, report, said = finished({"choice": "skip", "guidance": "auto"})
after_run = snapshot()
bpy.ops.ed.undo()
after_undo = snapshot()
settings = bpy.context.scene.scenefit
runs = bpy.data.objects[roots[1]].scenefit_asset.runs
bpy.ops.ed.undo_push(message="before apply")
before_apply = snapshot()
applied = sorted(bpy.ops.scenefit.apply_run("EXEC_DEFAULT", True, index=0))   # undo=True: as a click pushes
after_apply = snapshot()
bpy.ops.ed.undo()
settings = bpy.context.scene.scenefit
out["undo"] = {"run": [result, said[-1:]], "before": before, "after_run": after_run, "after_undo": after_undo,
               "apply": applied, "before_apply": before_apply, "after_apply": after_apply, "apply_undone": snapshot()}
"""

LOAD = r"""
settings.preset = "draft"
op, ctx, *_ = started(dict(ADAPT, iterations=50, choice="start"))
while op._job.poll().step < 1 and not op._job.state.finished:
    time.sleep(0.05)
job = op._job
t = time.perf_counter()
jobs._end_job_at_exit()                     # what quitting runs
waited = round(time.perf_counter() - t, 2)
asked = job.cancel_requested
job.wait(10)                                # (a quitting Blender ends here; the worker stops at its next check)
out["quit"] = [waited, asked, round(time.perf_counter() - t, 2), job.alive, job.poll().status]
background.release_job(job)
op, ctx, *_ = started(dict(ADAPT, iterations=50, choice="start"))
while op._job.poll().step < 1 and not op._job.state.finished:
    time.sleep(0.05)
job = op._job
t = time.perf_counter()
bpy.ops.wm.open_mainfile(filepath=str(tmp / "scene.blend"))   # another file (load_pre ends the job)
loaded, freed, asked = round(time.perf_counter() - t, 2), background.active_job() is None, job.cancel_requested
job.wait(10)
out["load"] = [loaded, freed, asked, round(time.perf_counter() - t, 2), job.alive, job.poll().status]
"""

ASSETS_STATE = r"""
bpy.ops.wm.open_mainfile(filepath=str(tmp / "scene.blend"))
settings = bpy.context.scene.scenefit
character, fox = roots
select(character); settings.prompt, settings.placement = "a bronze statue", (0.3, 0.7)
select(fox); fox_prompt = settings.prompt
settings.prompt = "a mossy fox"
select(character)
out["state"] = [fox_prompt, settings.prompt, list(map(lambda v: round(v, 3), settings.placement)),
                bpy.data.objects[fox].scenefit_asset.prompt]
select(fox)
out["fox_convert"] = sorted(bpy.ops.scenefit.convert(iterations=3))
fox_texture = settings.texture_path
select(character)
settings.texture_path = fox_texture      # another asset's texture, typed in
try:
    bpy.ops.scenefit.bake_asset(filepath=str(tmp / "wrong.glb"))
    out["refused"] = "baked"
except RuntimeError as error:
    out["refused"] = str(error).splitlines()[0]
select(fox)
runs = bpy.data.objects[fox].scenefit_asset.runs
out["runs"] = [(r.stage, r.state, r.preset, r.prompt, bool(r.when), len(r.slots)) for r in runs]
from scenefit.operators import history as history_ops
compare, ctx = probe(history_ops.SCENEFIT_OT_compare_run, index=0), Ctx()
shown = sorted(compare.invoke(ctx, event("LEFTMOUSE")))
compare.layout = Layout()
compare.draw(bpy.context)
first = runs[0]
out["compare"] = {"shown": shown, "drawn": compare.layout.icons, "texts": compare.layout.texts,
                  "expected": [first.composite.preview.icon_id if first.composite else None] + [
                      m.preview.icon_id for e in first.slots for m in (e.original, e.result)],
                  "names": [m.name for e in first.slots for m in (e.original, e.result)]}
out["apply"] = sorted(bpy.ops.scenefit.apply_run(index=0))
folder = Path(bpy.path.abspath(runs[0].folder))
material = runs[0].slots[0].result.name
out["delete"] = sorted(bpy.ops.scenefit.delete_run(index=0, folder=True))
out["deleted"] = [folder.exists(), material in bpy.data.materials, len(runs),
                  bpy.data.objects[fox].material_slots[0].material.name]
"""


# Nothing heavy on the main thread: the maps the job decodes are the ones Blender's own read gives, bit for bit;
# no tick of Convert decodes an image file (the worker does); a procedural chain bakes one per tick with its
# own words on the bar, and Esc between bakes ends it before the worker starts.
MAIN_THREAD = r"""
from scenefit.operators import convert as convert_ops
from scenefit.operators.asset import asset_layout
from scenefit.core.data import map_plan
DECODERS = {"read_image", "read_texture_bytes", "check_decodes", "_read_reduced"}
main = threading.main_thread()
decoded = {"main": [], "worker": []}
def decode_guard(frame, kind, arg):
    if kind == "call" and frame.f_code.co_name in DECODERS and frame.f_globals.get("__name__", "").endswith(
            "core.data.imageio"):
        decoded["main" if threading.current_thread() is main else "worker"].append(frame.f_code.co_name)
def leaves(value):
    if isinstance(value, map_plan.Deferred):
        return [leaf for a in value.args for leaf in leaves(a)]
    return [type(value).__name__] if isinstance(value, map_plan.Source) else []
same, kinds = {}, {}
for name in roots:
    select(name)
    layout = asset_layout(bpy.context)
    job, here = layout.plan(bpy.context), layout.plan(bpy.context, files_in_job=False)
    kinds[name] = sorted({leaf for m in job.materials for leaf in leaves(m.maps)})
    new, old = job.resolved(), here.resolved()
    same[name] = [[m.read == o.read and m.kept == o.kept and m.dropped == o.dropped] + [
        (np.array_equal(a, b) and a.dtype == b.dtype) if isinstance(a, np.ndarray) else a == b
        for a, b in ((getattr(m.maps, k), getattr(o.maps, k)) for k in ("base_color", "roughness", "metallic", "normal"))]
        for m, o in zip(new.materials, old.materials)]

def ticks(op, ctx, until_job=True):
    # each tick's seconds and bar until the worker starts (or the operator ends)
    seen = []
    while getattr(op, "_job", None) is None:
        t = time.perf_counter()
        result = sorted(op.modal(ctx, event("TIMER")))
        seen.append([round(time.perf_counter() - t, 4), rt.status, result])
        if result != ["RUNNING_MODAL"]:
            break
    return seen

def stop(op):
    if getattr(op, "_job", None) is not None:
        op._job.cancel(); op._job.wait(60); background.release_job(op._job)

rt = bpy.context.window_manager.scenefit_runtime
select(roots[0])
op, ctx = probe(convert_ops.SCENEFIT_OT_convert, iterations=3), Ctx()
sys.setprofile(decode_guard); threading.setprofile(decode_guard)
try:
    ui_invoke(op, ctx, event("LEFTMOUSE"))
    convert_ticks = ticks(op, ctx)
    sys.setprofile(None)
    op._job.wait(120)
finally:
    sys.setprofile(None); threading.setprofile(None)
convert_status = op._job.state.status
background.release_job(op._job)

# An artist's procedural material (two noise chains) on a plane of their own: two bakes, one per tick.
bpy.ops.mesh.primitive_plane_add(size=1.0, location=(5.0, 0.0, 0.0))
plane = bpy.context.active_object
material = bpy.data.materials.new("Artist Noise")
material.use_nodes = True
nodes, links = material.node_tree.nodes, material.node_tree.links
bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
for socket in ("Base Color", "Roughness"):
    links.new(nodes.new("ShaderNodeTexNoise").outputs["Color" if socket == "Base Color" else "Fac"], bsdf.inputs[socket])
plane.data.materials.append(material)
select(plane.name)
op, ctx = probe(convert_ops.SCENEFIT_OT_convert, iterations=3), Ctx()
ui_invoke(op, ctx, event("LEFTMOUSE"))
first = sorted(op.modal(ctx, event("TIMER")))
before_esc = [rt.status, getattr(op, "_job", None) is None, bpy.ops.scenefit.cancel_job.poll()]
esc = sorted(op.modal(ctx, event("ESC", 500, 10)))
cancelled = ticks(op, ctx)
cancelled_state = [rt.running, rt.status, getattr(op, "_job", None) is None]
op, ctx = probe(convert_ops.SCENEFIT_OT_convert, iterations=3), Ctx()
ui_invoke(op, ctx, event("LEFTMOUSE"))
baked = ticks(op, ctx)
stop(op)
for datablock, where in ((plane, bpy.data.objects), (plane.data, bpy.data.meshes), (material, bpy.data.materials)):
    where.remove(datablock)
out["main_thread"] = {"same": same, "kinds": kinds, "convert_ticks": convert_ticks, "convert_status": convert_status,
                      "decoded": {k: sorted(set(v)) for k, v in decoded.items()}, "first": first,
                      "before_esc": before_esc, "esc": esc, "cancelled": cancelled, "cancelled_state": cancelled_state,
                      "baked": baked}
"""


def artist_session(tmp_path_factory, name: str, extra: str = ""):
    """A bpy session with SETUP's file open (and `extra` run after it), for the module's steps."""
    missing = [p for p in ASSETS if not p.is_file()]
    if missing:
        pytest.skip(f"the corpus asset {missing[0]} is not here")
    from conftest import shared_tiny_pair

    tmp = tmp_path_factory.mktemp(name)
    tiny = shared_tiny_pair()
    python = PythonSession()
    try:
        setup = python.run(SETUP.replace("TMP", repr(str(tmp))).replace("ASSETS", repr([str(p) for p in ASSETS]))
                           + f"\ntiny = {[str(p) for p in tiny]!r}\n" + extra)
        yield SimpleNamespace(run=python.run, tmp=tmp, setup=setup)
    finally:
        python.close()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    yield from artist_session(tmp_path_factory, "trust_jobs")


def _step(session, code: str, name: str) -> dict:
    out = session.run(code)
    (session.tmp / f"{name}.json").write_text(json.dumps(out, default=str))
    return out


def test_a_click_returns_at_once_without_network_or_models(session):
    step = _step(session, INVOKE, "invoke")
    adapt, between, alone = step["whole_run"]
    # one bar for the whole run: convert, camera, light, adapt, compose, bake
    assert adapt == [pytest.approx((3 + 0.75) / 6), "stage 4 of 6 (adapt)"]
    assert between == [pytest.approx(1 / 6), "stage 2 of 6 (camera)"] and alone is None
    out = step["invoke"]
    assert out["touched"] == [], out["touched"]          # no torch, hub, socket or image file at the click
    assert all(r == ["RUNNING_MODAL"] for r in out["results"].values()), out["results"]
    assert max(out["seconds"].values()) < 0.2, out["seconds"]
    # The draft preset's 300 CPU iterations (hours) ask first; Estimate Light shows its options.
    for name in session.setup["roots"]:
        assert "hours" not in out["dialogs"][f"{name}/convert"] and out["dialogs"][f"{name}/light"] == ["options"]
        assert any("would run" in d for d in out["dialogs"][f"{name}/adapt"])
        assert out["dialogs"][f"{name}/run/buttons"] == [["Draft", "draft"], ["Skip adaptation", "skip"],
                                                         ["Start anyway", "start"]]
        assert out["dialogs"][f"{name}/adapt/buttons"] == [["Draft", "draft"], ["Start anyway", "start"]]


def test_the_question_sends_long_work_to_a_worker_set_to_take_it_when_asked(session):
    out = _step(session, WORKER, "worker")["worker"]
    assert out["ask"] == [["RUNNING_MODAL"], 1] and "worker" in out["buttons"] and "start" in out["buttons"]
    sent_remote, sent_module, address, here_remote, here_module = out["sent"]
    assert sent_remote and sent_module.endswith("workers.remote") and address
    assert not here_remote and not here_module.endswith("workers.remote")
    assert out["always"] == [0, None]   # every job goes there: nothing to ask
    assert "worker" not in out["no_worker_buttons"] and "draft" in out["no_worker_buttons"]


def test_esc_cancels_only_over_the_progress_and_resume_continues_the_count(session):
    out = _step(session, MODAL, "modal")
    modal = out["modal"]
    assert out["convert"] == ["FINISHED"]
    assert modal["first"] == ["RUNNING_MODAL"] and modal["invoke_s"] < 0.2 and modal["tick"] == ["RUNNING_MODAL"]
    assert modal["esc_elsewhere"] == [["PASS_THROUGH"], True]
    assert modal["esc_over_bar"] == ["RUNNING_MODAL"] and modal["statuses"] == ["adapt: cancelling…"]
    assert modal["end"] == ["CANCELLED"] and modal["stopped_s"] < 5.0
    assert modal["run"][:2] == ["adapt", "cancelled"]
    assert modal["partial_exists"] and not modal["folder_exists"] and modal["checkpoint_iteration"] >= 2
    assert out["resume"] == ["FINISHED"]
    resumed = out["resumed"]
    assert resumed["resumed_from"] == modal["checkpoint_iteration"] and resumed["iterations"] == 6
    assert resumed["run"] == ["finished", modal["run"][2]] and not resumed["partial_left"]


def test_each_answer_to_the_cost_question_runs_what_it_says(session):
    out = _step(session, CHOICES, "choices")
    first, result, adapt_status, why, said = out["skip"]
    assert first == ["RUNNING_MODAL"] and result == ["FINISHED"], said
    assert adapt_status == "skipped" and "Skip adaptation" in why
    first, result, preset, panel_preset, said, recorded = out["draft"]
    assert result == ["FINISHED"], said
    assert preset == "draft" and panel_preset == "final" and recorded == "draft"


def test_undo_takes_a_job_or_an_apply_out_of_the_file(session):
    out = _step(session, UNDO, "undo")["undo"]
    assert out["run"][0] == ["FINISHED"], out["run"]
    before, after = out["before"], out["after_run"]
    # The run added a World, a composite scene and image, and a history entry; Ctrl+Z takes all of it out.
    assert after["runs"] == before["runs"] + 1 and after["images"] != before["images"], after
    assert out["after_undo"] == before
    assert out["apply"] == ["FINISHED"] and out["after_apply"] != out["before_apply"]
    assert out["apply_undone"] == out["before_apply"]


def test_quitting_or_loading_a_file_stops_a_job_within_two_seconds(session):
    out = _step(session, LOAD, "load")
    # Blender waits at most 2 s for the worker, which was told to stop and ends at its next check (between
    # the halves of a view: seconds on a loaded CPU), cancelled, its checkpoint kept.
    waited, asked, ended, alive, status = out["quit"]
    assert waited < 2.5 and asked and not alive and status == "cancelled" and ended < waited + 5.0
    loaded, freed, asked, ended, alive, status = out["load"]
    assert loaded < 2.0 + 3.0 and freed and asked   # the wait for the worker, and the file's own loading
    assert not alive and status == "cancelled" and ended < loaded + 5.0


def test_each_asset_keeps_its_own_state_and_runs(session):
    out = _step(session, ASSETS_STATE, "assets")
    fox_prompt, character_prompt, placement, fox_now = out["state"]
    assert character_prompt == "a bronze statue" and placement == [0.3, 0.7] and fox_now == "a mossy fox"
    assert "made for another mesh" in out["refused"], out["refused"]
    assert out["fox_convert"] == ["FINISHED"]
    stage, state, preset, prompt, when, slots = out["runs"][-1]
    assert (stage, state, preset, prompt, when) == ("convert", "finished", "draft", "a mossy fox", True) and slots >= 1
    # Compare shows the run's materials before and after, side by side, as Blender previews them.
    compare = out["compare"]
    expected = [icon for icon in compare["expected"] if icon is not None]
    assert compare["shown"] == ["RUNNING_MODAL"] and compare["drawn"] == expected and len(expected) >= 2
    assert all(name in compare["texts"] for name in compare["names"]) and len(set(compare["names"])) == 2
    assert out["apply"] == ["FINISHED"] and out["delete"] == ["FINISHED"]
    folder_left, material_left, runs_left, slot_material = out["deleted"]
    assert not folder_left and not material_left and runs_left == len(out["runs"]) - 1
    assert "SceneFit" not in slot_material


def test_maps_are_decoded_in_the_job_and_bakes_run_one_per_tick(session):
    out = _step(session, MAIN_THREAD, "main_thread")["main_thread"]
    # The job's maps are Blender's own read, bit for bit (8-bit PNG/JPEG: the stored bytes x 1/255), and the
    # job really decodes files (a packed .glb image, an .obj's PNG), not Blender's copies.
    for name, materials in out["same"].items():
        assert materials and all(all(flags) for flags in materials), (name, materials)
        assert "TextureFile" in out["kinds"][name], out["kinds"]
    # No tick of Convert decodes an image file; its worker does.
    assert out["decoded"]["main"] == [] and "read_texture_bytes" in out["decoded"]["worker"], out["decoded"]
    assert out["convert_status"] == "done" and len(out["convert_ticks"]) == 1, out["convert_ticks"]
    # Two procedural chains: one bake per tick, each said on the bar before the worker starts.
    assert out["first"] == ["RUNNING_MODAL"]
    status, no_job, can_cancel = out["before_esc"]
    assert "baking material 1 of 2" in status and "Artist Noise" in status and no_job and can_cancel
    assert out["esc"] == ["RUNNING_MODAL"]
    assert out["cancelled"][-1][2] == ["CANCELLED"] and out["cancelled_state"] == [False, "Convert: cancelled", True]
    bars = [status for _, status, _ in out["baked"]]
    assert "baking material 1 of 2" in bars[0] and "baking material 2 of 2" in bars[1], bars
    assert out["baked"][-1][2] == ["RUNNING_MODAL"] and len(out["baked"]) == 3, out["baked"]
