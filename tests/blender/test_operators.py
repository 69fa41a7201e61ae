"""The operators in bpy with the extension installed from its zip, on scenes made here.

One Blender session is kept open for the module (each bpy start costs seconds; see
conftest.PythonSession) and every test runs its own step in it, so a step that fails fails its own
tests and the others still run: every operator through EXEC_DEFAULT, Bake Asset on the result, save
-> reopen with every SceneFit image present and the artist's material, World and objects unchanged,
the background-job path through its job object (progress, preview, cancel, error, no bpy access from
the worker thread, the file-load handler ending a job), Run All in an unsaved file with its images
packed, and a zip without its wheels (last: it disables the add-on).
"""
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT, PythonSession, extension_and_models, fill_in, printed_json

from scenefit.core.data.imageio import read_image

pytestmark = pytest.mark.blender


# Installs the zip and defines what the steps share: the add-on's modules, make_scene, snapshot, timed.
INSTALL = r"""
import json, math, sys, threading, time
from importlib import import_module
from pathlib import Path
import numpy as np
import bpy, addon_utils

tmp, zip_path, tiny = Path(TMP), ZIP, TINY
MODULE = "bl_ext.user_default.scenefit"
bpy.ops.extensions.package_install_files(repo="user_default", filepath=zip_path, enable_on_install=True)
sf = sys.modules[MODULE]
out["module_file"] = sf.__file__
prefs = bpy.context.preferences.addons[MODULE].preferences
prefs.base_model, prefs.inpaint_model = str(Path(tiny) / "sd2-base"), str(Path(tiny) / "sd2-inpaint")
prefs.offline = True
jobs = import_module(MODULE + ".workers.background")
work = import_module(MODULE + ".workers.blender_jobs")
asset_ops = import_module(MODULE + ".operators.asset")
dependencies = import_module(MODULE + ".operators.dependencies")
results = import_module(MODULE + ".operators.results")
imageio = import_module(MODULE + ".core.data.imageio")

class Layout:   # what a panel draws, recorded: panels cannot draw without a window
    def __init__(self): self.drawn = []
    def column(self, **kw): return self
    def row(self, **kw): return self
    def prop(self, *args, **kw): pass
    def operator(self, idname, **kw):
        self.drawn.append(idname)
        return Shown(self.drawn)
    def label(self, text="", **kw): self.drawn.append(text)

class Shown:   # an operator button's properties; a warning's whole sentence (its tooltip) is recorded
    def __init__(self, drawn): object.__setattr__(self, "drawn", drawn)
    def __setattr__(self, name, value):
        if name == "details": self.drawn.append(value)

def panel_lines(panel):
    from types import SimpleNamespace
    layout = Layout()
    panel.draw(SimpleNamespace(layout=layout), bpy.context)
    return layout.drawn

def select_only(*objects):
    bpy.ops.object.select_all(action="DESELECT")
    for o in objects:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]

def convert_and_bake(obj, stem):
    # the object alone, saved as STEM.blend, converted and baked into STEM_bake/<object>.glb
    select_only(obj)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / f"{stem}.blend"))
    return (sorted(bpy.ops.scenefit.convert(iterations=5)),
            sorted(bpy.ops.scenefit.bake_asset(filepath=str(tmp / f"{stem}_bake" / f"{obj.name.lower()}.glb"))))

def painted_plane(name, material, seed):
    # a plane whose material's base colour is an 8x8 image of random colours
    bpy.ops.mesh.primitive_plane_add()
    plane = bpy.context.object
    plane.name = name
    image = bpy.data.images.new(name.lower(), 8, 8)
    image.pixels.foreach_set(np.random.default_rng(seed).uniform(0, 1, 8 * 8 * 4).astype(np.float32))
    mat = bpy.data.materials.new(material)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage"); tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    plane.data.materials.append(mat)
    return plane

def make_scene():
    bpy.ops.wm.read_homefile(use_empty=True)  # (factory settings would disable the extension)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    obj = bpy.context.active_object
    image = bpy.data.images.new("asset_color", 32, 32, alpha=True)
    pixels = np.ones((32, 32, 4), np.float32)
    pixels[..., :3] = np.random.default_rng(0).uniform(0.1, 0.9, (32, 32, 3))
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    mat = bpy.data.materials.new("AssetMaterial")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage"); tex.image = image
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    links.new(tex.outputs["Alpha"], nodes["Principled BSDF"].inputs["Alpha"])
    obj.data.materials.append(mat)
    world = bpy.data.worlds.new("User World")
    bpy.context.scene.world = world
    settings = bpy.context.scene.scenefit
    settings.preset, settings.photo_path, settings.prompt = "draft", str(tmp / "photo.png"), "a mossy ball"
    return obj, mat, image, world

def snapshot(obj_name="Sphere"):
    obj = bpy.data.objects[obj_name]
    mat, world = bpy.data.materials["AssetMaterial"], bpy.data.worlds["User World"]
    return {"pixels": float(np.sum(np.array(bpy.data.images["asset_color"].pixels[:]))),
            "material_nodes": sorted(n.bl_idname for n in mat.node_tree.nodes),
            "world_nodes": len(world.node_tree.nodes) if world.node_tree else 0,
            "location": list(obj.location), "vertices": len(obj.data.vertices),
            "user_objects": sorted(o.name for o in bpy.data.objects if "scenefit" not in o)}

timings = {}
class timed:  # seconds per operator, printed by the tests for the README
    def __init__(self, name): self.name = name
    def __enter__(self): self.t = time.perf_counter()
    def __exit__(self, *exc): timings[self.name] = round(time.perf_counter() - self.t, 2)

photo = np.random.default_rng(1).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
imageio.write_image(tmp / "photo.png", photo)
"""

