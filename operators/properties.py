"""Per-scene SceneFit settings (what the N-panel edits)."""
import bpy
from bpy.props import EnumProperty, FloatProperty, FloatVectorProperty, PointerProperty, StringProperty

from ..core.placement import DEFAULT_AT
from ..core.presets import PRESET_DESCRIPTIONS, PRESET_NAMES

PRESETS = tuple((name, name.capitalize(), PRESET_DESCRIPTIONS[name]) for name in PRESET_NAMES)


class SceneFitSettings(bpy.types.PropertyGroup):
    photo_path: StringProperty(name="Photo", subtype="FILE_PATH", description="Photo to fit the asset into")
    placement: FloatVectorProperty(name="Placement", size=2, min=0.0, max=1.0, default=DEFAULT_AT,
                                   description="The asset's centre in the photo (x, y as fractions of width and "
                                               "height), as --at on the command line")
    elevation: FloatProperty(name="Elevation", subtype="ANGLE", default=0.0, min=-1.2, max=1.2,
                             description="Camera elevation above the asset's horizon")
    preset: EnumProperty(name="Preset", items=PRESETS, default="balanced")
    output_dir: StringProperty(name="Output", subtype="DIR_PATH", default="//scenefit/",
                               description="Folder for maps, renders and exported scenes")
    # Shown by the panel while a job runs.
    progress: FloatProperty(name="Progress", subtype="PERCENTAGE", min=0.0, max=100.0, default=0.0)
    status: StringProperty(name="Status", default="")


classes = (SceneFitSettings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.scenefit = PointerProperty(type=SceneFitSettings)


def unregister() -> None:
    del bpy.types.Scene.scenefit
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
