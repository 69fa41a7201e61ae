"""Per-scene SceneFit settings (what the panel edits) and the results they point to.

Runtime state (progress, the running job) is on the WindowManager (operators/jobs.py), not here:
only the artist's choices and the datablocks SceneFit made are saved with the .blend.
"""
import math

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty,
                       PointerProperty, StringProperty)

from ..core.pipeline.presets import PRESET_DESCRIPTIONS, PRESET_NAMES
from .asset import asset_owner, texture_mesh_digest
from .photo import remember_photo_size
from ..core.scene.camera import DEFAULT_FOV_DEG, DEFAULT_PITCH_DEG
from ..core.scene.placement import DEFAULT_AT, DEFAULT_OBJECT_SIZE

PRESETS = tuple((name, name.capitalize(), PRESET_DESCRIPTIONS[name]) for name in PRESET_NAMES)
SCENE_TYPES = (
    ("auto", "Auto", "Decide from the photo (sky at the top: outdoor)"),
    ("indoor", "Indoor", "A room: the unseen walls are completed from depth"),
    ("outdoor", "Outdoor", "Open sky: the unseen map is completed by outpainting or the sky/ground prior"),
)
CAMERA_SOURCES = (
    ("estimate", "From the photo", "Estimated from the photo's lines and EXIF (Match Camera shows what was found)"),
    ("panel", "As set here", "The field of view, pitch and roll below"),
)
SUN_SOURCES = (
    ("estimate", "From the photo", "Guessed from the photo: behind the camera, turned towards its brighter side "
                                   "(set it, or Pick Sun from a shadow, for a truer light)"),
    ("set", "As set here", "The azimuth and elevation below (Pick Sun sets them from a shadow in the photo, "
                           "Sun from Light from a Sun light turned until its shadows match the photo's)"),
)
GUIDANCE = (("auto", "Auto", "Adapt with Stable Diffusion 2 when its weights are on this machine and there is a "
                               "prompt; else compose the converted texture (Download in the add-on's preferences "
                               "fetches them)"),
            ("sd2", "Stable Diffusion 2", "Adapt; fail in one sentence when the weights are not on this machine "
                                          "(Download in the add-on's preferences fetches them)"),
            ("none", "None", "No adaptation: compose the converted texture (seconds instead of hours)"))
MODES = (
    ("scene", "Scene", "Restyle the asset so it fits the photo (the prompt describes how it should look there)"),
    ("generate", "Generate", "Make a new texture from the prompt alone"),
    ("edit", "Edit", "Change the asset by an instruction ('add dust to the sofa')"),
)


def _path_options() -> set[str]:
    """'//' (relative to the .blend) is accepted in path settings; Blender 4.5+ asks for it explicitly, and
    older ones refuse the flag when the class registers (StringProperty() itself only defers it)."""
    if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties.keys():
        return {"PATH_SUPPORTS_BLEND_RELATIVE"}
    return set()


PATH = _path_options()


def _sun_typed(settings, _context) -> None:
    """A direction typed in is as sure as it was typed: an earlier Pick Sun's uncertainty no longer applies
    (Pick Sun sets the direction first and its own uncertainty after). One the artist typed stays: it
    says how sure they are of whatever direction they set."""
    if settings.sun_uncertainty_picked and settings.sun_uncertainty != 0.0:
        settings.sun_uncertainty = 0.0


def _uncertainty_typed(settings, _context) -> None:
    """An uncertainty set by hand is the artist's own, which later nudges of the angles keep (set_sun marks
    a pick's after setting it)."""
    if settings.sun_uncertainty_picked:
        settings.sun_uncertainty_picked = False


class SceneFitSlot(bpy.types.PropertyGroup):
    """One material slot a result went to: what it held before (the artist's), SceneFit's latest material
    there, and the job that made it (the Results switch acts on the selection's slots, else the last job's)."""

    asset_object: PointerProperty(name="Object", type=bpy.types.Object, description="The object whose slot it is")
    slot: IntProperty(name="Slot", min=0, description="Which of its material slots")
    original: PointerProperty(name="Original material", type=bpy.types.Material, description="The material that was in the slot before SceneFit's")
    result: PointerProperty(name="SceneFit material", type=bpy.types.Material, description="SceneFit's latest material for the slot")
    job: IntProperty(name="Job", min=0, description="Which result this is: a later job has a higher number")


