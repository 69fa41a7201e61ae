"""How `scenefit bake` writes its glTF: compression, texture format, the cap on texture size and
tangents. By default the output is compressed as the input is and its textures are in the input's
format, and it carries tangents where the input has them (a glTF without them leaves them to its
clients, which generate MikkTSpace ones; blender_io.gltf_export adds them for normal-mapped materials
of other kinds of file). Skinned meshes stay root nodes where the
input had them so, and always for inputs of other kinds (FBX, .blend): Blender parents a skinned mesh
to its armature, and glTF ignores a skinned mesh node's transform, so a parent only earns the
validator's NODE_SKINNED_MESH_NON_ROOT warning."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ...base.errors import InputError
from ...data.glb import gltf_json, read_gltf, write_glb
from .engine_targets import AS_IMPORTED, check_given, engine_target, keep_only_extensions, kept_extensions

COMPRESSIONS = ("none", "draco", "meshopt")
TEXTURE_FORMATS = ("png", "jpeg", "webp", "ktx2")
DEFAULT_MAX_TEXTURE = 2048
_COMPRESSION_OF_EXTENSION = {"KHR_draco_mesh_compression": "draco", "EXT_meshopt_compression": "meshopt"}
_FORMAT_OF_MIME = {"image/png": "png", "image/jpeg": "jpeg", "image/webp": "webp", "image/ktx2": "ktx2"}
MIME_OF_FORMAT = {name: mime for mime, name in _FORMAT_OF_MIME.items()}
# Blender's exporter compresses TANGENT inside the Draco data, where a degenerate UV triangle's zero tangent
# can be neither kept from the input nor mended: a Draco file goes without, and clients generate them.
DRACO_TANGENTS = ("the input's tangents are not written into Draco-compressed meshes: engines generate "
                  "MikkTSpace tangents, as glTF asks")
_FORMAT_OF_SUFFIX = {".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg", ".webp": "webp", ".ktx2": "ktx2"}


@dataclass(frozen=True)
class GltfOutput:
    compress: str = "none"
    textures: str = "png"
    max_texture: int = DEFAULT_MAX_TEXTURE
    tangents: bool = False
    skins_at_root: bool = False
    normals: bool = True              # False where the input had none: glTF then shades flat, as it did
    # What of the input's own settings the output file cannot hold, and what it gets instead.
    unlike_input: tuple[str, ...] = ()
    target: str = AS_IMPORTED          # the engine it is written for (engine_targets.TARGETS)
    extensions: frozenset[str] | None = None   # the only extensions it may carry (None: any)
    # The glTF whose own tangents the output keeps where its vertices are the input's (gltf_tangents).
    tangent_source: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.compress not in COMPRESSIONS:
            raise InputError(f"--compress must be one of {', '.join(COMPRESSIONS)}, got '{self.compress}'.")
        if self.textures not in TEXTURE_FORMATS:
            raise InputError(f"--textures must be one of {', '.join(TEXTURE_FORMATS)}, got '{self.textures}'.")
        size = self.max_texture
        if not isinstance(size, int) or size < 4 or size > 8192 or size & (size - 1):
            raise InputError(f"--max-texture must be a power of two between 4 and 8192, got {size}.")

    def report(self) -> dict:
        return {"compress": self.compress, "textures": self.textures, "max_texture": self.max_texture,
                "tangents": self.tangents, "skins_at_root": self.skins_at_root, "normals": self.normals,
                "target": self.target,
                **({"unlike_input": list(self.unlike_input)} if self.unlike_input else {})}


def _image_format(image: dict) -> str | None:
    if image.get("mimeType") in _FORMAT_OF_MIME:
        return _FORMAT_OF_MIME[image["mimeType"]]
    return _FORMAT_OF_SUFFIX.get(Path(str(image.get("uri", ""))).suffix.lower())


# Written into .glb files only (meshoptimizer's encoder and KTX2's rewrite work on the binary chunk), and
# what a .gltf can be given instead.
GLB_ONLY = {"compress": "meshopt", "textures": "ktx2"}
_OTHERS = {"compress": "none or draco", "textures": "png, jpeg or webp"}


def glb_only(output: GltfOutput, file_format: str) -> str | None:
    """The first of `output`'s settings ("compress", "textures") that a `file_format` file cannot hold."""
    if file_format == "glb":
        return None
    return next((key for key, value in GLB_ONLY.items() if getattr(output, key) == value), None)


def check_output_format(output: GltfOutput, file_format: str) -> None:
    """One sentence (the command line's words), before any work, for a chosen setting a .gltf cannot hold."""
    key = glb_only(output, file_format)
    if key is not None:
        raise InputError(f"--{key} {GLB_ONLY[key]} writes .glb files only; use --format glb, or --{key} "
                         f"{_OTHERS[key]}.")


