"""The panel in an artist's words, in bpy: every operator and property described, a poll message on every
button that can be greyed out, labels through Blender's translation (never an f-string), the photo's
thumbnail read once and never while drawing, and the artist's camera's lens shift moving the asset's
placement as Blender's own projection does. One bpy session for the module (the package registered
from this tree)."""
import ast
from pathlib import Path

import pytest
from conftest import ROOT, PythonSession

pytestmark = pytest.mark.blender

PANELS = Path(ROOT) / "panels"

SETUP = r"""
import builtins, math
from types import SimpleNamespace
import numpy as np
import bpy
import scenefit
scenefit.register()
from scenefit import operators, panels

class Layout:   # what a panel draws, recorded: panels cannot draw without a window
    def __init__(self): self.drawn = []
    def column(self, **kw): return self
    def row(self, **kw): return self
    def box(self, **kw): return self
    def prop(self, data, name, **kw): self.drawn.append(("prop", name))
    def operator(self, idname, **kw):
        self.drawn.append(("operator", idname, kw.get("text"), kw.get("icon")))
        return SimpleNamespace()
    def label(self, text="", **kw): self.drawn.append(("label", text))
    def template_icon(self, icon_value=0, **kw): self.drawn.append(("icon", icon_value))
    def template_list(self, *args, **kw): self.drawn.append(("list",))
    def progress(self, **kw): self.drawn.append(("progress", kw.get("text")))

def drawn(panel_class):
    layout = Layout()
    panel_class.draw(SimpleNamespace(layout=layout), bpy.context)
    return layout.drawn
"""

DESCRIPTIONS = r"""
missing = []
for cls in operators.classes + panels.classes:
    if issubclass(cls, bpy.types.Operator):
        group, name = cls.bl_idname.split(".")
        rna = getattr(getattr(bpy.ops, group), name).get_rna_type()
        if not rna.description.strip():
            missing.append(cls.bl_idname)
        missing += [f"{cls.bl_idname}.{p.identifier}" for p in rna.properties
                    if p.identifier != "rna_type" and not p.description.strip()]
    elif issubclass(cls, (bpy.types.PropertyGroup, bpy.types.AddonPreferences)):
        missing += [f"{cls.__name__}.{p.identifier}" for p in cls.bl_rna.properties
                    if p.identifier not in ("rna_type", "name", "bl_idname") and not p.description.strip()]
texts = {cls.bl_idname: getattr(getattr(bpy.ops, cls.bl_idname.split(".")[0]), cls.bl_idname.split(".")[1])
         .get_rna_type().description for cls in operators.classes if issubclass(cls, bpy.types.Operator)}
out["missing"] = missing
out["command_line_words"] = [k for k, v in texts.items() if "scenefit " in v or "--" in v]
out["operators"] = len(texts)
"""

POLLS = r"""
said = {}
polled = [cls for cls in operators.classes if issubclass(cls, bpy.types.Operator) and hasattr(cls, "poll")]
for cls in polled:
    cls.poll_message_set = classmethod(lambda c, message, *args: said.__setitem__(c.bl_idname, message))

def greyed(case):
    said.clear()
    return {cls.bl_idname: said.get(cls.bl_idname) for cls in polled if not cls.poll(bpy.context)}

bpy.ops.wm.read_homefile(use_empty=True)
empty = greyed("empty")                      # no object, no job, no texture, no composite, no runs
bpy.ops.mesh.primitive_cube_add()
with_mesh = greyed("mesh")                    # a mesh, but nothing SceneFit made for it yet
out["empty"], out["with_mesh"], out["polled"] = empty, with_mesh, sorted(c.bl_idname for c in polled)
french = panels.translations.translations_dict["fr_FR"]
out["untranslated_buttons"] = sorted({c.bl_label for c in operators.classes if issubclass(c, bpy.types.Operator)
                                      and "INTERNAL" not in c.bl_options} - {k for ctx, k in french if ctx == "Operator"})
"""