# Every operator through EXEC_DEFAULT, in a saved file.
OPERATORS = r"""
obj, mat, image, world = make_scene()
bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "scene.blend"))
before = snapshot()
# Loading an asset file inside the open session leaves the open file as it was.
loader = import_module(MODULE + ".blender_io.asset_file")
bpy.data.libraries.write(str(tmp / "props.blend"), {obj})
counts = lambda: {k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "materials", "images", "scenes",
                                                          "libraries", "collections")}
ids_before = counts()
loaded, _ = loader.load_asset_file(tmp / "props.blend", "Sphere")
out["loader"] = [len(loaded.faces), counts() == ids_before, bpy.data.filepath == str(tmp / "scene.blend")]
out["panel_sections"] = sorted(c for c in dir(bpy.types) if c.startswith("SCENEFIT_PT_"))
found, dropped = import_module(MODULE + ".blender_io.material").material_summary(mat)
out["summary"] = [found, dropped]
ops = {}
ops["pick"] = bpy.ops.scenefit.pick_placement(x=0.5, y=0.8)
with timed("convert"):
    ops["convert"] = bpy.ops.scenefit.convert(iterations=30)
first_convert = bpy.context.scene.scenefit.result_material.name
bsdf = bpy.data.materials[first_convert].node_tree.nodes["Principled BSDF"]
out["convert_constants"] = {k: [bsdf.inputs[k].is_linked, round(bsdf.inputs[k].default_value, 3)]
                            for k in ("Roughness", "Metallic")}
ops["convert_again"] = bpy.ops.scenefit.convert(iterations=30)
with timed("light"):
    ops["light"] = bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior")
ops["light_again"] = bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior")   # reuses the first's stages
with timed("adapt"):
    ops["adapt"] = bpy.ops.scenefit.adapt(iterations=2, model_resolution=32, render_size=16)
# The warning before hours of local work: the draft preset's 300 iterations here, not the 2 just run.
adapt_op, job_ops = import_module(MODULE + ".operators.adapt"), import_module(MODULE + ".operators.jobs")
out["long_work"] = [job_ops.long_work_warning(bpy.context, "Adapt", adapt_op.adapt_seconds_here(bpy.context), True),
                    job_ops.long_work_warning(bpy.context, "Adapt", adapt_op.adapt_seconds_here(bpy.context, 2), True),
                    bpy.context.scene.scenefit.preset]
with timed("compose"):
    ops["compose"] = bpy.ops.scenefit.compose(samples=2)
with timed("export"):
    ops["export"] = bpy.ops.scenefit.export_mitsuba()
out["open_composite_options"] = sorted(bpy.ops.scenefit.open_composite.bl_options)
ops["revert_material"] = bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL")
out["after_revert"] = obj.active_material.name
ops["apply_material"] = bpy.ops.scenefit.use_result(target="MATERIAL", which="RESULT")
ops["revert_world"] = bpy.ops.scenefit.use_result(target="WORLD", which="ORIGINAL")
out["world_after_revert"] = bpy.context.scene.world.name
ops["apply_world"] = bpy.ops.scenefit.use_result(target="WORLD", which="RESULT")
out["ops"] = {k: sorted(v) for k, v in ops.items()}
s = bpy.context.scene.scenefit
out["placement"] = list(s.placement)
out["materials"] = [first_convert, s.result_material.name, obj.active_material.name]
out["world"] = bpy.context.scene.world.name
out["camera"] = [bpy.context.scene.camera.name if bpy.context.scene.camera else None,
                 bpy.data.scenes["SceneFit Composite"].camera.name]
out["shadow_catcher"] = bpy.data.objects["SceneFit Shadow Catcher"].is_shadow_catcher
out["paths"] = {"composite": s.composite_path, "texture": s.texture_path, "light": s.light_path}
out["run_folders"] = sorted(str(p.relative_to(tmp)) for p in (tmp / "scenefit").glob("*/*"))
out["images"] = sorted((i.name, i.filepath) for i in bpy.data.images if "scenefit" in i)
out["timings"] = dict(timings)
"""

