"""The SceneFit N-panel (panels/main.py), the add-on preferences (panels/preferences.py) and the add-on's
translations (panels/translations.py)."""
import bpy

from . import main, preferences, thumbnail, translations
from .preferences import ADDON_PACKAGE

classes = preferences.classes + main.classes

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register_classes()
    translations.register()


def unregister() -> None:
    translations.unregister()
    thumbnail.clear_thumbnails()
    _unregister_classes()


__all__ = ["ADDON_PACKAGE", "classes", "register", "unregister"]