def output_like_input(asset: str | Path | None, compress: str | None = None, textures: str | None = None,
                      max_texture: int | None = None, file_format: str = "glb",
                      target: str = AS_IMPORTED) -> GltfOutput:
    """The output settings: each one given, else as the input file has it (a non-glTF input, or none:
    none, png), within what `file_format` holds: an input's meshopt or KTX2 becomes plain or PNG in a
    .gltf (`unlike_input` says so; given ones are the caller's to refuse). For an engine `target`: only
    the compression, texture format and extensions that engine reads (engine_targets). Tangents where the
    input has them (and, for inputs that are not glTF, where a loaded material has a normal map:
    blender_io.gltf_export)."""
    engine = engine_target(target)
    check_given(engine, compress, textures)
    is_gltf = asset is not None and Path(asset).suffix.lower() in (".gltf", ".glb")
    document = gltf_json(Path(asset)) if asset is not None and is_gltf else {}
    unlike = []
    if compress is None:
        compress = _input_compression(document)
        if engine.compressions:   # an engine's first choice that this kind of file holds
            compress = next(c for c in engine.compressions if file_format == "glb" or c != GLB_ONLY["compress"])
        elif file_format != "glb" and compress == GLB_ONLY["compress"]:
            compress = "none"
            unlike.append("the input's meshopt compression is written into .glb files only: none in this .gltf")
    if textures is None:
        textures = _input_texture_format(document)
        if engine.textures and textures not in engine.textures:
            unlike.append(f"{engine.label} does not read the input's {textures} textures: {engine.textures[0]}")
            textures = engine.textures[0]
        if file_format != "glb" and textures == GLB_ONLY["textures"]:
            textures = "png"
            unlike.append("the input's KTX2 textures are written into .glb files only: PNG in this .gltf")
    attributes = [set(primitive.get("attributes", {})) for mesh in document.get("meshes", [])
                  for primitive in mesh.get("primitives", [])]
    tangents = any("TANGENT" in names for names in attributes)
    normals = not attributes or tangents or any("NORMAL" in names for names in attributes)
    if tangents and compress == "draco":
        tangents = False
        unlike.append(DRACO_TANGENTS)
    # A glTF's skinned meshes stay where it had them; another kind of file has no say, so they go to the
    # root, where glTF wants them (the validator warns NODE_SKINNED_MESH_NON_ROOT under Blender's armature).
    at_root = _skinned_meshes_at_root(document) if is_gltf else True
    return GltfOutput(compress, textures, DEFAULT_MAX_TEXTURE if max_texture is None else max_texture, tangents,
                      at_root, normals, tuple(unlike), engine.name, kept_extensions(engine, compress, textures),
                      str(asset) if tangents else None)


def _input_compression(document: dict) -> str:
    used = document.get("extensionsUsed", [])
    return next((c for e, c in _COMPRESSION_OF_EXTENSION.items() if e in used), "none")


def _input_texture_format(document: dict) -> str:
    formats = [f for f in (_image_format(image) for image in document.get("images", [])) if f is not None]
    return max(set(formats), key=formats.count, default="png")


def extensions_kept(path: Path, keep: frozenset[str]) -> list[str]:
    """engine_targets.keep_only_extensions on the .glb or .gltf file at `path`, rewritten in place if any
    went. Returns the extensions taken out."""
    document, chunk = read_gltf(path)
    removed = keep_only_extensions(document, keep)
    if removed and path.suffix.lower() == ".gltf":
        path.write_text(json.dumps(document, indent=2))
    elif removed:
        write_glb(path, document, chunk or b"")   # (a GLB without a BIN chunk is written back without one)
    return removed


def _parents(document: dict) -> dict[int, int]:
    return {child: index for index, node in enumerate(document.get("nodes", [])) for child in node.get("children", [])}


def _skinned_meshes_at_root(document: dict) -> bool:
    """Whether the input has skinned meshes and every one of them is a root node."""
    skinned = [index for index, node in enumerate(document.get("nodes", [])) if "skin" in node]
    parents = _parents(document)
    return bool(skinned) and not any(index in parents for index in skinned)


def move_skinned_meshes_to_root(document: dict) -> int:
    """Detach every skinned mesh node from its parent and make it a root of the scenes its parent was
    in (its transform is ignored by glTF, so nothing moves). Returns how many were moved."""
    nodes, parents = document.get("nodes", []), _parents(document)
    moved = [index for index, node in enumerate(nodes) if "skin" in node and index in parents]
    for index in moved:
        parent = nodes[parents[index]]
        parent["children"].remove(index)
        if not parent["children"]:
            del parent["children"]
        top = parents[index]
        while top in parents:
            top = parents[top]
        for scene in document.get("scenes", []):
            if top in scene.get("nodes", []):
                scene["nodes"].append(index)
    return len(moved)


def skinned_meshes_moved_to_root(path: Path) -> int:
    """move_skinned_meshes_to_root on the .glb or .gltf file at `path`, rewritten in place if any moved."""
    document, chunk = read_gltf(path)
    moved = move_skinned_meshes_to_root(document)
    if moved and chunk is None:
        path.write_text(json.dumps(document, indent=2))
    elif moved:
        write_glb(path, document, chunk or b"")   # (a GLB without a BIN chunk is written back without one)
    return moved
