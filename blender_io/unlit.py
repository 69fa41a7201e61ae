"""KHR_materials_unlit as Blender's glTF importer builds it: no Principled BSDF, an Emission (or
Background) shader mixed with a Transparent BSDF by Light Path's Is Camera Ray. SceneFit reads it
as a surface whose Base Color is the emission colour; Blender's exporter finds the same setup and
writes the material unlit again, with whatever image the bake links into that colour."""
from __future__ import annotations

from dataclasses import dataclass, field

# Stand-ins for the inputs an unlit material has none of: rough, not metallic, opaque, no emission.
_STAND_INS = {"Roughness": 1.0, "Metallic": 0.0, "Alpha": 1.0, "Normal": (0.0, 0.0, 0.0), "Emission Strength": 0.0,
              "Emission Color": (0.0, 0.0, 0.0, 1.0)}
_SHADERS = ("EMISSION", "BACKGROUND")


@dataclass
class StandInSocket:
    """An input the unlit setup lacks, unlinked with a fixed value (what SceneFit reads and writes)."""

    name: str
    default_value: object
    is_linked: bool = False
    links: tuple = ()


class _Inputs:
    """Sockets by name, iterated as values (as a node's inputs are)."""

    def __init__(self, sockets: dict) -> None:
        self._sockets = sockets

    def __getitem__(self, name: str):
        return self._sockets[name]

    def get(self, name: str, default=None):
        return self._sockets.get(name, default)

    def __iter__(self):
        return iter(self._sockets.values())


@dataclass
class UnlitSurface:
    """The unlit setup seen through a Principled BSDF's inputs: Base Color is the shader's Color."""

    shader: object
    inputs: _Inputs = field(init=False)
    unlit: bool = True

    def __post_init__(self) -> None:
        sockets = {name: StandInSocket(name, value) for name, value in _STAND_INS.items()}
        sockets["Base Color"] = self.shader.inputs["Color"]
        self.inputs = _Inputs(sockets)

    @property
    def name(self) -> str:
        return self.shader.name

    @property
    def location(self):
        return self.shader.location


def unlit_surface(tree) -> UnlitSurface | None:
    """The unlit setup behind the tree's output (through Mix Shaders), or None when there is none."""
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    if output is None or not output.inputs["Surface"].is_linked:
        return None
    queue = [output.inputs["Surface"].links[0].from_node]
    while queue:
        node = queue.pop(0)
        if node.type in _SHADERS:
            return UnlitSurface(node)
        if node.type == "MIX_SHADER":
            queue.extend(s.links[0].from_node for s in node.inputs[1:] if s.is_linked)
    return None
