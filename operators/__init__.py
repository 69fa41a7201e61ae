"""Operators: gather inputs from Blender, run core on them, write results back as new data."""
from . import convert, export, properties

_modules = (properties, export, convert)
classes = tuple(cls for module in _modules for cls in module.classes)


def register() -> None:
    for module in _modules:
        module.register()


def unregister() -> None:
    for module in reversed(_modules):
        module.unregister()