THUMBNAIL = r"""
from importlib import import_module
import sys
torch_before = "torch" in sys.modules
imageio = import_module("scenefit.core.data.imageio")
bpy.ops.wm.read_homefile(use_empty=True)
photo = np.zeros((60, 80, 3), np.float32); photo[:, :40] = (1.0, 0.0, 0.0)   # left half red
path = Path_ = __import__("pathlib").Path(TMP) / "photo.png"
imageio.write_image(path, photo)
reads, real_read = [], imageio.read_image
def counted(*args, **kw):
    reads.append(str(args[0]))
    return real_read(*args, **kw)
imageio.read_image = counted
try:
    bpy.context.scene.scenefit.photo_path = str(path)
    panels.thumbnail.wait_for_thumbnails(60)   # (decoded in the reader thread)
finally:
    imageio.read_image = real_read
import OpenImageIO as oiio
opened = []
real_open, real_oiio = builtins.open, oiio.ImageInput.open
def refuse(*args, **kw):
    opened.append(str(args[0]) if args else "")
    raise AssertionError("draw opened a file")
builtins.open, oiio.ImageInput.open = refuse, refuse
try:
    frames = [drawn(panels.main.SCENEFIT_PT_scene) for _ in range(3)]
    bpy.ops.mesh.primitive_cube_add()   # an asset for the Asset section to describe
    sections = {cls.__name__: drawn(cls) for cls in panels.main.classes if issubclass(cls, bpy.types.Panel)}
finally:
    builtins.open, oiio.ImageInput.open = real_open, real_oiio
icons = [[d[1] for d in frame if d[0] == "icon"] for frame in frames]
preview = panels.thumbnail._previews[str(path)]
pixels = np.array(preview.image_pixels_float[:]).reshape(preview.image_size[1], preview.image_size[0], 4)
out["sections"] = {name: len(lines) for name, lines in sections.items()}
out["quality"] = [d for d in sections["SCENEFIT_PT_quality"] if d[0] in ("label", "operator")]
out["torch"] = [torch_before, "torch" in sys.modules]
out.update(reads=reads, opened=opened, icons=icons, icon_id=preview.icon_id, size=list(preview.image_size),
           top_left=pixels[-1, 0].tolist(), top_right=pixels[-1, -1].tolist(),
           pickers=[d for d in frames[0] if d[0] == "operator" and d[1] in ("scenefit.pick_placement", "scenefit.pick_sun")])
"""

LENS_SHIFT = r"""
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector
from scenefit.blender_io.scene_camera import principal_point, scene_view
bpy.ops.wm.read_homefile(use_empty=True)
scene = bpy.context.scene
W, H = 640, 480
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
cam = bpy.data.objects.new("fSpy camera", bpy.data.cameras.new("fSpy camera"))
scene.collection.objects.link(cam)
scene.camera = cam
cam.location, cam.rotation_euler = (0.3, -6.0, 1.6), (math.radians(80), math.radians(3), math.radians(4))
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.2, 0.0, 0.5))
cube = bpy.context.active_object
rows = []
for fit in ("AUTO", "HORIZONTAL", "VERTICAL"):
    cam.data.sensor_fit = fit
    for shift in ((0.0, 0.0), (0.12, -0.07), (-0.2, 0.15)):
        cam.data.shift_x, cam.data.shift_y = shift
        bpy.context.view_layer.update()
        seen, notes = scene_view(cam, cube, (W, H), bpy.context.evaluated_depsgraph_get())
        axis = cam.matrix_world @ Vector((0.0, 0.0, -5.0))        # a point on the optical axis
        ax, ay = world_to_camera_view(scene, cam, axis)[:2]
        corner = world_to_camera_view(scene, cam, cube.matrix_world @ cube.data.vertices[0].co)
        rows.append({"fit": fit, "shift": shift, "principal": principal_point(cam, W, H),
                     "blender_axis": (ax * W, (1.0 - ay) * H), "placement": seen.placement, "size": seen.size,
                     "corner": (corner[0], 1.0 - corner[1]), "notes": notes})
out["rows"] = rows
"""

