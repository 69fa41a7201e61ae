"""The SceneFit N-panel (panels/main.py) and the add-on preferences (panels/preferences.py)."""
import bpy

from . import main, preferences
from .preferences import ADDON_PACKAGE

classes = preferences.classes + main.classes

register, unregister = bpy.utils.register_classes_factory(classes)

__all__ = ["ADDON_PACKAGE", "classes", "register", "unregister"]
