"""Operators: gather inputs from Blender, run core on them (as background jobs), write results back as new data."""
from . import (adapt, bake, camera, compose, convert, details, export, history, import_asset, jobs, light, models,
               placement, prompt, properties, results, run, sun, uv_map)

_modules = (properties, jobs, results, import_asset, placement, camera, sun, export, convert, light, prompt, adapt, compose,
            run, bake, history, details, models, uv_map)
classes = tuple(cls for module in _modules for cls in module.classes)


def register() -> None:
    for module in _modules:
        module.register()


def unregister() -> None:
    for module in reversed(_modules):
        module.unregister()
