"""How long Blender's main thread is held by Convert and Run All on corpus assets, each in a fresh process
(cold: torch not yet imported): the click (invoke) and each timer tick until the job's worker has started, driven through the operators' own invoke / modal code
with a stand-in window (as tests/blender/test_jobs_an_artist_can_trust.py does). The worker is cancelled
as soon as it starts: only the main thread's stretches are measured.

Each asset runs in a fresh interpreter (bpy), whose `scenefit` is the package at --code (default this
checkout's parent on PYTHONPATH), so an earlier commit's code can be measured beside this one:

    git archive <commit> --prefix=scenefit/ | tar -x -C /tmp/before
    python benchmarks/bench_main_thread.py --code /tmp/before --label before
    python benchmarks/bench_main_thread.py --label after

Prints one JSON line per asset and operator: invoke seconds, each tick's seconds, the longest stretch.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from corpus import ROOT, load_average

CORPUS = Path(os.environ.get("SCENEFIT_CORPUS", ROOT.parent / "shared" / "corpus")) / "assets"
ASSETS = ("kenney_blocky_character/character.glb", "khronos_ToyCar/ToyCar.gltf",
          "khronos_MaterialsVariantsShoe/MaterialsVariantsShoe.gltf",
          "polyhaven_painted_wooden_cabinet/painted_wooden_cabinet_1k.gltf", "khronos_SheenChair/SheenChair.gltf",
          "khronos_VertexColorTest/VertexColorTest.glb")

DRIVE = r"""
import json, sys, time
from pathlib import Path
from types import SimpleNamespace
import numpy as np
import bpy, addon_utils

asset, tmp, operator = sys.argv[-3:]
addon_utils.enable("scenefit", default_set=True)
from scenefit.operators import convert, jobs, run
from scenefit.workers import background
from scenefit.core.data.imageio import write_image
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.scenefit.import_asset(filepath=asset)
meshes = [o for o in bpy.context.view_layer.objects if o.type == "MESH" and o.visible_get()]
for o in bpy.context.view_layer.objects:
    o.select_set(o in meshes)
bpy.context.view_layer.objects.active = max(meshes, key=lambda o: len(o.data.vertices))
settings = bpy.context.scene.scenefit
write_image(Path(tmp) / "photo.png", np.full((48, 64, 3), 0.5, np.float32))
settings.photo_path, settings.preset, settings.prompt = str(Path(tmp) / "photo.png"), "draft", ""
settings.output_dir = str(Path(tmp) / "out")

# (its own stand-in window, not scenefit.devtools': --code may name a commit from before that module)
class WM:
    scenefit_runtime = property(lambda self: bpy.context.window_manager.scenefit_runtime)
    windows = ()
    def event_timer_add(self, seconds, window=None): return 1
    def event_timer_remove(self, timer): pass
    def modal_handler_add(self, op): pass

class Ctx:
    def __init__(self):
        self.window, self.window_manager = SimpleNamespace(screen=SimpleNamespace(areas=())), WM()
    def __getattr__(self, name): return getattr(bpy.context, name)

def probe(cls, **props):
    attrs = {}
    for klass in reversed(cls.__mro__):
        if klass.__module__.startswith("scenefit"):
            attrs.update({k: v for k, v in vars(klass).items() if not k.startswith("__") and k != "bl_rna"})
    attrs.update(props, properties=SimpleNamespace(is_property_set=lambda name: name in props))
    op = type("Probe", (), attrs)()
    op.report = lambda kind, text: None
    return op

timer = SimpleNamespace(type="TIMER", value="PRESS", mouse_x=0, mouse_y=0)
click = SimpleNamespace(type="LEFTMOUSE", value="PRESS", mouse_x=0, mouse_y=0)
jobs.has_ui = lambda context: True
OPERATORS = {"convert": (convert.SCENEFIT_OT_convert, {"iterations": 1}),
             "run": (run.SCENEFIT_OT_run, {"choice": "skip", "guidance": "none"})}
for name in (operator,):   # one per process: each measured cold (torch not yet imported)
    cls, props = OPERATORS[name]
    op, ctx = probe(cls, **props), Ctx()
    torch_before = "torch" in sys.modules
    t = time.perf_counter()
    op.invoke(ctx, click)
    invoke = time.perf_counter() - t
    ticks, ended = [], None
    while getattr(op, "_job", None) is None and len(ticks) < 200:
        t = time.perf_counter()
        ended = sorted(op.modal(ctx, timer))
        ticks.append(round(time.perf_counter() - t, 4))
        if ended != ["RUNNING_MODAL"]:
            break
    job = getattr(op, "_job", None)
    if job is not None:
        job.cancel(); job.wait(120); background.release_job(job)
    print("RESULT " + json.dumps({"operator": name, "torch_before": torch_before, "invoke_s": round(invoke, 4), "ticks_s": ticks,
                                  "longest_s": round(max([invoke] + ticks), 4), "started": job is not None,
                                  "said": bpy.context.window_manager.scenefit_runtime.status[:120]}))
"""


def measure(asset: Path, code: Path | None) -> list[dict]:
    import tempfile

    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code)
    rows = []
    for operator in ("convert", "run"):   # each in a fresh process: cold, as an artist's first click is
        with tempfile.TemporaryDirectory(prefix="scenefit-main-thread-") as tmp:
            done = subprocess.run([sys.executable, "-c", DRIVE, str(asset), tmp, operator], env=env,
                                  capture_output=True, text=True, timeout=900)
        found = [json.loads(line[len("RESULT "):]) for line in done.stdout.splitlines() if line.startswith("RESULT ")]
        if not found:
            raise SystemExit(f"{asset.name}: no result\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
        rows += found
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--code", type=Path, help="a folder holding the `scenefit` package to measure")
    parser.add_argument("--label", default="this checkout")
    parser.add_argument("--only", nargs="*", help="asset paths under the corpus (default: ASSETS)")
    args = parser.parse_args()
    for relative in args.only or ASSETS:
        asset = CORPUS / relative
        if not asset.is_file():
            print(json.dumps({"asset": relative, "missing": True}))
            continue
        for row in measure(asset, args.code):
            print(json.dumps({"label": args.label, "asset": relative, "load": load_average(), **row}), flush=True)


if __name__ == "__main__":
    main()
