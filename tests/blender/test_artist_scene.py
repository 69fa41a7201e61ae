"""The artist's scene stays theirs: every SceneFit operator, run on a corpus asset in a scene set up as an
artist's (EEVEE, 1920x1080, AgX at +0.7 EV, their own camera as the scene camera, their own compositor
with a Glare node, their materials and World), leaves each of those as it was; the Cycles composite
lives in SceneFit's own scene. One bpy session for the module (the extension installed from its zip)."""
import json
import os
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import PythonSession, extension_and_models, fill_in

pytestmark = pytest.mark.blender

# The corpus beside the repository (../shared/corpus), or where SCENEFIT_CORPUS says (a git worktree elsewhere).
CORPUS = Path(os.environ.get("SCENEFIT_CORPUS", Path(__file__).resolve().parents[2].parent / "shared" / "corpus")) / "assets"
ASSET = CORPUS / "kenney_blocky_character" / "character.glb"

SETUP = r"""
import json, math, sys, time
from importlib import import_module
from pathlib import Path
import numpy as np
import bpy

tmp, zip_path, tiny = Path(TMP), ZIP, TINY
MODULE = "bl_ext.user_default.scenefit"
bpy.ops.extensions.package_install_files(repo="user_default", filepath=zip_path, enable_on_install=True)
prefs = bpy.context.preferences.addons[MODULE].preferences
prefs.base_model, prefs.inpaint_model = str(Path(tiny) / "sd2-base"), str(Path(tiny) / "sd2-inpaint")
prefs.offline = True
imageio = import_module(MODULE + ".core.data.imageio")
TAG = "scenefit"

bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.scenefit.import_asset(filepath=ASSET)
scene = bpy.context.scene
scene.render.engine = "BLENDER_EEVEE" if "BLENDER_EEVEE" in {e.identifier for e in
    bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items} else "BLENDER_EEVEE_NEXT"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 1920, 1080, 100
scene.render.film_transparent = False
scene.view_settings.view_transform, scene.view_settings.exposure = "AgX", 0.7
cam_data = bpy.data.cameras.new("ArtistCam")
cam_data.lens = 42.0
artist_cam = bpy.data.objects.new("ArtistCam", cam_data)
artist_cam.location, artist_cam.rotation_euler = (0.0, -6.0, 1.5), (math.radians(80.0), 0.0, 0.0)
scene.collection.objects.link(artist_cam)
scene.camera = artist_cam
if hasattr(scene, "compositing_node_group"):    # Blender 5: the artist's compositor node group
    tree = bpy.data.node_groups.new("Artist Compositing", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    out_node = tree.nodes.new("NodeGroupOutput")
    scene.compositing_node_group = tree
else:                                             # Blender 4.x: the scene's own tree
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    out_node = tree.nodes.new("CompositorNodeComposite")
layers, glare = tree.nodes.new("CompositorNodeRLayers"), tree.nodes.new("CompositorNodeGlare")
tree.links.new(layers.outputs["Image"], glare.inputs["Image"])
tree.links.new(glare.outputs["Image"], out_node.inputs[0])
world = bpy.data.worlds.new("Artist World")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.8
scene.world = world
asset = sorted((o for o in scene.objects if o.type == "MESH"), key=lambda o: -len(o.data.vertices))[0]
for o in scene.objects:
    o.select_set(False)
asset.select_set(True)
bpy.context.view_layer.objects.active = asset
artist_materials = sorted({s.material.name for s in asset.material_slots if s.material})
photo = np.random.default_rng(1).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
imageio.write_image(tmp / "photo.png", photo)
settings = scene.scenefit
settings.preset, settings.photo_path, settings.prompt = "draft", str(tmp / "photo.png"), "a mossy figure"
bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "artist.blend"))

def compositor(s):
    tree = s.compositing_node_group if hasattr(s, "compositing_node_group") else s.node_tree
    return None if tree is None else [tree.name, sorted(n.bl_idname for n in tree.nodes), len(tree.links)]

def material_state(m):
    return [m.name, sorted((n.bl_idname, n.name) for n in m.node_tree.nodes), len(m.node_tree.links),
            [round(float(n.inputs[0].default_value), 4) for n in m.node_tree.nodes
             if n.bl_idname == "ShaderNodeBsdfPrincipled" and not n.inputs[0].is_linked]]

def snapshot():
    s, c = bpy.context.scene, artist_cam
    view = s.view_settings
    return {"scene": s.name, "engine": s.render.engine,
            "resolution": [s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage],
            "film_transparent": s.render.film_transparent,
            "colour": [view.view_transform, view.look, round(view.exposure, 4), round(view.gamma, 4)],
            "scene_camera": s.camera.name if s.camera else None,
            "camera": [c.data.lens, c.data.sensor_fit, [round(v, 5) for v in c.location],
                       [round(v, 5) for v in c.rotation_euler], len(c.data.background_images)],
            "compositor": compositor(s),
            "world": [len(world.node_tree.nodes), round(world.node_tree.nodes["Background"].inputs["Strength"].default_value, 4)],
            "scene_world_theirs_or_ours": s.world == world or (s.world is not None and TAG in s.world),
            "materials": [material_state(bpy.data.materials[n]) for n in artist_materials],
            "slots_theirs_or_ours": all(sl.material is None or sl.material.name in artist_materials or TAG in sl.material
                                        for sl in asset.material_slots),
            "their_objects": sorted(o.name for o in s.objects if TAG not in o)}

before = snapshot()
out["before"] = before
out["asset"] = [asset.name, len(asset.data.vertices), artist_materials]
"""