# Bake Asset: the object with its (adapted) SceneFit material as glTF; nothing of the session changes.
BAKE = r"""
obj = bpy.data.objects["Sphere"]
def session():
    kinds = ("objects", "meshes", "materials", "images", "scenes", "collections", "node_groups")
    mat = obj.active_material
    return [{k: sorted(x.name for x in getattr(bpy.data, k)) for k in kinds}, mat.name,
            sorted((n.bl_idname, n.name) for n in mat.node_tree.nodes), len(mat.node_tree.links),
            [round(v, 4) for v in obj.matrix_world.col[3]], len(bpy.context.scene.objects)]
before_bake = session()
bake_folders = set((tmp / "scenefit").glob("*/bake-*"))
ops = {}
with timed("bake_asset"):
    ops["bake_glb"] = bpy.ops.scenefit.bake_asset()
ops["bake_gltf"] = bpy.ops.scenefit.bake_asset(filepath=str(tmp / "chosen" / "asset"), file_format="gltf",
                                               compress="draco", textures="jpeg")
out["ops"] = {k: sorted(v) for k, v in ops.items()}
out["bake_unchanged"] = [session() == before_bake, session(), before_bake]
try:
    bpy.ops.scenefit.bake_asset(texture_size=100)
except RuntimeError as error:
    out["bake_refused"] = str(error)
# The maps Bake Asset wrote, recomputed from the same texture and mesh (deterministic), for the re-import check.
gltf_export = import_module(MODULE + ".blender_io.gltf_export")
game_bake = import_module(MODULE + ".core.stages.bake.game_bake")
texture = import_module(MODULE + ".core.texture.bake").load_neural_texture(bpy.path.abspath(bpy.context.scene.scenefit.texture_path))
mesh_b, _ = import_module(MODULE + ".blender_io.material").object_mesh_and_slots(obj, bpy.context.evaluated_depsgraph_get())
# (each material at its own images' shape, from the artist's maps behind the result in the slot)
layout = import_module(MODULE + ".operators.asset").asset_layout(bpy.context)
own = [m.maps for m in layout.read(bpy.context).materials]
out["bake_shape"] = list(game_bake.own_texture_shape(own[0], import_module(MODULE + ".core.stages.bake.gltf_output").DEFAULT_MAX_TEXTURE))
# The file holds the artist's material (the slot holds SceneFit's preview of the texture) with the baked maps.
(artist,) = layout.artists
(expected,) = game_bake.bake_game_maps(texture, mesh_b, [artist.name], [tuple(out["bake_shape"])],
                                       [gltf_export.constant_channels(artist)], None, own)
np.savez(tmp / "expected_bake.npz", base_color=expected.base_color, roughness=np.asarray(expected.roughness),
         metallic=np.asarray(expected.metallic))
out["bake_material"] = [artist.name, obj.active_material.name]
out["bake_folders"] = sorted(str(p.relative_to(tmp)) for p in set((tmp / "scenefit").glob("*/bake-*")) - bake_folders)
out["bake_files"] = sorted(str(p) for p in tmp.rglob("*.gl*"))
out["timings"] = dict(timings)
"""

# Save -> reopen: every SceneFit image comes back, the artist's data is as it was.
REOPEN = r"""
out["images"] = sorted((i.name, i.filepath) for i in bpy.data.images if "scenefit" in i)
out["unchanged_before_save"] = snapshot() == before
bpy.ops.wm.save_mainfile()
bpy.ops.wm.open_mainfile(filepath=str(tmp / "scene.blend"))
out["reopened_images"] = sorted((i.name, list(i.size), i.has_data or bool(i.pixels[:4]))
                                for i in bpy.data.images if "scenefit" in i)
out["unchanged_after_reopen"] = snapshot() == before
out["snapshot"] = [snapshot(), before]
"""

