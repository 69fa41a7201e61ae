"""Loading an asset from any file Blender reads (.blend, glTF, OBJ, FBX, PLY, USD).

An artist's open file is never reset or replaced: a .blend's object is appended, an import goes
into a temporary scene, the mesh and maps are read, and every datablock that arrived is removed
again. A background process that holds nothing but Blender's untouched startup file (the command
line, a batch worker, a test's fresh bpy) first empties it (factory settings, empty scene): the
startup Cube, Camera and Light would otherwise collide with the asset's own names ('Material'
read back as 'Material.001') and stand in the way of importers and bakes that use the context.
"""
from __future__ import annotations

import re
import tempfile
from contextlib import contextmanager
from typing import Callable
from pathlib import Path

from ..core.data.asset_io import check_asset_path
from ..core.base.errors import InputError
from ..core.data.gltf_meshopt import importable
from ..core.data.maps import PBRMaps
from ..core.data.materials import AssetMaterials
from ..core.data.mesh import Mesh
from ..core.base.quiet import native_output_captured
from .fbx_ascii import binary_copy, is_ascii_fbx
from .material import read_object_materials
from .scene_asset import read_scene_materials

IMPORTERS = {
    ".glb": ("import_scene", "gltf"), ".gltf": ("import_scene", "gltf"),
    ".obj": ("wm", "obj_import"), ".fbx": ("import_scene", "fbx"), ".ply": ("wm", "ply_import"),
    ".usd": ("wm", "usd_import"), ".usda": ("wm", "usd_import"), ".usdc": ("wm", "usd_import"),
    ".usdz": ("wm", "usd_import"),
}
# The kinds of datablock a load may add (and that are removed again afterwards).
_ID_COLLECTIONS = ("objects", "meshes", "materials", "images", "textures", "node_groups", "collections",
                   "cameras", "lights", "actions", "armatures", "curves", "worlds", "scenes", "libraries")


# What Blender's factory startup file holds, per kind of datablock (the rest are empty).
_STARTUP_NAMES = {"objects": {"Camera", "Cube", "Light"}, "meshes": {"Cube"}, "materials": {"Material", "Dots Stroke"},
                  "cameras": {"Camera"}, "lights": {"Light"}, "collections": {"Collection"}, "worlds": {"World"},
                  "scenes": {"Scene"}}
# Datablocks Blender makes by itself, present or not in a startup file.
_BLENDER_OWN = {"images": {"Render Result", "Viewer Node"}}


def _all_ids(bpy) -> set:
    return {id_ for name in _ID_COLLECTIONS for id_ in getattr(bpy.data, name)}


def holds_only_startup_file(bpy) -> bool:
    """True in a background process whose file is Blender's startup file, unsaved, with exactly its
    datablocks: nothing of anyone's is open, so it may be emptied before a load."""
    if not bpy.app.background or bpy.data.filepath:
        return False
    return all({id_.name for id_ in getattr(bpy.data, name)} - _BLENDER_OWN.get(name, set())
               == _STARTUP_NAMES.get(name, set()) for name in _ID_COLLECTIONS)


def empty_startup_file(bpy) -> None:
    """Replace Blender's startup file by an empty one where holds_only_startup_file (see the module's note)."""
    if holds_only_startup_file(bpy):
        with native_output_captured():
            bpy.ops.wm.read_factory_settings(use_empty=True)


def _empty_own_scene(bpy) -> bool:
    """True where the file is an unsaved, empty one in a background process (as empty_startup_file
    leaves it): its own scene is the empty scene to load into, and the output keeps its name."""
    return bool(bpy.app.background and not bpy.data.filepath and not bpy.data.objects and len(bpy.data.scenes) == 1)


@contextmanager
def _temporary_data(bpy):
    """The scene to load into, shown in the window while the block runs (importers and bakes act on
    the window's scene and its active object); on exit every datablock that arrived is removed.

    An empty background file lends its own scene; any other file gets a temporary scene."""
    empty_startup_file(bpy)
    before = _all_ids(bpy)
    scene = bpy.context.scene if _empty_own_scene(bpy) else bpy.data.scenes.new("SceneFit temporary import")
    window = bpy.context.window
    shown = window.scene if window is not None else None
    try:
        if window is not None:
            window.scene = scene
        yield scene
    finally:
        if window is not None and shown is not None:
            window.scene = shown
        added = [id_ for id_ in _all_ids(bpy) if id_ not in before]
        bpy.data.batch_remove(added)


