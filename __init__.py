"""SceneFit: restyle a textured asset to fit a photo, light it like the photo, composite it.

Blender entry point. Nothing here imports bpy at import time, so `import scenefit.core` works in a
plain Python (tests, the command line); register() loads the Blender-facing modules lazily.
Installed by Blender this package is `bl_ext.<repo>.scenefit`, hence relative imports throughout.
"""

# Order matters: operators before the panels that draw their buttons; reversed on unregister.
_MODULE_NAMES = ("operators", "panels")


def _modules():
    import importlib

    return [importlib.import_module(f".{name}", __package__) for name in _MODULE_NAMES]


def glTF2ImportUserExtension():
    """Blender's glTF importer calls this name in every enabled add-on, once per import: File > Import of a
    glTF marks the objects it makes with their file (blender_io.asset_file.GltfImportMark), for Bake Asset."""
    from .blender_io.asset_file import GltfImportMark

    return GltfImportMark()


def register() -> None:
    for module in _modules():
        module.register()


def unregister() -> None:
    for module in reversed(_modules()):
        module.unregister()