# The job path without a window: progress, preview, cancel, error; no bpy in the worker.
JOBS = r"""
obj, mat, image, world = make_scene()
mesh, maps = asset_ops.asset_layout(bpy.context).read(bpy.context).fitting_view()
touched = []

def profile(frame, event, arg):  # every Python call and C call in threads started from here on
    if threading.current_thread() is threading.main_thread():
        return
    if event == "call":
        name = frame.f_globals.get("__name__", "")
    elif event == "c_call":
        owner = getattr(arg, "__self__", None)
        name = getattr(arg, "__module__", None) or type(owner).__module__
    else:
        return
    if (name or "").startswith(("bpy", "_bpy")) or type(getattr(arg, "__self__", None)).__name__.startswith("bpy_"):
        touched.append(f"{event} {name} {getattr(arg, '__name__', '')}")

t_job = time.perf_counter()
threading.setprofile(profile)
try:
    RunConfig = import_module(MODULE + ".core.pipeline.run_config").RunConfig
    quick = lambda n: RunConfig(preset="draft", stage_overrides={"convert": {"iterations": n}})
    data = {"mesh": mesh, "maps": maps, "config": quick(12), "out": str(tmp / "job_convert")}
    job = jobs.start_job(jobs.Job("convert", work.convert, data))
    seen = []
    while not job.poll().finished:
        seen.append((job.state.stage, job.state.step))
        time.sleep(0.02)
    state = job.state
    jobs.release_job(job)
    out["job"] = {"status": state.status, "stages": sorted({s for s, _ in seen if s}), "steps": max(s for _, s in seen),
                  "result_maps": {k: v if isinstance(v, float) else Path(v).name for k, v in state.result.maps.items()}}
    out["worker_touched_bpy"] = list(touched)
    timings["profiled_job"] = round(time.perf_counter() - t_job, 2)
    mat_from_job = results.apply_result_material(bpy.context, "Sphere", state.result, "convert")  # main thread
    # What the modal timer does with a state: runtime on the WindowManager, the preview as an icon.
    jobs_ui = import_module(MODULE + ".operators.jobs")
    jobs_ui.update_runtime(bpy.context, jobs.JobState("convert", stage="fit", step=3, total=6, fraction=0.5,
                                                      preview=np.zeros((8, 8, 3), np.uint8), preview_serial=1))
    rt = bpy.context.window_manager.scenefit_runtime
    # (no icon ids without a UI: check the preview's pixels instead)
    out["runtime"] = [rt.running, rt.progress, rt.status, rt.has_preview, list(jobs_ui._previews["live"].image_size)]
    out["job_material"] = mat_from_job.name

    # The hook would see it: a worker that does touch bpy is caught (so the check can fail).
    touched.clear()
    bad = jobs.start_job(jobs.Job("bad", lambda d, p, c: bpy.path.abspath("//x"), None))
    bad.wait(10)
    jobs.release_job(bad)
    out["control_caught"] = len(touched) > 0
finally:
    threading.setprofile(None)

data = dict(data, config=quick(100000), out=str(tmp / "job_cancel"))
job = jobs.start_job(jobs.Job("convert", work.convert, data))
while job.poll().step < 2:
    time.sleep(0.02)
job.cancel()
out["cancelled"] = job.wait(30).status
jobs.release_job(job)
out["cancel_left"] = sorted(p.name for p in tmp.iterdir() if "job_cancel" in p.name)  # written beside: nothing
job = jobs.start_job(jobs.Job("light", work.estimate_light, {"photo": str(tmp / "missing.png"), "placement": (0.5, 0.6),
                                                            "config": RunConfig(), "out": str(tmp / "light")}))
state = job.wait(30)
jobs.release_job(job)
out["error"] = [state.status, state.error]

# Loading a file ends a running job (load_pre handler) and frees the slot.
job = jobs.start_job(jobs.Job("convert", work.convert, data))
while job.poll().step < 1:
    time.sleep(0.02)
bpy.ops.wm.read_homefile(use_empty=True)
out["after_load"] = [job.poll().status, jobs.active_job() is None, job.alive]
timings["job_section"] = round(time.perf_counter() - t_job, 2)
out["timings"] = dict(timings)
"""

# An unsaved file (Run All): results packed, not in Blender's temp dir or the add-on's folder.
UNSAVED = r"""
obj, mat, image, world = make_scene()
before = snapshot()
bpy.context.scene.scenefit.prompt = ""  # Run All: convert, light, the composite set up; adapt skipped (no prompt)
bpy.context.scene.scenefit.camera_from = "panel"            # the panel's camera reaches the Mitsuba composite
bpy.context.scene.scenefit.fov = math.radians(50.0)
bpy.context.scene.scenefit.pitch = math.radians(-14.0)
bpy.context.scene.scenefit.scene_type = "outdoor"          # the Scene section's type and sun reach the light stage
bpy.context.scene.scenefit.sun_from = "set"
bpy.context.scene.scenefit.sun_azimuth, bpy.context.scene.scenefit.sun_elevation = math.radians(-40.0), math.radians(30.0)
with timed("run_all"):
    ops = [bpy.ops.scenefit.run()]
out["unsaved_ops"] = [sorted(o) for o in ops]
s = bpy.context.scene.scenefit
composite = bpy.data.images.get("SceneFit Composite")
out["run_composite"] = [composite is not None and composite.get("scenefit"), list(composite.size) if composite else None]
run_dir = Path(bpy.path.abspath(s.composite_path)).parent.parent
out["run_report"] = json.loads((run_dir / "report.json").read_text())
out["run_folder_siblings"] = sorted(p.name for p in run_dir.parent.iterdir())
out["run_all"] = [bpy.data.scenes["SceneFit Composite"].camera.name,
                  bpy.context.scene.world.name, bpy.context.active_object.active_material.name]
made = [i for i in bpy.data.images if "scenefit" in i]
out["unsaved_packed"] = [(i.name, i.packed_file is not None) for i in made]
folders = [Path(bpy.path.abspath(i.filepath)).parent for i in made]
addon_dir = Path(sf.__file__).parent
out["unsaved_outside_temp_and_addon"] = all(Path(bpy.app.tempdir) not in f.parents and addon_dir not in f.parents
                                            for f in folders)
bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "was_unsaved.blend"))
bpy.ops.wm.open_mainfile(filepath=str(tmp / "was_unsaved.blend"))
out["unsaved_reopened"] = sorted((i.name, list(i.size)) for i in bpy.data.images if "scenefit" in i)
out["unsaved_unchanged"] = snapshot() == before
out["timings"] = dict(timings)
"""

# A zip without its wheels: one sentence, no traceback, nothing run (last: it disables the add-on).
MISSING = r"""
dependencies.REQUIRED_MODULES["scenefit_no_such_module"] = "NoSuchModule"
dependencies._missing = None
try:
    out["missing"] = [sorted(bpy.ops.scenefit.convert()), dependencies.dependency_sentence()]
except RuntimeError as error:  # bpy.ops raises what the operator reported as an error
    out["missing"] = [str(error), dependencies.dependency_sentence()]
addon_utils.disable(MODULE, default_set=True)
"""


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    """The Blender session with the extension installed from its zip into its own user folder."""
    tmp = tmp_path_factory.mktemp("operators")
    zip_path, tiny, user = extension_and_models(tmp)
    session = PythonSession(env={"BLENDER_USER_RESOURCES": str(user)})
    try:
        installed = session.run(fill_in(INSTALL, tmp, zip_path, tiny))
        yield SimpleNamespace(run=session.run, tmp=tmp, user=user, installed=installed)
    finally:
        session.close()