def _import_into(bpy, scene, path: Path, suffix: str) -> None:
    """Blender's importer for `suffix` reading `path` into `scene`; scene None: into the context's
    scene and active collection, as File > Import does."""
    module, op = IMPORTERS[suffix]
    if module == "import_scene":
        import addon_utils

        addon_utils.enable("io_scene_gltf2" if "gltf" in suffix or suffix == ".glb" else "io_scene_fbx",
                           default_set=False)
    importer = getattr(getattr(bpy.ops, module), op)
    if scene is None:
        importer(filepath=str(path))
        return
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0],
                                   collection=scene.collection):
        importer(filepath=str(path))


def _read_or_sentence(path: Path, read: Callable[[], None]) -> None:
    """`read()` (Blender importing or appending `path` or its readable copy) with its chatter kept off the
    terminal; a failure is one sentence (InputError) naming `path`."""
    suffix = path.suffix.lower()
    # Blender's importers print to the terminal and raise RuntimeError on a broken file: their
    # chatter is kept off the user's terminal and serves as the error's reason.
    with native_output_captured() as chatter:
        try:
            read()
            return
        except (RuntimeError, ValueError, OSError, UnicodeDecodeError) as error:
            failure = error
    reason = _blender_reason(failure) or chatter.last_line() or "Blender could not read it"
    missing = re.search(r"Extension (\S+) is not available", reason)
    if missing:  # a valid file: Blender's importer lacks what it requires
        raise InputError(f"Asset file '{path}' requires the glTF extension {missing.group(1)}, which "
                         "Blender's importer does not read; write it without that extension (gltf-transform "
                         "or gltfpack can) and give that file.") from None
    raise InputError(f"Asset file '{path}' cannot be read ({reason}); check that it is a valid "
                     f"'{suffix}' file, or export it again.") from None


# What Import Asset reads: the files Blender's importers read, meshopt glTF and ASCII FBX included.
IMPORTABLE_SUFFIXES = tuple(IMPORTERS)
# The mark an import leaves on each object it brought: the file it came from, so Bake Asset can write the
# game asset as that file was written (compression, texture format, tangents) ...
SOURCE_PROPERTY = "scenefit_source_file"
# ... and which import it was (one id per import): a file imported twice gives two sets of cameras.
IMPORT_PROPERTY = "scenefit_import"
# Both are properties the add-on registers on Object (operators/properties.py), not custom properties: the
# artist's own exports with custom properties would write the file's absolute path into what they ship.


def mark_imported(obj, path: str | Path, import_id: str) -> None:
    """Mark `obj` as brought by the import `import_id` of the file `path` (Import Asset, and Blender's own
    File > Import of a glTF through the add-on's importer hook)."""
    if obj is not None:
        _set_mark(obj, SOURCE_PROPERTY, str(Path(path).resolve()))
        _set_mark(obj, IMPORT_PROPERTY, import_id)


def _set_mark(obj, key: str, value: str) -> None:
    if key in obj.bl_rna.properties:
        setattr(obj, key, value)
    else:   # (the add-on not registered: a plain bpy session, as the tests' and the command line's)
        obj[key] = value


def import_mark(obj, key: str) -> str | None:
    """An object's SOURCE_PROPERTY or IMPORT_PROPERTY, None when it has none (a .blend saved before the
    marks were registered properties keeps them as custom properties: read those too)."""
    value = getattr(obj, key, "") if key in obj.bl_rna.properties else ""
    if not value:
        value = obj.get(key)
    return value if isinstance(value, str) and value else None


class GltfImportMark:
    """Blender's glTF importer calls an enabled add-on's `glTF2ImportUserExtension` for every node it makes
    (one instance per import): each object of a File > Import of a glTF is marked as Import Asset marks its
    own, so Bake Asset's As imported and Cameras and Lights work for the artist's usual import too."""

    def __init__(self) -> None:
        import uuid

        self.import_id = uuid.uuid4().hex

    def gather_import_node_after_hook(self, vnode, gltf_node, blender_object, gltf) -> None:
        # (several files in one import share the instance: the file's path keeps their objects apart)
        mark_imported(blender_object, gltf.filename, f"{self.import_id}:{Path(gltf.filename).name}")