PROGRESS = r"""
import time
from importlib import import_module
jobs, background = import_module("scenefit.operators.jobs"), import_module("scenefit.workers.background")
registry = import_module("scenefit.core.pipeline.registry")   # the stage order Run All's bar counts
rt = bpy.context.window_manager.scenefit_runtime
said = {}
rt.expected_seconds = 7200.0                         # the bench's projection, set when the job starts
state = background.JobState("adapt", stage="adapt", fraction=0.0, started=time.perf_counter())
jobs.update_runtime(bpy.context, state)
said["adapt_at_start"] = rt.status
stages = list(registry.RUN_ORDER)
later = stages[stages.index("adapt") + 1]
for stage in ("convert", later):                     # Run All before its adaptation, and after it
    jobs.update_runtime(bpy.context, background.JobState("run", stage=stage, fraction=0.5, total=len(stages)))
    said["run_" + stage] = rt.status
said["later"] = later
rt.expected_seconds = 0.0
state = background.JobState("run", stage=stages[1], fraction=0.5, total=len(stages), started=time.perf_counter())
frame = np.zeros((6, 8, 3), np.uint8); frame[0, 0] = (255, 0, 0)     # the top-left pixel red
state.preview, state.preview_serial = frame, 1
jobs.update_runtime(bpy.context, state)
said["run"], said["progress"], said["stages"] = rt.status, rt.progress, stages
image = bpy.data.images.get(jobs.PREVIEW_IMAGE)
pixels = np.array(image.pixels[:]).reshape(6, 8, 4)
said["image"] = [list(image.size), pixels[-1, 0].tolist(), pixels[0, 0].tolist(), image.users]
out.update(said)
"""

BAKE_BROWSER = r"""
bake = operators.bake.SCENEFIT_OT_bake_asset
chosen = SimpleNamespace(filepath="/somewhere/chair.glb", file_format="gltf")
out["changed"] = [bake.check(chosen, bpy.context), chosen.filepath]
out["unchanged"] = [bake.check(chosen, bpy.context), chosen.filepath]
# Its own invoke on a stand-in window: the browser opens on a file beside the .blend, no job starts yet.
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_cube_add()
bpy.context.active_object.name = "Chair"
bpy.ops.wm.save_as_mainfile(filepath=str(__import__("pathlib").Path(TMP) / "scene.blend"))
attrs = {}
for klass in reversed(bake.__mro__):
    if klass.__module__.startswith("scenefit"):
        attrs.update({k: v for k, v in vars(klass).items() if not k.startswith("__") and k != "bl_rna"})
op = type("Probe", (), dict(attrs, filepath="", file_format="glb"))()
browsed = []
class Ctx:
    window = object()
    window_manager = SimpleNamespace(fileselect_add=lambda o: browsed.append(o.filepath))
    def __getattr__(self, name): return getattr(bpy.context, name)
operators.bake.has_ui = lambda context: True
try:
    out["invoke"] = [sorted(op.invoke(Ctx(), None)), browsed]
finally:
    operators.bake.has_ui = operators.jobs.has_ui
out["blend_folder"] = str(__import__("pathlib").Path(TMP))
rt = bpy.context.window_manager.scenefit_runtime
rt.details = ""
out["copy_greyed"] = operators.details.SCENEFIT_OT_copy_details.poll(bpy.context)
rt.details = "Adapt failed: CUDA out of memory\nTraceback ..."
out["copy"] = [operators.details.SCENEFIT_OT_copy_details.poll(bpy.context), sorted(bpy.ops.scenefit.copy_details())]
"""


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("panel_words")
    session = PythonSession()
    try:
        session.run(SETUP, timeout=300)
        yield session, tmp
    finally:
        session.close()


