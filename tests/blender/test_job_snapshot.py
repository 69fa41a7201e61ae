"""A job belongs to its asset, from the click to the result (corpus assets, tiny models, one bpy session):
a Run All whose asset was switched away from, edited and renamed while it ran is recorded with its click-time
settings on its own asset; a cancelled Run All keeps every finished stage and its checkpoint, and Resume
continues it to the end with the step count going on; Delete takes the hidden unfinished part too; a
duplicate starts with an empty history and its Delete leaves the original's folder."""
import importlib.util
from pathlib import Path

import pytest

# The artist's file of the jobs tests (two corpus assets, a photo, SceneFit enabled) and its stand-in window.
_SPEC = importlib.util.spec_from_file_location("trust_jobs", Path(__file__).with_name("test_jobs_an_artist_can_trust.py"))
_TRUST = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_TRUST)

pytestmark = pytest.mark.blender

HELPERS = r"""
from scenefit.operators import run as run_ops
rt = bpy.context.window_manager.scenefit_runtime
prefs.base_model, prefs.inpaint_model, prefs.offline = str(tiny[0]), str(tiny[1]), True
QUICK = {"iterations": 6, "model_resolution": 32, "render_size": 16}

def clicked(props):
    op, ctx = probe(run_ops.SCENEFIT_OT_run, **props), Ctx()
    first = sorted(ui_invoke(op, ctx, event("LEFTMOUSE")))
    while getattr(op, "_job", None) is None:   # the first ticks gather the request and start the worker
        if sorted(op.modal(ctx, event("TIMER"))) != ["RUNNING_MODAL"]:
            break
    return op, ctx, first

def to_the_end(op, ctx):
    result = ["RUNNING_MODAL"]
    while result == ["RUNNING_MODAL"]:
        time.sleep(0.05)
        result = sorted(op.modal(ctx, event("TIMER")))
    return result

def partial_of(folder):
    return folder.parent / f".{folder.name}.partial"
"""

# Clicked on the fox with its own prompt and placement; while it runs the artist selects the character, edits
# the prompt and placement there, renames the fox and changes the panel's preset.
SNAPSHOT = r"""
fox, character = (bpy.data.objects[n] for n in (roots[1], roots[0]))
select(fox.name)
settings.preset, settings.prompt, settings.placement, settings.size = "draft", "a mossy fox", (0.4, 0.75), 0.3
op, ctx, first = clicked({"choice": "skip", "guidance": "auto", **QUICK})
select(character.name)
settings.prompt, settings.placement, settings.size = "a bronze statue", (0.8, 0.2), 0.6
fox.name = "Fox Renamed"
settings.preset = "final"
end = to_the_end(op, ctx)
settings.preset = "draft"
runs = fox.scenefit_asset.runs
run = runs[len(runs) - 1]
folder = Path(bpy.path.abspath(run.folder))
request = json.loads((folder / "request.json").read_text())
composite_scene = next((s for s in bpy.data.scenes if s.get("scenefit") == "composite"), None)
out["snapshot"] = {"first": first, "end": end, "said": op.reported[-1:], "run": [run.stage, run.state, run.prompt, run.preset],
                   "character_runs": [r.folder for r in character.scenefit_asset.runs],
                   "fox_slots": [s.material.name if s.material else None for s in fox.material_slots],
                   "character_slots": [s.material.name if s.material else None for s in character.material_slots],
                   "request": [request["asset_name"], request["placement"], request["run"]["object_size"],
                               request["run"]["prompt"], request["run"]["preset"]],
                   "composite_objects": sorted(o.name for o in composite_scene.objects) if composite_scene else None,
                   "folder": folder.is_dir()}
"""