def imported_from(objects: list) -> Path | None:
    """The file Import Asset read most of `objects` from (the first such file on a tie), if it is still there:
    a selection that mixes two imports is written as the file most of it came from."""
    from collections import Counter

    sources = [import_mark(obj, SOURCE_PROPERTY) for obj in objects]
    counts = Counter(s for s in sources if s and Path(s).is_file())
    return Path(counts.most_common(1)[0][0]) if counts else None   # (most_common keeps the first of a tie)


# What an asset file holds beside its geometry and is written with it when it came from the same file.
BESIDE_TYPES = ("CAMERA", "LIGHT")


def imported_beside(objects: list, scene_objects, source: Path | None) -> list:
    """The cameras and lights among `scene_objects` that the import of the file the asset is written as
    (`source`, imported_from(objects): most of them came from it) brought: the file's own (the diorama's
    camera and sun), not the artist's, another file's, nor those of a second import of the same file."""
    if source is None:
        return []
    mine = [o for o in objects if import_mark(o, SOURCE_PROPERTY) == str(source)]
    imports = {import_mark(o, IMPORT_PROPERTY) for o in mine} - {None}
    # (objects imported before imports had ids: by the file alone)
    key, wanted = (IMPORT_PROPERTY, imports) if imports else (SOURCE_PROPERTY, {str(source)})
    return sorted((o for o in scene_objects if o.type in BESIDE_TYPES and o not in objects
                   and import_mark(o, key) in wanted), key=lambda o: o.name)


def import_into_open_scene(path: str | Path) -> list:
    """The objects of the asset file `path`, imported into the open scene's active collection as
    File > Import does (selected, one of them active; each marked with SOURCE_PROPERTY), including what
    Blender's own importers refuse: a meshopt-compressed glTF is decoded and an ASCII FBX written as
    binary first. Images the import read from such a temporary copy's folder are packed into the
    .blend, so they outlive it. Nothing that was there before is changed; a file that cannot be read
    is one sentence (InputError)."""
    import bpy

    path = Path(path)
    check_asset_path(path)
    suffix = path.suffix.lower()
    if path.is_dir() or suffix not in IMPORTERS:
        raise InputError(f"Import Asset reads {', '.join(IMPORTABLE_SUFFIXES)} files, not '{path.name}'; "
                         "use File > Append for a .blend file.")
    before, ids_before = set(bpy.data.objects), _all_ids(bpy)
    images_before = set(bpy.data.images)
    try:
        with _readable(path) as readable:
            _read_or_sentence(path, lambda: _import_into(bpy, None, readable, readable.suffix.lower()))
            if readable != path:   # read from a temporary copy, whose folder is gone after this block
                _pack_images_from(bpy, set(bpy.data.images) - images_before, readable.parent, path)
    except InputError:   # an import that failed part way leaves nothing behind
        bpy.data.batch_remove([id_ for id_ in _all_ids(bpy) if id_ not in ids_before])
        raise
    objects = sorted((o for o in bpy.data.objects if o not in before), key=lambda o: o.name)
    import uuid

    this_import = uuid.uuid4().hex
    for obj in objects:   # (over the hook's marks, which name a temporary copy where one was read)
        mark_imported(obj, path, this_import)
    return objects


def _pack_images_from(bpy, images, folder: Path, path: Path) -> None:
    """Pack the `images` read from `folder` (a temporary copy's), so they outlive it."""
    folder = folder.resolve()
    for image in images:
        file = Path(bpy.path.abspath(image.filepath)).resolve() if image.filepath else None
        if image.packed_file is None and file is not None and file.is_file() and file.is_relative_to(folder):
            try:
                image.pack()
            except RuntimeError as error:
                raise InputError(f"The image '{image.name}' of '{path.name}' could not be kept in the .blend "
                                 f"({_blender_reason(error)}); check the file's images.") from None