# The tests on the operators' scene (operated, Bake Asset, save -> reopen) come first, in this order:
# the later steps make scenes of their own.
def step(blender, code: str) -> dict:
    out = blender.run(code)
    (blender.tmp / "out.json").write_text(json.dumps(out, default=str))  # for a look after a failure
    if "timings" in out:
        print("seconds per operator:", out["timings"])
    return out


@pytest.fixture(scope="module")
def operated(blender):
    return blender.tmp, step(blender, OPERATORS), blender.user


@pytest.fixture(scope="module")
def unsaved(blender):
    return step(blender, UNSAVED)


def test_every_operator_finishes_with_exec_default(blender, operated):
    tmp, out, user = operated
    assert blender.installed["module_file"].startswith(str(user))  # the installed copy
    assert out["loader"][0] > 0 and out["loader"][1:] == [True, True]  # the open file was not reset or changed
    assert all(v == ["FINISHED"] for v in out["ops"].values()), out["ops"]
    assert {"SCENEFIT_PT_asset", "SCENEFIT_PT_scene", "SCENEFIT_PT_style", "SCENEFIT_PT_quality",
            "SCENEFIT_PT_run", "SCENEFIT_PT_results"} <= set(out["panel_sections"])
    found, dropped = out["summary"]
    assert found[0] == "Base Color: image 'asset_color'" and found[1] == "Roughness: value" and dropped == ["Alpha"]
    assert out["placement"] == pytest.approx([0.5, 0.8])
    # A new material per run; each run in its own folder (the second convert overwrote nothing).
    first, last, active = out["materials"]
    assert first != last and active == last and "adapt" in last
    assert out["after_revert"] == "AssetMaterial" and out["world_after_revert"] == "User World"
    assert out["world"] == "SceneFit Light.001" and out["camera"]   # (a World per Estimate Light: the second's) == [None, "SceneFit Camera"] and out["shadow_catcher"]
    kinds = sorted(Path(f).name.split("-")[0] for f in out["run_folders"])
    assert kinds == ["adapt", "compose", "convert", "convert", "light", "light", "mitsuba"], out["run_folders"]
    # Constant channels stay constants: the sphere's roughness 0.5 and metallic 0 are socket values, not images.
    assert out["convert_constants"] == {"Roughness": [False, 0.5], "Metallic": [False, 0.0]}
    assert out["open_composite_options"] == ["REGISTER"]
    assert all(p.startswith("//scenefit/") for p in out["paths"].values()), out["paths"]
    assert all(path.startswith("//scenefit/") for _, path in out["images"]), out["images"]


def test_estimate_light_is_the_pipelines_light_stage_and_a_second_click_reuses_it(operated):
    """Estimate Light runs run_pipeline's camera and light stages on the photo alone; the same click again
    copies the first run's stages in (same photo and settings) and the World reads the new folder's map."""
    tmp, out, _ = operated
    first, second = sorted(tmp / f for f in out["run_folders"] if Path(f).name.startswith("light"))
    reports = [json.loads((folder / "report.json").read_text()) for folder in (first, second)]
    assert [list(r["stages"]) for r in reports] == [["light"], ["light"]]
    assert [r["stages"]["light"]["status"] for r in reports] == ["ran", "reused"]
    assert Path(reports[1]["stages"]["light"]["from"]).resolve() == first.resolve()
    assert reports[0]["inputs"]["asset"] is None
    assert reports[0]["camera"]["status"] == "ran" and (first / "camera" / "camera.json").is_file()
    assert (tmp / out["paths"]["light"][2:]).resolve() == (second / "light" / "light.exr").resolve()
    assert (first / "light" / "light.exr").read_bytes() == (second / "light" / "light.exr").read_bytes()


def test_hours_of_local_adaptation_are_said_before_they_start(operated):
    """Adapt with the models present on a CPU: the preset's iterations at the measured seconds per
    iteration (SD2 size) is hours, said in one sentence that offers the worker; two iterations are not."""
    _, out, _ = operated
    from scenefit.workers import time_model as quality   # (the panel's numbers, without bpy)

    sentence, short, preset = out["long_work"]
    hours = quality.duration_text(quality.adapt_projection(preset))
    assert short is None and hours.endswith(" h"), hours
    assert sentence.endswith(".") and ". " not in sentence, sentence
    assert f"about {hours}" in sentence and "worker environment" in sentence, sentence


def test_composite_shows_the_photo_around_the_asset(operated):
    tmp, out, _ = operated
    composite = read_image(tmp / out["paths"]["composite"][2:])[..., :3]
    photo = read_image(tmp / "photo.png")
    assert composite.shape == photo.shape == (48, 64, 3)
    same = np.abs(composite - photo).max(axis=2) < 2 / 255
    assert same[:8].mean() > 0.9  # the top rows (sky of the photo) come through the compositor unchanged
    assert not same[30:42, 26:38].all()  # the asset stands around (0.5, 0.8)