RUN_STATES = (("finished", "Finished", "The run finished; Apply puts its results in the asset's slots and World"),
              ("cancelled", "Cancelled", "The run was cancelled; Resume continues it from its finished stages and checkpoint"),
              ("failed", "Failed", "The run failed; Resume continues it from the stages it finished"))


class SceneFitRun(bpy.types.PropertyGroup):
    """One run on an asset (the Results section's history): where its files are, what it was asked, what it made."""

    folder: StringProperty(name="Folder", subtype="DIR_PATH", options=PATH,
                           description="The run's folder (a cancelled adaptation's work waits beside it, hidden)")
    stage: StringProperty(name="Stage", description="Which button made it: run, convert or adapt")
    preset: StringProperty(name="Preset", description="The quality preset it ran at")
    prompt: StringProperty(name="Prompt", description="The prompt it was given")
    when: StringProperty(name="Time", description="When the run ended")
    state: EnumProperty(name="State", items=RUN_STATES, default="finished", description="How the run ended")
    composite: PointerProperty(name="Composite", type=bpy.types.Image, description="Its composite picture")
    world: PointerProperty(name="World", type=bpy.types.World, description="The World (light) it made")
    slots: CollectionProperty(name="Slots", type=SceneFitSlot, description="The material slots its materials went to")
    texture_path: StringProperty(name="Neural texture", subtype="FILE_PATH", options=PATH, description="The texture it made (texture.pt)")
    mesh_digest: StringProperty(name="Mesh", options={"HIDDEN"}, description="Which mesh its texture was made for")
    iterations: IntProperty(name="Iterations", min=0, options={"HIDDEN"}, description="Restyling steps it was asked for (Resume goes on with them)")
    model_resolution: IntProperty(name="Model resolution", min=0, options={"HIDDEN"}, description="Image size its diffusion model worked at")
    render_size: IntProperty(name="Render size", min=0, options={"HIDDEN"}, description="Size of the views of the asset it looked at")


def _texture_typed(state, _context) -> None:
    """A texture path set by hand names the mesh it was made for when SceneFit made it (any asset's run)."""
    digest = texture_mesh_digest(state.texture_path)
    if state.texture_mesh != digest:
        state.texture_mesh = digest


class SceneFitAsset(bpy.types.PropertyGroup):
    """What belongs to one asset (on its object, or its selection's root): switching the active object
    switches these. The Scene and Style sections' Prompt, Placement, Size and the texture read and write them."""

    prompt: StringProperty(name="Prompt", description="How the asset should look, e.g. 'a leather sofa, soggy and "
                                                      "stained with mud'")
    placement: FloatVectorProperty(name="Placement", size=2, min=0.0, max=1.0, default=DEFAULT_AT,
                                   description="Where the asset stands in the photo: x from the left, y from "
                                               "the top, as fractions (Pick Placement sets it by a click)")
    size: FloatProperty(name="Size", min=0.02, max=1.0, default=DEFAULT_OBJECT_SIZE, subtype="FACTOR",
                        description="The asset's height as a fraction of the photo's height")
    turn: FloatProperty(name="Turn", subtype="ANGLE", default=0.0, min=-math.pi, max=math.pi,
                        description="How far the asset is turned about its up axis, seen from the photo's camera")
    texture_path: StringProperty(name="Neural texture", subtype="FILE_PATH", options=PATH, update=_texture_typed,
                                 description="texture.pt of this asset's last conversion or adaptation (adapt and "
                                             "Bake Asset start here)")
    texture_mesh: StringProperty(name="Texture's mesh", options={"HIDDEN"},
                                 description="Which mesh the texture was made for (a texture of another is refused)")
    runs: CollectionProperty(name="Runs", type=SceneFitRun, description="Every run on this asset, finished, cancelled or failed")
    run_index: IntProperty(name="Run", min=0, description="The run chosen in the Results section's list")


PER_ASSET = ("prompt", "placement", "size", "turn", "texture_path")


def _holder(settings):
    """Where the per-asset values live: the active asset's state, else the scene's (no active object)."""
    owner = asset_owner(settings.id_data)
    return (owner.scenefit_asset, "") if owner is not None else (settings, "loose_")


def _per_asset(name: str) -> dict:
    def get(settings):
        holder, prefix = _holder(settings)
        value = getattr(holder, prefix + name)
        return tuple(value) if name == "placement" else value

    def set_(settings, value):
        holder, prefix = _holder(settings)
        setattr(holder, prefix + name, value)

    return {"get": get, "set": set_}


