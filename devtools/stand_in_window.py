"""A job operator driven without a window (bpy has none): its own invoke / modal / execute code on a plain
object, a stand-in window manager and context, and the events a window would send. For the tests and the
main-thread bench, which measure what an artist's click and Blender's timer ticks hold."""
from __future__ import annotations

from types import SimpleNamespace


def probe(cls, package: str = "scenefit", **props):
    """The operator class's own methods and `props` on a plain object (Blender makes operator instances only for
    a window); what it reports is kept in `.reported`."""
    attrs: dict = {}
    for klass in reversed(cls.__mro__):
        if klass.__module__.startswith(package):
            attrs.update({k: v for k, v in vars(klass).items() if not k.startswith("__") and k != "bl_rna"})
    attrs.update(props, properties=SimpleNamespace(is_property_set=lambda name: name in props))
    op = type("Probe", (), attrs)()
    op.reported = []
    op.report = lambda kind, text: op.reported.append(text)
    return op


class WindowManager:
    """The window manager's calls a job operator makes; the runtime is Blender's own."""

    windows = ()

    def __init__(self) -> None:
        self.timers: list = []
        self.handlers: list = []
        self.dialogs: list = []

    @property
    def scenefit_runtime(self):
        import bpy

        return bpy.context.window_manager.scenefit_runtime

    def event_timer_add(self, seconds, window=None):
        self.timers.append(seconds)
        return len(self.timers)

    def event_timer_remove(self, timer) -> None:
        if self.timers:
            self.timers.pop()

    def modal_handler_add(self, op) -> None:
        self.handlers.append(op)


class Context:
    """bpy.context with a stand-in window (no areas) and window manager."""

    def __init__(self) -> None:
        self.window, self.window_manager = SimpleNamespace(screen=SimpleNamespace(areas=())), WindowManager()

    def __getattr__(self, name):
        import bpy

        return getattr(bpy.context, name)


def event(kind: str, x: int = 0, y: int = 0):
    return SimpleNamespace(type=kind, value="PRESS", mouse_x=x, mouse_y=y)
