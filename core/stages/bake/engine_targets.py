"""The engines a game bake is written for (`scenefit bake --target`, Bake Asset's Target): per engine, the
mesh compressions, texture formats and glTF extensions its own importer reads, as its documentation
says (docs/technical/engine-targets.md cites each). A bake for an engine keeps what of the input that engine
reads and gives up the rest: an extension it does not read is taken out of the file (a client ignores
an optional extension it does not know, so only bytes and the validator's word change), a compression
or texture format it does not read becomes the first it does."""
from __future__ import annotations

from dataclasses import dataclass

from ...base.errors import InputError

AS_IMPORTED = "as-imported"
COMPRESSION_EXTENSION = {"draco": "KHR_draco_mesh_compression", "meshopt": "EXT_meshopt_compression"}
TEXTURE_EXTENSION = {"webp": "EXT_texture_webp", "ktx2": "KHR_texture_basisu"}


@dataclass(frozen=True)
class EngineTarget:
    name: str
    label: str                          # the engine in an artist's words
    compressions: tuple[str, ...]       # what it reads, the one a bake chooses first
    textures: tuple[str, ...]           # what it reads; the input's where it is one of these, else the first
    extensions: frozenset[str] | None   # the extensions its importer reads (None: any, as the input has them)

    def reads(self, extension: str) -> bool:
        return self.extensions is None or extension in self.extensions


# three.js GLTFLoader's documented list (model-viewer renders with it), KHR_materials_sheen from its source,
# KHR_materials_variants from model-viewer's variant API.
_THREE = frozenset({
    "KHR_draco_mesh_compression", "KHR_lights_punctual", "KHR_materials_anisotropy", "KHR_materials_clearcoat",
    "KHR_materials_diffuse_roughness", "KHR_materials_dispersion", "KHR_materials_emissive_strength",
    "KHR_materials_ior", "KHR_materials_iridescence", "KHR_materials_sheen", "KHR_materials_specular",
    "KHR_materials_transmission", "KHR_materials_unlit", "KHR_materials_variants", "KHR_materials_volume",
    "KHR_mesh_quantization", "KHR_texture_basisu", "KHR_texture_transform", "EXT_materials_bump",
    "EXT_meshopt_compression", "EXT_mesh_gpu_instancing", "EXT_texture_avif", "EXT_texture_webp"})
# Godot 4's GLTFDocument::get_supported_gltf_extensions (the engine's own list) and its WebP module.
_GODOT = frozenset({
    "KHR_animation_pointer", "KHR_lights_punctual", "KHR_materials_emissive_strength",
    "KHR_materials_pbrSpecularGlossiness", "KHR_materials_unlit", "KHR_node_visibility", "KHR_texture_transform",
    "EXT_texture_webp"})
# Unity glTFast 6's GLTFast.Extension list, less what needs an optional package (Draco, KTX, meshopt).
_UNITY = frozenset({
    "KHR_lights_punctual", "KHR_materials_clearcoat", "KHR_materials_pbrSpecularGlossiness",
    "KHR_materials_transmission", "KHR_materials_unlit", "KHR_materials_variants", "KHR_mesh_quantization",
    "KHR_texture_transform", "EXT_mesh_gpu_instancing"})
# Unreal's glTF importer (Interchange GLTFCore): FAsset::SupportedExtensions, with the texture transform and
# emissive strength its parser reads (GLTF::EExtension); Draco is parsed but not among the supported.
_UNREAL = frozenset({
    "KHR_lights_punctual", "KHR_materials_clearcoat", "KHR_materials_emissive_strength", "KHR_materials_ior",
    "KHR_materials_pbrSpecularGlossiness", "KHR_materials_sheen", "KHR_materials_specular",
    "KHR_materials_transmission", "KHR_materials_unlit", "KHR_materials_variants", "KHR_texture_transform"})

TARGETS = {t.name: t for t in (
    EngineTarget(AS_IMPORTED, "As imported", (), (), None),
    EngineTarget("web", "Web (three.js, model-viewer)", ("meshopt", "draco", "none"), ("png", "jpeg", "webp", "ktx2"),
                 _THREE),
    EngineTarget("godot", "Godot 4", ("none",), ("png", "jpeg", "webp"), _GODOT),
    EngineTarget("unity", "Unity (glTFast)", ("none",), ("png", "jpeg"), _UNITY),
    EngineTarget("unreal", "Unreal Engine", ("none",), ("png", "jpeg"), _UNREAL),
)}
TARGET_NAMES = tuple(TARGETS)


def engine_target(name: str) -> EngineTarget:
    if name not in TARGETS:
        raise InputError(f"--target must be one of {', '.join(TARGET_NAMES)}, got '{name}'.")
    return TARGETS[name]


def check_given(target: EngineTarget, compress: str | None, textures: str | None) -> None:
    """One sentence for a compression or texture format asked for that the target's engine does not read."""
    if target.name == AS_IMPORTED:
        return
    if compress is not None and compress not in target.compressions:
        raise InputError(f"{target.label} does not read {compress} compression; give --compress "
                         f"{' or '.join(target.compressions)} with --target {target.name}, or another target.")
    if textures is not None and textures not in target.textures:
        raise InputError(f"{target.label} does not read {textures} textures; give --textures "
                         f"{', '.join(target.textures)} with --target {target.name}, or another target.")


def kept_extensions(target: EngineTarget, compress: str, textures: str) -> frozenset[str] | None:
    """The extensions a bake for `target` may write (None: any), the chosen compression's and format's among them."""
    if target.extensions is None:
        return None
    chosen = {name for name in (COMPRESSION_EXTENSION.get(compress), TEXTURE_EXTENSION.get(textures)) if name is not None}
    return target.extensions | chosen


def _strip(node, keep: frozenset[str], removed: set[str]) -> None:
    if isinstance(node, dict):
        extensions = node.get("extensions")
        if isinstance(extensions, dict):
            for name in [n for n in extensions if n not in keep]:
                removed.add(name)
                del extensions[name]
            if not extensions:
                del node["extensions"]
        for value in node.values():
            _strip(value, keep, removed)
    elif isinstance(node, list):
        for value in node:
            _strip(value, keep, removed)


def keep_only_extensions(document: dict, keep: frozenset[str]) -> list[str]:
    """Take every extension not in `keep` out of the glTF `document` (its objects' and the lists of used and
    required ones). Returns the names taken out. One that the file requires is refused: without it the file
    would mean something else."""
    required = [name for name in document.get("extensionsRequired", []) if name not in keep]
    if required:
        raise InputError(f"The glTF requires {', '.join(required)}, which the target's engine does not read.")
    removed: set[str] = set()
    _strip(document, keep, removed)
    removed |= {name for name in document.get("extensionsUsed", []) if name not in keep}
    used = [name for name in document.get("extensionsUsed", []) if name in keep]
    if used:
        document["extensionsUsed"] = used
    else:
        document.pop("extensionsUsed", None)
    return sorted(removed)