STEPS = r"""
def run(name, call):
    t = time.perf_counter()
    try:
        result = sorted(call())
    except RuntimeError as error:
        result = ["ERROR", str(error).splitlines()[0]]
    out["ops"][name] = [result, round(time.perf_counter() - t, 2)]
    now = snapshot()
    out["changed"][name] = {k: [before[k], now[k]] for k in before if now[k] != before[k]}

out["ops"], out["changed"] = {}, {}
run("pick_placement", lambda: bpy.ops.scenefit.pick_placement(x=0.5, y=0.8))
run("match_camera", lambda: bpy.ops.scenefit.match_camera())
run("convert", lambda: bpy.ops.scenefit.convert(iterations=5))
run("estimate_light", lambda: bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior"))
run("adapt", lambda: bpy.ops.scenefit.adapt(iterations=2, model_resolution=32, render_size=16))
run("compose", lambda: bpy.ops.scenefit.compose(samples=1))
run("run_all", lambda: bpy.ops.scenefit.run(guidance="none"))
run("bake_asset", lambda: bpy.ops.scenefit.bake_asset(filepath=str(tmp / "baked" / "asset.glb")))
run("original_material", lambda: bpy.ops.scenefit.use_result(target="MATERIAL", which="ORIGINAL"))
run("original_world", lambda: bpy.ops.scenefit.use_result(target="WORLD", which="ORIGINAL"))
out["restored"] = [[s.material.name if s.material else None for s in asset.material_slots],
                   bpy.context.scene.world.name]
own = bpy.data.scenes.get("SceneFit Composite")
out["composite_scene"] = None if own is None else {
    "tag": own.get(TAG), "engine": own.render.engine, "camera": own.camera.name if own.camera else None,
    "film_transparent": own.render.film_transparent, "view": own.view_settings.view_transform,
    "resolution": [own.render.resolution_x, own.render.resolution_y], "has_asset": asset.name in own.objects,
    "compositor": compositor(own)}
out["scenes"] = sorted(s.name for s in bpy.data.scenes)
out["window_scene"] = bpy.context.scene.name
"""