# Run All with adaptation (tiny models): cancelled during the adaptation, every finished stage and the
# checkpoint are kept; Resume from the history finishes it with the count going on.
RESUME = r"""
import torch
fox = select("Fox Renamed")
settings.prompt = "a mossy fox"
op, ctx, first = clicked({"choice": "start", "guidance": "sd2", **QUICK})
while not (op._job.poll().stage == "adapt" and op._job.state.step >= 2) and not op._job.state.finished:
    op.modal(ctx, event("TIMER")); time.sleep(0.05)
t = time.perf_counter()
op._job.cancel()
end = to_the_end(op, ctx)
stopped_s = time.perf_counter() - t
runs = fox.scenefit_asset.runs
index = len(runs) - 1
folder = Path(bpy.path.abspath(runs[index].folder))
partial = partial_of(folder)
checkpoint = partial / "adapt" / "checkpoint" / "adapt_checkpoint.pt"
done = int(torch.load(checkpoint, map_location="cpu", weights_only=True)["iteration"]) if checkpoint.is_file() else -1
kept = sorted(p.parent.name for p in partial.glob("*/stage.json"))
out["cancelled"] = {"end": end, "stopped_s": round(stopped_s, 2), "run": [runs[index].stage, runs[index].state],
                    "kept": kept, "checkpoint_iteration": done, "folder": folder.exists(), "partial": partial.is_dir()}
settings.prompt = "something else entirely"   # Resume goes on with the run's own settings
out["resume"] = sorted(bpy.ops.scenefit.resume_run(index=index))
report = json.loads((folder / "report.json").read_text())
stages = report["stages"]
out["resumed"] = {"statuses": {k: v["status"] for k, v in stages.items()},
                  "resumed_from": stages["adapt"]["report"].get("resumed_from"),
                  "iterations": stages["adapt"]["report"].get("iterations"),
                  "prompt": report["config"].get("prompt") if isinstance(report.get("config"), dict) else None,
                  "run": [runs[index].state, len(runs), runs[index].prompt], "partial_left": partial.exists(),
                  "slots": [s.material.name if s.material else None for s in fox.material_slots]}

# Delete takes an unfinished run's hidden part too.
op, ctx, first = clicked({"choice": "skip", "guidance": "auto", **QUICK})
while op._job.poll().step < 2 and not op._job.state.finished:
    time.sleep(0.05)
op._job.cancel()
to_the_end(op, ctx)
index = len(runs) - 1
folder = Path(bpy.path.abspath(runs[index].folder))
had = [runs[index].state, partial_of(folder).is_dir()]
deleted = sorted(bpy.ops.scenefit.delete_run(index=index, folder=True))
out["delete"] = {"had": had, "deleted": deleted, "left": [folder.exists(), partial_of(folder).exists()]}
"""

# Composing one asset, then another: each composite shows only its own asset (and SceneFit's camera and floor).
COMPOSE = r"""
shown = {}
for name in ("Fox Renamed", roots[0]):
    select(name)
    settings.placement = (0.5, 0.75)
    said = sorted(bpy.ops.scenefit.compose(render=False))
    scene = next(s for s in bpy.data.scenes if s.get("scenefit") == "composite")
    shown[name] = [said, sorted(o.name for o in scene.collection.objects if "scenefit" not in o)]
out["compose"] = shown
"""

# Three Estimate Lights, then a run's Delete: Purge leaves only what the scene or a kept run holds.
LEFTOVERS = r"""
def held():
    runs = [r for o in bpy.data.objects for r in getattr(o.scenefit_asset, "runs", ())]
    worlds = {s.world.name for s in bpy.data.scenes if s.world} | {r.world.name for r in runs if r.world}
    materials = {slot.material.name for o in bpy.data.objects for slot in o.material_slots if slot.material} | {
        e.result.name for r in runs for e in r.slots if e.result}
    return worlds, materials

def left(kind):
    return sorted(x.name for x in getattr(bpy.data, kind) if "scenefit" in x)

def purge():
    bpy.ops.outliner.orphans_purge(do_local_ids=True, do_linked_ids=True, do_recursive=True)

select("Fox Renamed")
before = len(left("worlds"))
said = [sorted(bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior")) for _ in range(3)]   # (quick)
made = len(left("worlds")) - before
purge()
worlds, materials = held()
after_lights = {"worlds": left("worlds"), "held": sorted(worlds), "fake": [w.name for w in bpy.data.worlds if w.use_fake_user and "scenefit" in w]}
runs = bpy.data.objects["Fox Renamed"].scenefit_asset.runs
deleted = sorted(bpy.ops.scenefit.delete_run(index=0))
purge()
worlds, materials = held()
out["leftovers"] = {"said": said, "made": made, "after_lights": after_lights,
                    "after_delete": [deleted, sorted(set(left("worlds")) - worlds), sorted(set(left("materials")) - materials)],
                    "env_images": sorted(i.name for i in bpy.data.images if "scenefit" in i and i.users == 0)}
"""

