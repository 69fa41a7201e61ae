"""A new Blender World lit by an estimated HDR map (the user's worlds are never modified).

Node setup: Texture Coordinate (Generated: the ray direction) -> Mapping (rotation, 0 by default:
the artist turns the light with its Z) -> Environment Texture (the EXR, linear, equirectangular) ->
Background (strength) -> World Output. At rotation 0 Blender looks the map up with

    u = 0.5 - atan2(d.y, d.x) / 2pi,    v = atan2(d.z, hypot(d.x, d.y)) / pi + 0.5  (v from the bottom)

which is the convention core/render/renderer.py gives Mitsuba through ENVMAP_TO_WORLD, so the map lights the
asset from the same directions in both renderers (tests/blender/test_lighting_blender.py checks it).
"""
from __future__ import annotations

from pathlib import Path

from ..core.base.errors import InputError


MAPPING_NODE = "SceneFit Rotation"
BACKGROUND_NODE = "SceneFit Strength"


def world_controls(world):
    """(Mapping node, Background node) of a World made by world_from_hdr, else (None, None)."""
    if world is None or world.node_tree is None:
        return None, None
    nodes = world.node_tree.nodes
    return nodes.get(MAPPING_NODE), nodes.get(BACKGROUND_NODE)


def world_from_hdr(path: str | Path, name: str = "SceneFit Light", strength: float = 1.0):
    """A NEW bpy World whose background is the equirectangular HDR map at `path`; returns it unassigned."""
    import bpy

    path = Path(path)
    if not path.is_file():
        raise InputError(f"The HDR map '{path}' does not exist; run the light stage first.")
    image = bpy.data.images.load(str(path), check_existing=False)
    image.colorspace_settings.name = "Linear Rec.709" if "Linear Rec.709" in _colorspaces(image) else \
        image.colorspace_settings.name
    world = bpy.data.worlds.new(name)
    world.use_nodes = True
    tree = world.node_tree
    tree.nodes.clear()
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    env.projection = "EQUIRECTANGULAR"
    env.interpolation = "Linear"
    env.location = (-300, 0)
    coords = tree.nodes.new("ShaderNodeTexCoord")
    coords.location = (-900, 0)
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.name = mapping.label = MAPPING_NODE
    mapping.location = (-700, 0)
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    background = tree.nodes.new("ShaderNodeBackground")
    background.name = background.label = BACKGROUND_NODE
    background.inputs["Strength"].default_value = float(strength)
    output = tree.nodes.new("ShaderNodeOutputWorld")
    output.location = (250, 0)
    tree.links.new(env.outputs["Color"], background.inputs["Color"])
    tree.links.new(background.outputs["Background"], output.inputs["Surface"])
    return world


def assign_world(scene, world) -> None:
    """Make `world` the scene's world; the artist's previous one gets a fake user so saving does not purge it
    (a SceneFit World replaced gets none: a run that keeps it holds it, else Purge takes it and its map)."""
    from .tag import TAG

    previous = scene.world
    if previous is not None and previous != world and TAG not in previous:
        previous.use_fake_user = True
    scene.world = world


def _colorspaces(image) -> set[str]:
    try:
        return {item.identifier for item in image.colorspace_settings.bl_rna.properties["name"].enum_items}
    except Exception:  # enum lookup differs across versions: keep whatever Blender chose for EXR (linear)
        return set()