# The compositor is only ever set up on SceneFit's own scene, on either compositor API (Blender 5: a node
# group per scene; 4.x: the scene's own tree): an artist's scene is refused before anything is touched.
GUARD = r"""
compose = import_module(MODULE + ".blender_io.compose")

class FourX:   # a Blender 4.x scene as photo_behind_render sees it: no compositing_node_group, its own tree
    def __init__(self, tag):
        self.name, self._tag = "Scene 4.x", tag
        self.use_nodes, self.touched = False, []
        self.render = SimpleNamespace(engine="BLENDER_EEVEE", film_transparent=False)
        self.view_settings = SimpleNamespace(view_transform="AgX", look="None", exposure=0.7, gamma=1.0)
    def get(self, key, default=None):
        return self._tag if key == TAG else default
    @property
    def node_tree(self):
        self.touched.append("node_tree")
        raise RuntimeError("the 4.x tree was reached")

from types import SimpleNamespace
refusals = {}
for label, candidate in (("artist_5", bpy.context.scene), ("artist_4x", FourX(None))):
    try:
        compose.photo_behind_render(candidate, None)
        refusals[label] = "set up"
    except ValueError as error:
        refusals[label] = str(error)
ours_4x = FourX("composite")
try:
    compose.photo_behind_render(ours_4x, None)
except RuntimeError as error:
    refusals["ours_4x"] = [str(error), ours_4x.use_nodes, ours_4x.render.engine, ours_4x.view_settings.view_transform]
out["guard"] = refusals
out["artist_compositor_after_guard"] = compositor(bpy.context.scene)
"""


@pytest.fixture(scope="module")
def artist(tmp_path_factory):
    if not ASSET.is_file():
        pytest.skip(f"the corpus asset {ASSET} is not here")
    tmp = tmp_path_factory.mktemp("artist_scene")
    zip_path, tiny, user = extension_and_models(tmp)
    session = PythonSession(env={"BLENDER_USER_RESOURCES": str(user)})
    try:
        setup = session.run(fill_in(SETUP, tmp, zip_path, tiny).replace("ASSET", repr(str(ASSET))))
        yield SimpleNamespace(run=session.run, tmp=tmp, setup=setup)
    finally:
        session.close()


@pytest.fixture(scope="module")
def operated(artist):
    out = artist.run(STEPS)
    (artist.tmp / "out.json").write_text(json.dumps(out, default=str))
    print("seconds per operator:", {k: v[1] for k, v in out["ops"].items()})
    return out


def test_every_operator_finishes_and_leaves_the_artists_scene_as_it_was(artist, operated):
    before = artist.setup["before"]
    assert before["engine"].startswith("BLENDER_EEVEE") and before["resolution"] == [1920, 1080, 100]
    assert before["colour"][0] == "AgX" and before["colour"][2] == 0.7 and before["scene_camera"] == "ArtistCam"
    assert "CompositorNodeGlare" in before["compositor"][1] and before["materials"]
    assert {k: v[0] for k, v in operated["ops"].items()} == {k: ["FINISHED"] for k in operated["ops"]}, operated["ops"]
    assert operated["changed"] == {k: {} for k in operated["ops"]}, operated["changed"]
    assert operated["window_scene"] == before["scene"]   # the window still shows the artist's scene


def test_the_composite_lives_in_scenefits_own_scene(operated):
    own = operated["composite_scene"]
    assert own is not None and own["tag"] == "composite"
    assert own["engine"] == "CYCLES" and own["film_transparent"] and own["view"] == "Standard"
    assert own["camera"] == "SceneFit Camera" and own["resolution"] == [64, 48] and own["has_asset"]
    assert "CompositorNodeAlphaOver" in own["compositor"][1]


def test_the_switch_brings_back_the_artists_materials_and_world(artist, operated):
    slots, world = operated["restored"]
    assert world == "Artist World"
    assert slots and all(name in artist.setup["asset"][2] for name in slots if name)


def test_an_artists_compositor_is_refused_on_either_api(artist, operated):
    out = artist.run(GUARD)
    guard = out["guard"]
    assert "SceneFit's composite scene only" in guard["artist_5"] and "SceneFit's composite scene only" in guard["artist_4x"]
    # SceneFit's own 4.x scene goes on to its own tree (the 4.x branch), after its film and view are set
    message, use_nodes, engine, view = guard["ours_4x"]
    assert message == "the 4.x tree was reached" and use_nodes and engine == "CYCLES" and view == "Standard"
    assert out["artist_compositor_after_guard"] == artist.setup["before"]["compositor"]
