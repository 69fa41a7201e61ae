"""An asset file as a scene (issue 23): every mesh object with its world transform, as one mesh whose
material_index numbers the distinct materials of all of them. A bike is its frame, wheels and chain,
not the object with the most faces; compose places and lights the whole, and bake re-textures
every object's materials and writes the whole scene back.

Objects that cannot be textured (no faces, no material) are left out of the texture and
named in the notes; the exporter still writes them unchanged."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import InputError
from ..core.data.materials import AssetMaterials
from ..core.data.mesh import Mesh
from .material import object_mesh_and_slots, read_material


@dataclass
class SceneMesh:
    """All mesh objects of a scene as one mesh: `materials[i]` is material i's datablock, and
    `users[i]` the (object, slot) it is read through (its first user)."""

    mesh: Mesh
    materials: list
    users: list[tuple[object, int]]
    objects: list[str]
    notes: list[str]


def scene_mesh(objects, depsgraph, name: str, strict: bool = False) -> SceneMesh:
    """The mesh objects `objects` in world space, one mesh; materials shared by objects counted once.
    strict: an object that cannot be textured is refused (the objects the artist chose in Blender)
    instead of left out with a note (an asset file's scene)."""
    parts, materials, users, taken, notes = [], [], [], [], []
    index_of: dict[str, int] = {}
    for obj in sorted(objects, key=lambda o: o.name):   # a fixed order: convert and bake read alike
        try:
            mesh, slots = object_mesh_and_slots(obj, depsgraph, space="world")
        except InputError as error:
            if strict:
                raise
            notes.append(f"object '{obj.name}' is left as it is ({error})")
            continue
        local = []
        for slot in slots:
            material = obj.material_slots[slot].material
            if material.name not in index_of:
                index_of[material.name] = len(materials)
                materials.append(material)
                users.append((obj, slot))
            local.append(index_of[material.name])
        raw = np.zeros(len(mesh.faces), np.int32) if mesh.material_index is None else mesh.material_index
        parts.append((mesh, np.asarray(local, np.int32)[raw]))
        taken.append(obj.name)
    if not parts:
        raise InputError(f"No mesh object of '{name}' can be textured ({'; '.join(notes)}).")
    return SceneMesh(_joined(parts, name), materials, users, taken, notes)


def _joined(parts: list[tuple[Mesh, np.ndarray]], name: str) -> Mesh:
    offsets = np.cumsum([0] + [len(m.positions) for m, _ in parts])[:-1]
    positions = np.concatenate([m.positions for m, _ in parts])
    faces = np.concatenate([m.faces + o for (m, _), o in zip(parts, offsets)])
    uvs = np.concatenate([m.uvs for m, _ in parts])
    normals = None
    if all(m.normals is not None for m, _ in parts):
        normals = np.concatenate([m.normals for m, _ in parts])
    index = np.concatenate([i for _, i in parts])
    return Mesh.from_arrays(positions, faces, uvs, normals, name=name,
                            material_index=index if index.max() > 0 else None)


def read_scene_materials(objects, depsgraph, name: str, what: str = "the whole scene") -> AssetMaterials:
    """Several mesh objects as one asset (`what` says which: the whole scene, or a named node): their
    joined mesh and every material they use, read once each."""
    scene = scene_mesh(objects, depsgraph, name)
    materials = tuple(read_material(m, obj, slot) for m, (obj, slot) in zip(scene.materials, scene.users))
    notes = (f"{what}: {len(scene.objects)} mesh object(s) with their world transforms "
             f"({', '.join(scene.objects)})", *scene.notes)
    return AssetMaterials(mesh=scene.mesh, materials=materials, notes=notes)