class SceneFitSettings(bpy.types.PropertyGroup):
    # Scene
    photo_path: StringProperty(name="Photo", subtype="FILE_PATH", options=PATH, description="Photo to fit the asset into",
                               update=lambda settings, _context: _photo_chosen(settings))
    # The active asset's own (SceneFitAsset); the loose_ ones hold them while no object is active.
    placement: FloatVectorProperty(name="Placement", size=2, min=0.0, max=1.0, **_per_asset("placement"),
                                   description="Where the asset stands in the photo: x from the left, y from "
                                               "the top, as fractions (Pick Placement sets it by a click)")
    size: FloatProperty(name="Size", min=0.02, max=1.0, subtype="FACTOR", **_per_asset("size"),
                        description="The asset's height as a fraction of the photo's height")
    turn: FloatProperty(name="Turn", subtype="ANGLE", min=-math.pi, max=math.pi, **_per_asset("turn"),
                        description="How far the asset is turned about its up axis, seen from the photo's camera")
    loose_placement: FloatVectorProperty(size=2, min=0.0, max=1.0, default=DEFAULT_AT, options={"HIDDEN"}, description="Placement while no object is active")
    loose_size: FloatProperty(min=0.02, max=1.0, default=DEFAULT_OBJECT_SIZE, options={"HIDDEN"}, description="Size while no object is active")
    loose_turn: FloatProperty(default=0.0, options={"HIDDEN"}, description="Turn while no object is active")
    loose_prompt: StringProperty(options={"HIDDEN"}, description="Prompt while no object is active")
    loose_texture_path: StringProperty(options={"HIDDEN"} | PATH, subtype="FILE_PATH", description="Texture while no object is active")
    scene_type: EnumProperty(name="Scene type", items=SCENE_TYPES, default="auto", description="Indoor or outdoor: how the light beyond the photo's edges is completed")
    camera_from: EnumProperty(name="Camera", items=CAMERA_SOURCES, default="estimate",
                              description="Where the photo's camera comes from when the scene's camera does not "
                                          "show the photo")
    fov: FloatProperty(name="Field of view", subtype="ANGLE", default=math.radians(DEFAULT_FOV_DEG), min=0.1,
                       max=2.8, description="The photo's horizontal field of view")
    pitch: FloatProperty(name="Pitch", subtype="ANGLE", default=math.radians(DEFAULT_PITCH_DEG), min=-1.5, max=1.5,
                         description="Where the photo's camera looks above the horizon (negative: down)")
    roll: FloatProperty(name="Roll", subtype="ANGLE", default=0.0, min=-0.8, max=0.8,
                        description="How far the photo's camera is turned counter-clockwise about its view (the "
                                    "horizon then appears turned clockwise)")
    sun_from: EnumProperty(name="Sun", items=SUN_SOURCES, default="estimate",
                           description="Where the dominant light comes from")
    sun_azimuth: FloatProperty(name="Azimuth", subtype="ANGLE", default=0.0, min=-math.pi, max=math.pi,
                               description="The sun's direction from the photo's view, positive to the right "
                                           "(90°: from the right, 180°: from behind the camera)",
                               update=_sun_typed)
    sun_elevation: FloatProperty(name="Elevation", subtype="ANGLE", default=math.radians(45.0), min=0.0,
                                 max=math.pi / 2, description="The sun's height above the horizon",
                                 update=_sun_typed)
    sun_uncertainty: FloatProperty(name="Uncertainty", subtype="ANGLE", default=0.0, min=0.0, max=math.pi / 2,
                                   description="How far off the sun's direction may be: Pick Sun sets how far a "
                                               "click slipping 2/640 of the photo's width turns it; typing a "
                                               "direction sets that back to 0 (sure); one typed here stays. The light "
                                               "around it widens from the narrow lobe at 15° to the guess's at 30°",
                                   update=_uncertainty_typed)
    # True by default: a file saved before this flag holds Pick Sun's uncertainty, which typing then reset.
    sun_uncertainty_picked: BoolProperty(name="Uncertainty from Pick Sun", default=True, options={"HIDDEN"},
                                         description="Whether Uncertainty is Pick Sun's (a typed direction "
                                                     "resets it) rather than the artist's (kept)")
    # Style
    mode: EnumProperty(name="Mode", items=MODES, default="scene", description="What the prompt asks for: fit the photo, a new look, or a change")
    prompt: StringProperty(name="Prompt", **_per_asset("prompt"),
                           description="How the asset should look, e.g. 'a leather sofa, soggy and stained with mud' "
                                       "(each asset keeps its own)")
    object_prompt: StringProperty(name="Object", description="What the asset is, e.g. 'a leather sofa' (edit mode, "
                                                             "and for Write Prompt)")
    scene_prompt: StringProperty(name="Scene", description="What the scene is, e.g. 'a swamp': Write Prompt turns the "
                                                           "object and scene into the prompt (a vision model reads the photo)")
    prompt_source: StringProperty(name="Prompt source", description="Who wrote the prompt: the language model or the "
                                                                    "offline template")
    instruction: StringProperty(name="Instruction", description="Edit mode: e.g. 'add dust to the sofa'")
    negative_prompt: StringProperty(name="Avoid", description="What the asset should not look like, e.g. 'blurry, "
                                                              "text' (the restyling steers away from it)")
    seed: IntProperty(name="Seed", default=-1, min=-1, description="The same seed gives the same texture again "
                                                                   "(-1: SceneFit's own for each step)")
    # Quality and output
    preset: EnumProperty(name="Preset", items=PRESETS, default="balanced", description="Draft is quick, Final is best; the times below say how long each takes")
    guidance: EnumProperty(name="Adaptation", items=GUIDANCE, default="auto",
                           description="Whether Run All restyles the texture with Stable Diffusion 2")
    output_dir: StringProperty(name="Output", subtype="DIR_PATH", options=PATH, default="//scenefit/",
                               description="Each run writes a new folder here ('//' is the .blend's folder)")
    # Results (datablocks SceneFit made, and the originals they replaced)
    result_material: PointerProperty(name="SceneFit material", type=bpy.types.Material, description="SceneFit's latest material")
    original_material: PointerProperty(name="Original material", type=bpy.types.Material, description="The material it replaced")
    result_object: PointerProperty(name="Asset", type=bpy.types.Object, description="The object the latest result went to")
    # Every slot of every object the last result went to (the Results section switches them all).
    result_slots: CollectionProperty(name="Result slots", type=SceneFitSlot, description="Every slot the latest result went to")
    runs_without_asset: CollectionProperty(name="Runs without asset", type=SceneFitRun,
                                           description="Runs whose asset was deleted while they ran (their folders "
                                                       "keep what they made)")
    result_world: PointerProperty(name="SceneFit World", type=bpy.types.World, description="SceneFit's latest World (the photo's light)")
    original_world: PointerProperty(name="Original World", type=bpy.types.World, description="The World it replaced")
    texture_path: StringProperty(name="Neural texture", subtype="FILE_PATH", options=PATH, **_per_asset("texture_path"),
                                 description="texture.pt of the active asset's last conversion or adaptation (adapt "
                                             "and Bake Asset start here)")
    light_path: StringProperty(name="Light", subtype="FILE_PATH", options=PATH, description="light.exr of the last estimate")
    composite_path: StringProperty(name="Composite", subtype="FILE_PATH", options=PATH, description="The last composite render")
    bake_path: StringProperty(name="Last bake", subtype="FILE_PATH", options=PATH,
                              description="The file Bake Asset wrote last")