def test_export_uses_the_photo_camera_and_the_estimated_light(operated):
    tmp, out, _ = operated
    (folder,) = [tmp / f for f in out["run_folders"] if Path(f).name.startswith("mitsuba")]
    xml = (folder / "scene.xml").read_text()
    assert 'name="fov_axis" value="x"' in xml and 'name="width" value="64"' in xml
    light = read_image(tmp / out["paths"]["light"][2:])
    env = read_image(folder / "envmap.exr")
    assert env.shape[0] > 16 and np.allclose(env.mean(), light.mean(), rtol=0.1)


def test_bake_asset_writes_valid_gltf_that_reads_back(blender, operated, validator, run_py):
    tmp = blender.tmp
    out = step(blender, BAKE)
    assert out["ops"]["bake_glb"] == out["ops"]["bake_gltf"] == ["FINISHED"]
    (folder,) = out["bake_folders"]   # Bake Asset without a path: one run folder of its own
    assert Path(folder).parent.name == "Sphere" and Path(folder).name.startswith("bake-")
    after, before = out["bake_unchanged"][1:]
    assert out["bake_unchanged"][0], [(a, b) for a, b in zip(after, before) if a != b]
    assert "power of two" in out["bake_refused"]
    glb, gltf = sorted(out["bake_files"], key=lambda p: not p.endswith(".glb"))
    assert Path(glb).parent.parent.name == "Sphere" and Path(glb).parent.name.startswith("bake-")
    assert gltf == str(tmp / "chosen" / "asset.gltf")
    chosen = json.loads(Path(gltf).read_text())  # Compression Draco, Textures JPEG
    assert "KHR_draco_mesh_compression" in chosen["extensionsUsed"]
    kinds = {image["name"]: image.get("mimeType", Path(image.get("uri", "")).suffix) for image in chosen["images"]}
    assert kinds["AssetMaterial_metallic_roughness"] in ("image/jpeg", ".jpg"), kinds
    # the base colour carries the artist's alpha (their material links it), which JPEG cannot hold: PNG
    assert kinds["AssetMaterial_base_color"] in ("image/png", ".png"), kinds
    for path in (glb, gltf):
        report = validator(path)
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    # Re-imported in a process of its own (bpy may crash importing glTF after the exporter ran).
    proc = run_py(f"""
        import json
        import numpy as np
        from scenefit.blender_io.asset_file import load_asset_materials
        from scenefit.core.data.imageio import linear_to_srgb
        want = np.load({str(tmp / "expected_bake.npz")!r})
        (material,) = load_asset_materials({glb!r}).materials
        err = {{"name": material.name, "shape": list(material.maps.base_color.shape[:2]),
                "base_color": float(np.abs(np.round(linear_to_srgb(material.maps.base_color) * 255) - want["base_color"]).max())}}
        for channel in ("roughness", "metallic"):
            got, expected = np.asarray(getattr(material.maps, channel)), want[channel]
            err[channel] = float(np.max(np.abs(np.round(got * 255) - expected) if expected.ndim else np.abs(got - expected) * 255))
        print("JSON" + json.dumps(err))
    """)
    err = printed_json(proc)
    artist, in_slot = out["bake_material"]
    assert err["name"] == artist == "AssetMaterial" and in_slot != artist   # the artist's, not SceneFit's preview
    assert err["base_color"] <= 1.0 and err["roughness"] <= 1.0 and err["metallic"] <= 1.0, err
    assert err["shape"] == out["bake_shape"], (err, out["bake_shape"])


def test_results_survive_save_and_reopen_and_the_artists_data_is_unchanged(blender, operated):
    out = step(blender, REOPEN)
    assert out["unchanged_before_save"] and out["unchanged_after_reopen"], out["snapshot"]
    names = {name for name, _ in out["images"]}
    assert len(names) >= 7  # 3 maps per material x 3 runs + the light
    reopened = {name: (size, ok) for name, size, ok in out["reopened_images"]}
    assert set(reopened) == names
    assert all(size[0] > 0 and size[1] > 0 and ok for size, ok in reopened.values()), reopened


def test_the_job_path_reports_progress_cancels_fails_cleanly_and_never_touches_bpy(blender):
    out = step(blender, JOBS)
    job = out["job"]
    assert job["status"] == "done" and "convert" in job["stages"] and job["steps"] >= 1
    assert job["result_maps"] == {"base_color": "base_color.png", "roughness": 0.5, "metallic": 0.0}
    assert out["worker_touched_bpy"] == [] and out["control_caught"]
    assert out["job_material"].startswith("Sphere SceneFit convert")
    assert out["runtime"] == [True, 0.5, "convert: fit 3/6", True, [8, 8]]
    assert out["cancelled"] == "cancelled" and out["cancel_left"] == []
    status, error = out["error"]
    assert status == "failed" and "missing.png" in error and "Traceback" not in error
    assert out["after_load"] == ["cancelled", True, False]


