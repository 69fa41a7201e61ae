"""Operator polls shared by the operators: a mesh is active, a scene setting is filled in."""
from __future__ import annotations


class OnMesh:
    """Operator mixin: available when the active object is a mesh (what every stage works on)."""

    @classmethod
    def poll(cls, context) -> bool:
        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            return True
        cls.poll_message_set("Select the asset: a mesh object")
        return False


class OnMeshWithPhoto(OnMesh):
    """Operator mixin: a mesh is active and the Scene section has a photo (Run All fits the asset into it)."""

    @classmethod
    def poll(cls, context) -> bool:
        if not super().poll(context):
            return False
        settings = getattr(context.scene, "scenefit", None)
        if settings is not None and settings.photo_path.strip():
            return True
        cls.poll_message_set("Pick a photo in the Scene section first")
        return False


def needs_setting(name: str, why: str) -> classmethod:
    """An operator poll: available when the scene's SceneFit setting `name` is filled in."""

    def poll(cls, context) -> bool:
        settings = getattr(context.scene, "scenefit", None)
        if settings is not None and bool(getattr(settings, name).strip()):
            return True
        cls.poll_message_set(why)
        return False

    return classmethod(poll)