def _photo_chosen(settings) -> None:
    """The photo's size and thumbnail read once when it is chosen (the panel draws from those, never from
    the file)."""
    from ..panels.thumbnail import load_thumbnail

    remember_photo_size(settings.photo_path)
    load_thumbnail(settings.photo_path)


classes = (SceneFitSlot, SceneFitRun, SceneFitAsset, SceneFitSettings)


def _import_marks() -> dict:
    """The marks an import leaves on its objects (blender_io/asset_file.py), as registered properties: kept
    out of the custom properties that exporters may write into the files the artist ships."""
    from ..blender_io.asset_file import IMPORT_PROPERTY, SOURCE_PROPERTY

    return {SOURCE_PROPERTY: StringProperty(name="Imported from", options={"HIDDEN"}, subtype="FILE_PATH",
                                            description="The file SceneFit's import mark says this object came from"),
            IMPORT_PROPERTY: StringProperty(name="Import", options={"HIDDEN"},
                                            description="Which import brought this object (SceneFit's mark)")}


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.scenefit = PointerProperty(type=SceneFitSettings)
    bpy.types.Object.scenefit_asset = PointerProperty(type=SceneFitAsset)
    for name, prop in _import_marks().items():
        setattr(bpy.types.Object, name, prop)


def unregister() -> None:
    for name in _import_marks():
        delattr(bpy.types.Object, name)
    del bpy.types.Object.scenefit_asset
    del bpy.types.Scene.scenefit
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