# An asset deleted while its run goes on: the run is kept (the scene's runs without an asset) with its folder.
DELETED = r"""
character = select(roots[0])
settings.placement = (0.5, 0.75)
op, ctx, first = clicked({"choice": "skip", "guidance": "auto", **QUICK})
bpy.data.objects.remove(character)
end = to_the_end(op, ctx)
kept = [(r.stage, r.state, Path(bpy.path.abspath(r.folder)).is_dir()) for r in settings.runs_without_asset]
out["deleted"] = {"end": end, "said": op.reported[-1:], "kept": kept}
"""

# Two clicks of Run All before the first one's first tick: the second is refused, not started beside it. A file
# loaded during a job leaves no job thread running.
SECOND = r"""
import threading
select("Fox Renamed")
first_op, first_ctx = probe(run_ops.SCENEFIT_OT_run, choice="skip", guidance="auto", **QUICK), Ctx()
second_op, second_ctx = probe(run_ops.SCENEFIT_OT_run, choice="skip", guidance="auto", **QUICK), Ctx()
answers = [sorted(ui_invoke(first_op, first_ctx, event("LEFTMOUSE"))), sorted(ui_invoke(second_op, second_ctx, event("LEFTMOUSE")))]
while getattr(first_op, "_job", None) is None:
    first_op.modal(first_ctx, event("TIMER"))
while first_op._job.poll().step < 1 and not first_op._job.state.finished:
    time.sleep(0.05)
third = sorted(ui_invoke(probe(run_ops.SCENEFIT_OT_run, choice="skip", guidance="auto", **QUICK), Ctx(), event("LEFTMOUSE")))
job = first_op._job
t = time.perf_counter()
bpy.ops.wm.open_mainfile(filepath=str(tmp / "scene.blend"))   # another file: load_pre ends the job first
out["second"] = {"answers": answers, "refused": second_op.reported[-1:], "third": third,
                 "load_s": round(time.perf_counter() - t, 2), "alive": job.alive,
                 "threads": [th.name for th in threading.enumerate() if th.name == "scenefit-run"],
                 "slot": background.active_job() is None}
settings = bpy.context.scene.scenefit
"""

# Shift+D: the copy starts with an empty history; its Delete cannot reach the original's folder.
DUPLICATE = r"""
fox = bpy.data.objects["Fox Renamed"]
select(fox.name)
original_runs = [Path(bpy.path.abspath(r.folder)) for r in fox.scenefit_asset.runs]
bpy.ops.object.duplicate()
copy = bpy.context.active_object
copied = len(copy.scenefit_asset.runs)
bpy.context.view_layer.update()
try:
    said = sorted(bpy.ops.scenefit.delete_run(index=0, folder=True))
except RuntimeError as error:
    said = str(error).splitlines()[0]
out["duplicate"] = {"copy": copy.name, "copied": copied, "after": len(copy.scenefit_asset.runs), "said": said,
                    "ids": [fox.get("scenefit_id") == copy.get("scenefit_id")],
                    "original": [len(fox.scenefit_asset.runs), all(f.is_dir() for f in original_runs)]}
"""


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    yield from _TRUST.artist_session(tmp_path_factory, "job_snapshot", HELPERS)


_step = _TRUST._step