@contextmanager
def _readable(path: Path):
    """`path`, or while the block runs a copy Blender's importers read: a meshopt-compressed glTF
    decoded, an ASCII FBX written as binary FBX (its importer reads only binary)."""
    if not is_ascii_fbx(path):
        with importable(path) as readable:
            yield readable
        return
    with tempfile.TemporaryDirectory(prefix="scenefit-fbx-") as folder:
        yield binary_copy(path, Path(folder) / path.name)


def _blender_reason(error: Exception) -> str:
    """The last meaningful line of a Blender operator error (they carry the importer's traceback)."""
    lines = [line for line in str(error).splitlines() if line.strip()]
    lines = [line.strip() for line in lines if not line.startswith((" ", "\t"))
             and not line.startswith(("Traceback", "Location:", "Error: Python: Traceback"))]
    reason = lines[-1].removeprefix("Error:").strip() if lines else ""
    reason = re.sub(r"^[A-Za-z_][\w.]*(Error|error|Exception): ", "", reason)
    return reason[:200]


def blend_external_files(path: str | Path) -> list[Path]:
    """The files a .blend's images read from disk (not packed into it), as absolute paths: its images are
    linked for the look and removed again, so the open file is neither reset nor left changed (the open
    file itself, which Blender cannot link from, is read from what it holds)."""
    import os

    import bpy

    before = {id_ for id_ in (*bpy.data.images, *bpy.data.libraries)}
    try:
        if bpy.data.filepath and Path(bpy.path.abspath(bpy.data.filepath)).resolve() == Path(path).resolve():
            images = [image for image in bpy.data.images if image.library is None]   # the open file's own
        else:
            try:
                with native_output_captured(), bpy.data.libraries.load(str(path), link=True) as (source, target):
                    target.images = list(source.images)
            except (OSError, RuntimeError, ValueError) as error:
                raise InputError(f"Blender cannot read '{path}' ({_blender_reason(error)}); open it in Blender "
                                 "and save it again.") from None
            images = target.images
        files = []
        for image in images:
            if image is None or image.packed_file is not None or image.source not in ("FILE", "SEQUENCE", "TILED"):
                continue
            if image.filepath:   # ('//' is the .blend's folder: the asset's, however the open file was reached)
                relative = image.filepath.startswith("//") and image.library is None
                named = Path(os.path.normpath(Path(path).parent / image.filepath[2:] if relative else
                                              bpy.path.abspath(image.filepath, library=image.library)))
                files += _tiles_or_frames(named, image.source) if image.source != "FILE" else [named]
        return sorted(set(files))
    finally:
        bpy.data.batch_remove([id_ for id_ in (*bpy.data.images, *bpy.data.libraries) if id_ not in before])


def _tiles_or_frames(named: Path, source: str) -> list[Path]:
    """A UDIM image's tiles (its name holds '<UDIM>' or a tile number) or an image sequence's frames: the
    files beside `named` that differ from it only in those digits."""
    name = named.name
    if "<UDIM>" in name or "<UVTILE>" in name:   # the tile number's own place
        pattern = re.compile("^" + re.escape(name).replace(re.escape("<UDIM>"), r"\d{4}")
                             .replace(re.escape("<UVTILE>"), r"u\d+_v\d+") + "$")
    else:
        match = list(re.finditer(r"\d+", name))
        if not match:
            return [named]
        last = match[-1]
        pattern = re.compile("^" + re.escape(name[:last.start()]) + r"\d+" + re.escape(name[last.end():]) + "$")
    return [p for p in named.parent.glob("*") if pattern.match(p.name)] if named.parent.is_dir() else []


def _append_blend(bpy, scene, path: Path, object_name: str | None) -> None:
    """Every object of the file (a named one's children come with it; the others are left out later)."""
    with bpy.data.libraries.load(str(path), link=False) as (source, target):
        names = list(source.objects)
        if object_name is not None and object_name not in names:
            raise InputError(f"No object '{object_name}' in '{path.name}'; objects: {', '.join(names) or 'none'}.")
        target.objects = names
    for obj in target.objects:
        if obj is not None:
            scene.collection.objects.link(obj)


def _asset_node_names(scene) -> list[str]:
    """What --object can name: the mesh objects and every node with meshes under it."""
    return sorted(o.name for o in scene.objects
                  if o.type == "MESH" or any(c.type == "MESH" for c in o.children_recursive))