def test_every_operator_and_property_is_described_in_an_artists_words(blender):
    session, _ = blender
    out = session.run(DESCRIPTIONS)
    assert out["operators"] >= 20
    assert out["missing"] == []
    assert out["command_line_words"] == []


def test_every_button_that_can_be_greyed_out_says_why(blender):
    session, _ = blender
    out = session.run(POLLS)
    # The empty file greys out the asset's buttons, the job's, the runs', Write Prompt, the composite's;
    # a mesh with nothing made for it greys out Bake Asset (no texture) and the last bake's folder.
    for must in ("scenefit.run", "scenefit.adapt", "scenefit.bake_asset", "scenefit.generate_prompt",
                 "scenefit.cancel_job", "scenefit.apply_run", "scenefit.open_composite", "scenefit.copy_details"):
        assert must in out["empty"], must
    assert "scenefit.bake_asset" in out["with_mesh"] and "photo" in out["with_mesh"]["scenefit.run"]
    assert "photo" in out["with_mesh"]["scenefit.estimate_light"]   # both need the photo, and say so
    silent = {k: v for case in ("empty", "with_mesh") for k, v in out[case].items() if not v}
    assert silent == {}
    assert out["with_mesh"]["scenefit.bake_asset"] != out["empty"]["scenefit.bake_asset"]   # each says its own why
    assert out["untranslated_buttons"] == []   # each button's name has a French entry