def test_unsaved_file_results_are_packed_and_survive_saving(unsaved):
    out = unsaved
    assert out["unsaved_ops"] == [["FINISHED"]]
    assert out["run_all"] == ["SceneFit Camera", "SceneFit Light", "Sphere SceneFit convert"]
    # base colour (roughness and metallic stay values), the light and the composite
    assert len(out["unsaved_packed"]) == 3 and all(packed for _, packed in out["unsaved_packed"])
    assert out["unsaved_outside_temp_and_addon"]
    assert len(out["unsaved_reopened"]) == 3 and all(w > 0 and h > 0 for _, (w, h) in out["unsaved_reopened"])
    assert out["unsaved_unchanged"]


def test_run_all_is_the_command_lines_pipeline_and_shows_the_composite(unsaved):
    out = unsaved
    assert out["run_composite"] == ["run", [64, 48]]  # loaded as an image, the photo's size
    stages = out["run_report"]["stages"]
    assert list(stages) == ["convert", "light", "adapt", "compose", "bake"]
    assert [stages[k]["status"] for k in ("convert", "light", "compose")] == ["ran"] * 3
    assert stages["adapt"] == {"status": "skipped", "why": "the Style section has no prompt"}
    assert stages["bake"]["status"] == "skipped" and "Bake Asset" in stages["bake"]["why"]
    assert out["run_report"]["composite"] == "compose/composite.png"  # relative: the folder was swapped in
    # The panel's camera (50 degrees, 14 above the horizon) is the light stage's and so the composite's.
    camera = stages["light"]["report"]["decisions"]["photo_camera"]
    assert camera["fov_deg"] == pytest.approx(50.0) and camera["pitch_deg"] == pytest.approx(-14.0)
    assert stages["compose"]["report"]["camera"]["fov_deg"] == pytest.approx(50.0)
    # The Scene section's Scene type (Run All once dropped it) and Sun.
    decisions = stages["light"]["report"]["decisions"]
    assert decisions["scene_type"]["chosen"] == "outdoor"
    assert decisions["sun"]["deg"] == [pytest.approx(-40.0), pytest.approx(30.0)]
    # written beside and swapped in whole: nothing but the run's folder is left
    assert len(out["run_folder_siblings"]) == 1 and out["run_folder_siblings"][0].startswith("run-")



# Import Asset: a meshopt-compressed GLB (Blender's glTF importer refuses it) into an artist's scene.
IMPORT = r"""
bpy.ops.wm.read_homefile(use_empty=True)
painted_plane("Painted", "Paint", 4)
bpy.ops.export_scene.gltf(filepath=str(tmp / "plain.glb"), export_format="GLB")
meshopt = import_module(MODULE + ".core.data.gltf_meshopt")
glb = import_module(MODULE + ".core.data.glb")
packed = meshopt.encoded_glb(tmp / "plain.glb", tmp / "packed.glb")
(tmp / "broken.glb").write_bytes(b"glTF not really")
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_cube_add()
mine = bpy.context.object
mine.name = "MyCube"
try:
    bpy.ops.import_scene.gltf(filepath=str(packed))
    out["blender_importer"] = "read it"
except RuntimeError as error:
    out["blender_importer"] = str(error).splitlines()[-1]
out["objects_after_refusal"] = sorted(o.name for o in bpy.data.objects)
out["import"] = sorted(bpy.ops.scenefit.import_asset(filepath=str(packed)))
new = [o for o in bpy.data.objects if o.name != "MyCube"]
out["imported"] = sorted(o.name for o in new)
out["active"] = bpy.context.view_layer.objects.active.name
out["selected"] = sorted(o.name for o in bpy.context.selected_objects)
out["mine"] = [list(mine.location), len(mine.data.vertices), mine.name]
images = [i for i in bpy.data.images if i.name not in ("Render Result", "Viewer Node")]
out["images"] = [(i.packed_file is not None, list(i.size)) for i in images]
try:
    bpy.ops.scenefit.import_asset(filepath=str(tmp / "broken.glb"))
    out["broken"] = "imported"
except RuntimeError as error:
    out["broken"] = str(error)
out["after_broken"] = sorted(o.name for o in bpy.data.objects)
menu = bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
out["in_file_import"] = any(getattr(f, "__module__", "").endswith("operators.import_asset") for f in menu)
# The Asset section says what the selection is
mine.select_set(True)
out["asset_section"] = panel_lines(bpy.types.SCENEFIT_PT_asset)
# Bake Asset writes it as the file was written (Compression and Textures default to As imported)
painted = bpy.data.objects["Painted"]
out["source"] = painted.scenefit_source_file
out["import_convert"], out["import_bake"] = convert_and_bake(painted, "imported")
out["import_bake_extensions"] = glb.read_gltf(tmp / "imported_bake" / "painted.glb")[0].get("extensionsUsed", [])
"""