def test_a_job_keeps_its_click_time_settings_on_its_own_asset(session):
    out = _step(session, SNAPSHOT, "snapshot")["snapshot"]
    assert out["first"] == ["RUNNING_MODAL"] and out["end"] == ["FINISHED"], out["said"]
    # recorded on the fox (renamed meanwhile) with the prompt and preset of the click, none on the character
    assert out["run"] == ["run", "finished", "a mossy fox", "draft"] and out["character_runs"] == []
    assert all(name and "SceneFit" in name for name in out["fox_slots"]), out["fox_slots"]
    assert not any(name and "SceneFit" in name for name in out["character_slots"]), out["character_slots"]
    name, placement, size, prompt, preset = out["request"]
    assert placement == pytest.approx([0.4, 0.75]) and size == pytest.approx(0.3)
    assert prompt == "a mossy fox" and preset == "draft" and out["folder"]


def test_a_cancelled_run_all_keeps_its_stages_and_resumes_to_the_end(session):
    out = _step(session, RESUME, "resume")
    cancelled = out["cancelled"]
    assert cancelled["end"] == ["CANCELLED"] and cancelled["run"] == ["run", "cancelled"]
    assert not cancelled["folder"] and cancelled["partial"]
    assert {"convert", "camera", "light"} <= set(cancelled["kept"]) and cancelled["checkpoint_iteration"] >= 2
    assert out["resume"] == ["FINISHED"]
    resumed = out["resumed"]
    assert resumed["statuses"]["convert"] == "reused" and resumed["statuses"]["light"] == "reused"
    assert resumed["statuses"]["adapt"] == "ran" and resumed["resumed_from"] == cancelled["checkpoint_iteration"]
    assert resumed["iterations"] == 6 and resumed["run"][0] == "finished" and resumed["run"][2] == "a mossy fox"
    assert not resumed["partial_left"] and all("SceneFit" in (s or "") for s in resumed["slots"])
    state, had_partial = out["delete"]["had"]
    assert state == "cancelled" and had_partial and out["delete"]["deleted"] == ["FINISHED"]
    assert out["delete"]["left"] == [False, False]


def test_a_duplicate_starts_with_an_empty_history(session):
    out = _step(session, DUPLICATE, "duplicate")["duplicate"]
    assert out["copied"] >= 1   # Shift+D copies the list: the copy is told apart on its first use
    assert out["after"] == 0 and "no such run" in str(out["said"]) and out["ids"] == [False]
    runs, folders_kept = out["original"]
    assert runs >= 1 and folders_kept


def test_composing_one_asset_never_shows_another(session):
    out = _step(session, COMPOSE, "compose")["compose"]
    fox, character = out.values()
    assert fox == [["FINISHED"], ["Fox Renamed"]] and character[0] == ["FINISHED"]
    assert "Fox Renamed" not in character[1] and len(character[1]) == 1, character


def test_three_estimate_lights_and_a_delete_leave_nothing_purge_keeps(session):
    out = _step(session, LEFTOVERS, "leftovers")["leftovers"]
    assert out["said"] == [["FINISHED"]] * 3 and out["made"] == 3
    lights = out["after_lights"]
    assert set(lights["worlds"]) <= set(lights["held"]) and lights["fake"] == [], lights   # the two older: purged
    deleted, worlds_left, materials_left = out["after_delete"]
    assert deleted == ["FINISHED"] and worlds_left == [] and materials_left == []
    assert out["env_images"] == []


def test_an_asset_deleted_during_its_run_keeps_the_run_and_its_folder(session):
    out = _step(session, DELETED, "deleted")["deleted"]
    assert out["end"] == ["CANCELLED"] and "deleted while SceneFit ran" in out["said"][0]
    assert out["kept"] == [["run", "failed", True]]


def test_a_second_run_all_never_starts_beside_the_first_and_a_file_load_ends_it(session):
    out = _step(session, SECOND, "second")["second"]
    assert out["answers"] == [["RUNNING_MODAL"], ["CANCELLED"]] and "wait for it" in out["refused"][0]
    assert out["third"] == ["CANCELLED"]
    assert not out["alive"] and out["threads"] == [] and out["slot"]