def _layout_calls(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                node.func.attr in ("label", "operator", "prop", "progress", "template_icon"):
            yield node


def test_no_panel_label_is_an_f_string_and_every_label_built_in_code_is_translated():
    from scenefit.panels.translations import translations_dict

    f_strings, untranslated = [], []
    french = {key for context, key in translations_dict["fr_FR"]}
    # (the time model's words, said by the panel through Blender's translation, live beside the model)
    for path in sorted(PANELS.glob("*.py")) + [PANELS.parent / "workers" / "time_model.py"]:
        tree = ast.parse(path.read_text(), str(path))
        for call in _layout_calls(tree):
            for keyword in call.keywords:
                if keyword.arg == "text" and isinstance(keyword.value, ast.JoinedStr):
                    f_strings.append(f"{path.name}:{call.lineno}")
        for node in ast.walk(tree):   # the words handed to Blender's translation have a table entry
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "iface_" and node.args and \
                    isinstance(node.args[0], ast.Constant) and node.args[0].value not in french:
                untranslated.append(f"{path.name}:{node.lineno}: {node.args[0].value!r}")
        if path.name in ("main.py", "quality.py", "time_model.py"):   # they build labels: none from an f-string at all
            f_strings += [f"{path.name}:{n.lineno}" for n in ast.walk(tree) if isinstance(n, ast.JoinedStr)]
    assert f_strings == []
    assert untranslated == []


def test_the_photos_thumbnail_is_read_once_and_drawing_opens_no_file(blender):
    session, tmp = blender
    out = session.run(THUMBNAIL.replace("TMP", repr(str(tmp))))
    assert len(out["reads"]) == 1 and out["reads"][0].endswith("photo.png")
    assert out["opened"] == []
    assert out["torch"] == [False, False]   # nor does drawing load torch (seconds, the first time)
    assert out["icons"] == [[out["icon_id"]]] * 3   # (0 without a window: Blender makes icons for the UI)
    assert out["size"] == [80, 60]
    # the preview is the photo the right way up: red on the left, black on the right
    assert out["top_left"][:3] == pytest.approx([1.0, 0.0, 0.0]) and out["top_right"][:3] == pytest.approx([0.0, 0.0, 0.0])
    assert {d[3] for d in out["pickers"]} == {"EYEDROPPER"} and len(out["pickers"]) == 2
    # every section draws from what was read before, none of them opening a file
    assert all(n > 0 for n in out["sections"].values()) and len(out["sections"]) == 7, out["sections"]
    adapt = [d for d in out["quality"] if d[0] == "operator" and d[1] == "scenefit.show_details"]
    assert len(adapt) == 1 and adapt[0][2].startswith("adapt: about") and len(adapt[0][2]) <= 40   # short label


def test_lens_shift_moves_the_principal_point_and_the_placement_as_blender_projects(blender):
    session, _ = blender
    rows = session.run(LENS_SHIFT)["rows"]
    for row in rows:   # the optical axis meets the frame where Blender's own projection puts it
        assert row["principal"] == pytest.approx(row["blender_axis"], abs=1e-3), row
    for fit in ("AUTO", "HORIZONTAL", "VERTICAL"):
        level, *shifted = [r for r in rows if r["fit"] == fit]
        assert level["principal"] == pytest.approx([320.0, 240.0]) and level["notes"] == []
        for row in shifted:   # the asset moves in the photo as a point of it moves in Blender's view
            moved = [p - q for p, q in zip(row["placement"], level["placement"])]
            expected = [p - q for p, q in zip(row["corner"], level["corner"])]
            assert moved == pytest.approx(expected, abs=1e-5), row
            assert max(abs(v) for v in moved) > 0.05
            assert row["size"] == pytest.approx(level["size"], rel=1e-9)
            assert any("lens shift" in note for note in row["notes"])


def test_time_left_starts_from_the_projection_and_goes_over_to_the_runs_own_pace():
    from scenefit.panels.quality import eta_from_start

    assert eta_from_start(3600.0, 0.0, 0.0) == pytest.approx(3600.0)            # the first moment: the bench
    assert eta_from_start(100.0, 50.0, 0.5) == pytest.approx(50.0)              # past a tenth: its own pace
    assert eta_from_start(100.0, 10.0, 0.02) == pytest.approx(0.8 * 98.0 + 0.2 * 490.0)   # slow: weighed in
    assert eta_from_start(None, 10.0, 0.25) == pytest.approx(30.0)             # no projection: the pace
    assert eta_from_start(None, 0.0, 0.0) is None
    assert eta_from_start(100.0, 80.0, 1.0) == pytest.approx(0.0)


def test_progress_says_the_stage_the_time_left_from_the_start_and_keeps_a_preview_image(blender):
    session, _ = blender
    out = session.run(PROGRESS)
    assert out["adapt_at_start"].endswith("about 2.0 h left"), out["adapt_at_start"]
    assert out["run_convert"].endswith("about 2.0 h left"), out["run_convert"]   # the adaptation still to come
    assert "2.0 h" not in out["run_" + out["later"]]                             # done: no projection left
    n = len(out["stages"])
    assert f"stage 2 of {n} ({out['stages'][1]})" in out["run"]
    assert out["progress"] == pytest.approx(1.5 / n)
    size, top_left, bottom_left, users = out["image"]
    assert size == [8, 6] and top_left[:3] == pytest.approx([1.0, 0.0, 0.0]) and bottom_left[:3] == [0.0, 0.0, 0.0]
    assert users == 0   # SceneFit's own preview is not saved into the artist's file


def test_bake_asset_names_its_file_in_a_browser_and_copy_details_is_offered_after_a_failure(blender):
    session, tmp = blender
    out = session.run(BAKE_BROWSER.replace("TMP", repr(str(tmp))))
    assert out["changed"] == [True, "/somewhere/chair.gltf"]      # the ending follows the chosen format
    assert out["unchanged"] == [False, "/somewhere/chair.gltf"]
    assert out["invoke"] == [["RUNNING_MODAL"], [str(Path(out["blend_folder"]) / "Chair.glb")]]
    assert out["copy_greyed"] is False
    assert out["copy"] == [True, ["FINISHED"]]   # (bpy without a window has no clipboard to read back)