def test_import_asset_reads_a_file_blenders_importer_refuses_into_the_artists_scene(blender):
    out = step(blender, IMPORT)
    assert "EXT_meshopt_compression" in out["blender_importer"]   # why the operator exists
    assert out["objects_after_refusal"] == ["MyCube"]
    assert out["import"] == ["FINISHED"] and out["imported"] == ["Painted"]
    assert out["active"] == "Painted" and out["selected"] == ["Painted"]
    assert out["mine"] == [[0.0, 0.0, 0.0], 8, "MyCube"]   # the artist's object as it was
    # the image came from a decoded copy in a temporary folder: packed, so it outlives the copy
    assert out["images"] == [[True, [8, 8]]]
    assert out["broken"].startswith("Error: Asset file '") and "broken.glb' cannot be read" in out["broken"]
    assert out["broken"].rstrip().count("\n") == 0 and "Traceback" not in out["broken"]
    assert out["after_broken"] == ["MyCube", "Painted"]
    assert out["in_file_import"]
    assert out["asset_section"][:3] == ["Painted", "scenefit.import_asset", "2 objects, one asset"]
    assert out["source"] == str((blender.tmp / "packed.glb").resolve())
    assert out["import_convert"] == out["import_bake"] == ["FINISHED"]
    assert "EXT_meshopt_compression" in out["import_bake_extensions"]   # as imported (else plain: "none")

# Blender's own File > Import of a glTF (not Import Asset): the add-on's importer hook marks what it makes,
# so Bake Asset writes it as the file was written and takes along the file's camera.
NATIVE = r"""
bpy.ops.wm.read_homefile(use_empty=True)
painted_plane("Tile", "Glaze", 5)
bpy.ops.object.camera_add(location=(0, -4, 2))
bpy.context.object.name = "TileCamera"
bpy.ops.export_scene.gltf(filepath=str(tmp / "draco.glb"), export_format="GLB", export_cameras=True,
                          export_draco_mesh_compression_enable=True, export_image_format="WEBP")
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.import_scene.gltf(filepath=str(tmp / "draco.glb"))   # File > Import > glTF 2.0
out["marks"] = {o.name: [o.scenefit_source_file, bool(o.scenefit_import)] for o in bpy.data.objects}
# not custom properties: the artist's own export with custom properties would ship the file's path
out["custom_properties"] = sorted({k for o in bpy.data.objects for k in o.keys()})
bpy.ops.export_scene.gltf(filepath=str(tmp / "mine.glb"), export_format="GLB", export_extras=True)
out["path_in_own_export"] = str(tmp) in (tmp / "mine.glb").read_bytes().decode("latin-1")
out["native_convert"], out["native_bake"] = convert_and_bake(bpy.data.objects["Tile"], "native")
doc = import_module(MODULE + ".core.data.glb").read_gltf(tmp / "native_bake" / "tile.glb")[0]
out["native_extensions"] = sorted(doc.get("extensionsUsed", []))
out["native_nodes"] = sorted(n.get("name", "") for n in doc["nodes"])
"""


def test_blenders_own_gltf_import_is_baked_as_the_file_was_written(blender):
    out = step(blender, NATIVE)
    source = str((blender.tmp / "draco.glb").resolve())
    assert out["marks"] == {"Tile": [source, True], "TileCamera": [source, True]}, out["marks"]
    assert out["custom_properties"] == [] and not out["path_in_own_export"]
    assert out["native_convert"] == out["native_bake"] == ["FINISHED"]
    # Draco and WebP as the file had them (they were none and PNG: the import left no mark), and its camera
    assert {"KHR_draco_mesh_compression", "EXT_texture_webp"} <= set(out["native_extensions"]), out["native_extensions"]
    assert out["native_nodes"] == ["Tile", "TileCamera"]


# A tree on a ground plane, selected together: the Asset section names the plane before Run All refuses.
FLAT = r"""
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_cylinder_add(radius=0.3, depth=3.0, location=(0, 0, 1.5))
bpy.context.object.name = "Trunk"
bpy.ops.mesh.primitive_cone_add(radius1=1.5, depth=2.0, location=(0, 0, 3.5))
bpy.context.object.name = "Crown"
bpy.ops.mesh.primitive_plane_add(size=300.0)   # 67 times the tree's height
bpy.context.object.name = "Ground"
bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 0, 0.01))   # a blob shadow: flat too, but not the culprit
bpy.context.object.name = "ShadowDecal"
def drawn(names):
    select_only(*(bpy.data.objects[n] for n in names))
    return [t for t in panel_lines(bpy.types.SCENEFIT_PT_asset) if "ground plane" in t]
out["with_ground"] = drawn(["Trunk", "Crown", "Ground", "ShadowDecal"])
out["tree_alone"] = drawn(["Trunk", "Crown"])
out["flat_parts"] = asset_ops.flat_parts([bpy.data.objects[n] for n in ("Trunk", "Crown", "Ground", "ShadowDecal")])
"""


def test_the_asset_section_names_a_ground_plane_that_makes_the_selection_too_flat(blender):
    out = step(blender, FLAT)
    assert out["with_ground"] == ["'Ground' is flat (a ground plane?): deselect it to fit the rest"]
    assert out["tree_alone"] == []
    assert [name for name, _ in out["flat_parts"]] == ["Ground"]   # the blob shadow is flat too, but not named


def test_missing_dependencies_are_one_sentence(blender):
    out = step(blender, MISSING)   # the module's last test: it disables the add-on
    reported, sentence = out["missing"]
    assert sentence.startswith("Missing Python modules: NoSuchModule;") and sentence.count(".") == 1
    assert sentence in reported and "Traceback" not in reported