def load_asset(path: str | Path, object_name: str | None = None) -> tuple[Mesh, PBRMaps]:
    """(Mesh, PBRMaps) from an asset folder (read without Blender) or from a file Blender reads."""
    from ..core.data.asset_io import is_asset_folder, load_asset_folder

    return load_asset_folder(path) if is_asset_folder(path) else load_asset_file(path, object_name)


def load_asset_file(path: str | Path, object_name: str | None = None) -> tuple[Mesh, PBRMaps]:
    """The asset (the file's meshes, or the named node's) and its maps; several materials come as
    one atlas (see AssetMaterials.fitting_view)."""
    return load_asset_materials(path, object_name).fitting_view()


def load_asset_materials(path: str | Path, object_name: str | None = None) -> AssetMaterials:
    """The asset's mesh in world space with every material its faces use: every mesh of the file, or
    the named node and the meshes under it; an asset folder (read without Blender) as its one material."""
    from ..core.data.asset_io import is_asset_folder, load_asset_folder
    from ..core.data.materials import Material

    if is_asset_folder(path):
        mesh, maps = load_asset_folder(path)
        return AssetMaterials(mesh=mesh, materials=(Material(name=mesh.name, maps=maps,
                                                             read=(f"asset folder '{path}'",)),))
    import bpy

    from .material import unwrap_vertex_coloured

    with loaded_asset(path, object_name) as (meshes, scene):
        unwrap_vertex_coloured(meshes)   # (vertex colours without UVs: the temporary copy gets a UV map)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        if len(meshes) > 1:
            return read_scene_materials(meshes, depsgraph, object_name or Path(path).stem,
                                        "the whole scene" if object_name is None else f"'{object_name}'")
        # With its node's world transform: a painting stood upright by its node stands upright, a
        # mirrored node stays mirrored, as the baked file (which keeps the transforms) shows it.
        return read_object_materials(meshes[0], depsgraph, space="world")


@contextmanager
def loaded_asset(path: str | Path, object_name: str | None = None):
    """(the asset's mesh objects, temporary scene), with the context pointing at that scene, while the
    block runs: every mesh object of the file, or with `object_name` that object (a mesh, or a node
    such as an empty) and the mesh objects under it. Everything the load brought is removed
    afterwards (see the module's note)."""
    import bpy

    path = Path(path)
    check_asset_path(path)
    if path.is_dir():   # an asset folder is read without Blender (core.asset_io), never imported
        raise InputError(f"'{path}' is a SceneFit asset folder, not a file Blender reads.")
    with _temporary_data(bpy) as scene, _readable(path) as readable:
        if path.suffix.lower() == ".blend":
            _read_or_sentence(path, lambda: _append_blend(bpy, scene, path, object_name))
        else:
            _read_or_sentence(path, lambda: _import_into(bpy, scene, readable, readable.suffix.lower()))
        meshes = asset_meshes(scene, object_name, path)
        with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0]):
            yield meshes, scene


def asset_meshes(scene, object_name: str | None, path: Path) -> list:
    """The mesh objects that make the asset, in a fixed order: all of the scene's, or the named
    object's (itself when a mesh, and every mesh under it: a bike's frame, wheels and chain)."""
    meshes = sorted((o for o in scene.objects if o.type == "MESH"), key=lambda o: o.name)
    if object_name is None:
        if not meshes:
            raise InputError(f"'{path.name}' holds no mesh object.")
        return meshes
    # (a name the importer had to change gets Blender's ".001": the file's own name still finds it)
    named = next((o for o in scene.objects if o.name == object_name), None) or next(
        (o for o in scene.objects if o.name.startswith(object_name + ".")), None)
    taken = [] if named is None else [o for o in [named, *named.children_recursive] if o.type == "MESH"]
    if not taken:
        what = f"No object '{object_name}' in '{path.name}'" if named is None else \
            f"'{object_name}' in '{path.name}' is a {named.type.lower()} object with no mesh under it"
        names = ", ".join(_asset_node_names(scene)) or "none"
        raise InputError(f"{what}; give one of its mesh objects or a node above them: {names}.")
    return sorted(taken, key=lambda o: o.name)
