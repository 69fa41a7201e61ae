"""Bake Asset: the asset (the selected objects, or the active object with all its materials) with its
SceneFit texture written as a game asset (GLB or glTF), every material baked in its own UVs.

The maps are baked from the neural texture in the background job (plain arrays, no bpy); a COPY of
each object and its materials gets them and is exported by Blender's glTF exporter on the main
thread, then removed: the artist's object, materials and scene stay as they were.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from ..blender_io.asset_file import imported_beside, imported_from
from ..blender_io.gltf_export import FORMATS, bake_copies_to_gltf, normal_mapped
from ..core.base.errors import InputError
from ..core.stages.bake.gltf_ktx2 import basisu_path
from ..core.stages.bake.engine_targets import TARGETS
from ..core.stages.bake.gltf_output import COMPRESSIONS, DEFAULT_MAX_TEXTURE, TEXTURE_FORMATS, GltfOutput
from ..core.base.report import write_report
from ..workers import blender_jobs as work
from .asset import asset_layout, asset_texture
from .folders import run_folder
from .polls import OnMesh
from .jobs import JobOperator, has_ui
from .properties import PATH

FORMAT_ITEMS = (("glb", "glTF Binary (.glb)", "One file holding the mesh, materials and images"),
                ("gltf", "glTF Separate (.gltf)", "JSON, a .bin and the images beside it"))
assert {key for key, *_ in FORMAT_ITEMS} == set(FORMATS)
AS_IMPORTED = "imported"
COMPRESS_ITEMS = ((AS_IMPORTED, "As imported", "As the file the asset was imported from, by Import Asset or File > "
                                               "Import > glTF (None for objects made in Blender or imported from "
                                               "other formats by Blender's importers; None for meshopt in a .gltf)"),
                  ("none", "None", "Plain mesh data"),
                  ("draco", "Draco", "KHR_draco_mesh_compression, by Blender's exporter"),
                  ("meshopt", "meshopt", "EXT_meshopt_compression, by meshoptimizer's encoder (.glb only)"))
TEXTURE_ITEMS = ((AS_IMPORTED, "As imported", "As the file the asset was imported from, by Import Asset or File > "
                                              "Import > glTF (PNG for objects made in Blender or imported from "
                                              "other formats by Blender's importers; PNG for KTX2 in a .gltf)"),
                 ("png", "PNG", "Lossless"), ("jpeg", "JPEG", "Smaller, lossy (images with alpha stay PNG)"),
                 ("webp", "WebP", "Smaller; needs an engine that reads EXT_texture_webp"),
                 ("ktx2", "KTX2", "GPU-compressed (KHR_texture_basisu: ETC1S colour, UASTC data; .glb only; "
                                  "needs Basis Universal's basisu)"))
TARGET_ITEMS = ((TARGETS["as-imported"].name, "As imported", "Compression, textures and extensions as chosen "
                                                              "here or as the imported file had them"),
                ("web", "Web", "three.js and model-viewer: meshopt compression; PNG, JPEG, WebP or KTX2 textures"),
                ("godot", "Godot 4", "No mesh compression; PNG, JPEG or WebP; only the extensions Godot reads"),
                ("unity", "Unity (glTFast)", "No mesh compression; PNG or JPEG; only the extensions glTFast reads "
                                             "without extra packages"),
                ("unreal", "Unreal Engine", "No mesh compression; PNG or JPEG; only the extensions Unreal's glTF "
                                            "importer reads"))
assert [k for k, *_ in TARGET_ITEMS] == list(TARGETS)
assert [k for k, *_ in COMPRESS_ITEMS[1:]] == list(COMPRESSIONS) and \
    [k for k, *_ in TEXTURE_ITEMS[1:]] == list(TEXTURE_FORMATS)


def bake_output(compress: str, textures: str, max_texture: int, file_format: str, source: Path | None,
                normal_maps: bool, target: str = "as-imported") -> GltfOutput:
    """Bake Asset's output: compression and texture format as chosen, or As imported: as the file `source`
    was written (scenefit bake's default), within what `file_format` holds (meshopt and KTX2: .glb only);
    tangents where that file had them or a material has a normal map; skinned meshes at the root, where
    glTF wants them (Blender's exporter puts them under the armature: NODE_SKINNED_MESH_NON_ROOT).
    One sentence (InputError) for a setting that cannot be written, before any work."""
    from ..core.stages.bake.gltf_output import glb_only, output_like_input

    like = output_like_input(source, None if compress == AS_IMPORTED else compress,
                             None if textures == AS_IMPORTED else textures, max_texture, file_format, target)
    cannot = glb_only(like, file_format)   # (in Blender's words, not the command line's flags)
    if cannot == "compress":
        raise InputError("Compression meshopt writes .glb files only; choose the glTF Binary format, or None or "
                         "Draco compression.")
    if cannot == "textures":
        raise InputError("Textures KTX2 writes .glb files only; choose the glTF Binary format, or PNG, JPEG or "
                         "WebP textures.")
    if like.textures == "ktx2":
        why = "As imported (the file had KTX2 textures)" if textures == AS_IMPORTED else "KTX2"
        basisu_path(f"Textures {why}", "; or choose PNG, JPEG or WebP textures")
    return replace(like, tangents=like.tangents or normal_maps, skins_at_root=True)


class SCENEFIT_OT_bake_asset(OnMesh, JobOperator):
    """Write the asset (the selected objects, or the active one) with its SceneFit texture baked into every
    material as a game asset (glTF 2.0); the objects, their materials and the scene are left as they are"""

    bl_idname = "scenefit.bake_asset"
    bl_label = "Bake Asset"
    job_name = "bake"

    filepath: StringProperty(name="File", subtype="FILE_PATH", options={"SKIP_SAVE"} | PATH, default="",
                             description="Where to write; empty: a new run folder next to the .blend")
    filter_glob: StringProperty(default="*.glb;*.gltf", options={"HIDDEN"},
                                description="The kinds of file the browser lists")
    file_format: EnumProperty(name="Format", items=FORMAT_ITEMS, default="glb",
                              description="One .glb file, or a .gltf with its data and images beside it")
    texture_size: IntProperty(name="Texture size", default=0, min=0, max=8192, options={"SKIP_SAVE"},
                              description="Pixels per side (a power of two) for every material; 0: each "
                                          "material's own images' size")
    target: EnumProperty(name="Target", items=TARGET_ITEMS, default="as-imported",
                         description="The engine the file is for: only what its importer reads")
    compress: EnumProperty(name="Compression", items=COMPRESS_ITEMS, default=AS_IMPORTED,
                           description="How the mesh data is compressed in the file")
    textures: EnumProperty(name="Textures", items=TEXTURE_ITEMS, default=AS_IMPORTED,
                           description="The image format of the baked textures")
    max_texture: IntProperty(name="Max texture", default=DEFAULT_MAX_TEXTURE, min=4, max=8192,
                             description="Largest baked texture side, a power of two")
    cameras_and_lights: BoolProperty(name="Cameras and Lights", default=True,
                                     description="Also write the cameras and lights imported with the asset (Import "
                                                 "Asset, or File > Import > glTF) from the "
                                                 "asset's file, as they are")

    @classmethod
    def poll(cls, context):
        if not super().poll(context):
            return False
        if context.scene.scenefit.texture_path:
            return True
        cls.poll_message_set("This asset has no SceneFit texture yet: Run All, Convert or Adapt makes one")
        return False

    def invoke(self, context, event):
        """The file browser first (with the options beside it), as Blender's own exporters do; its
        Bake Asset button starts the job."""
        if not has_ui(context):
            return self.execute(context)
        if not self.filepath:
            from .asset import asset_objects
            from .folders import output_root

            objects = asset_objects(context)
            name = bpy.path.clean_name(objects[0].name if objects else "asset")
            # beside the .blend, as Blender's own exporters start; an unsaved file's runs folder otherwise
            folder = Path(bpy.data.filepath).parent if bpy.data.is_saved else output_root(context)
            self.filepath = str(folder / f"{name}.{self.file_format}")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def check(self, _context) -> bool:
        """The file's ending follows the chosen format (True: the browser shows the new name)."""
        if not self.filepath:
            return False
        path = Path(self.filepath)
        wanted = path.with_suffix(f".{self.file_format}") if path.suffix or path.name else path
        if str(wanted) == self.filepath:
            return False
        self.filepath = str(wanted)
        return True

    def prepare(self, context):
        size = self.texture_size
        if size and (size < 4 or size & (size - 1)):
            raise InputError(f"Texture size must be a power of two from 4 to 8192 (or 0 for each material's own "
                             f"images' size), got {size}.")
        layout = asset_layout(context)   # the selected objects, or the active one with all its materials
        texture = asset_texture(context, layout)   # this asset's, made for its mesh
        artists = layout.artists   # what is exported: the artist's materials with the baked maps
        objects = [bpy.data.objects[n] for n in layout.objects]
        source = imported_from(objects)
        self._output = bake_output(self.compress, self.textures, self.max_texture, self.file_format, source,
                                   any(normal_mapped(m) for m in artists), self.target)
        if self.filepath:
            out_file = Path(bpy.path.abspath(self.filepath))
            if out_file.suffix.lower() != f".{self.file_format}":
                out_file = out_file.with_suffix(f".{self.file_format}")
            self._folder = None
        else:
            self._folder = run_folder(context, "bake", layout.name)
            out_file = Path(f"{bpy.path.clean_name(layout.name)}.{self.file_format}")
        self._objects, self._slots, self._out_file = layout.objects, layout.slots, out_file
        self._sources = [m.name for m in artists]
        self._beside = [o.name for o in imported_beside(objects, context.scene.objects, source)] \
            if self.cameras_and_lights else []
        remap, remapped, self._new_uvs = new_uv_map(context, layout, texture)
        return work.bake_game_maps, dict(layout.bake_data(), **layout.own_maps(context),
                                         texture=str(texture),
                                         size=self.texture_size, max_size=self.max_texture, remap=remap,
                                         remapped=remapped)

    def apply(self, context, result) -> str:
        gone = [name for name in self._objects if name not in bpy.data.objects]
        if gone:
            raise InputError(f"The object '{gone[0]}' was deleted while SceneFit baked it.")
        objects = [bpy.data.objects[name] for name in self._objects]
        slots = [[(bpy.data.objects[name], number) for name, number in pairs] for pairs in self._slots]
        if any(number >= len(obj.material_slots) for pairs in slots for obj, number in pairs):
            raise InputError("A material slot of the asset was removed while SceneFit baked it; bake again.")
        gone = [name for name in self._sources if name not in bpy.data.materials]
        if gone:
            raise InputError(f"The material '{gone[0]}' was deleted or renamed while SceneFit baked it; bake again.")
        sources = [bpy.data.materials[name] for name in self._sources]
        beside = [bpy.data.objects[name] for name in self._beside if name in bpy.data.objects]
        shown = objects[0].name if len(objects) == 1 else f"{len(objects)} objects ({', '.join(self._objects)})"

        def export(folder: Path | None) -> dict:
            out_file = self._out_file if folder is None else folder / self._out_file
            # A chosen file is written over as Blender's own exporters do; a run folder is new.
            report = bake_copies_to_gltf(objects, result["baked"], slots, out_file, self.file_format, self._output,
                                         replace=True, new_uvs=self._new_uvs, sources=sources, beside=beside)
            report.update({"object": objects[0].name if len(objects) == 1 else None, "objects": list(self._objects),
                           "format": self.file_format, "texture_size": result["size"], "file": str(out_file),
                           "cameras_and_lights": [o.name for o in beside]})
            if folder is not None:
                write_report(folder / "report.json", report)
            return report

        # A run folder is written whole; a chosen file is moved into place once the exporter has finished.
        report = export(None) if self._folder is None else work.written_whole(str(self._folder), export)
        context.scene.scenefit.bake_path = str(self._out_file if self._folder is None else
                                               Path(self._folder) / self._out_file)
        unlike = "".join(f"; {why}" for why in self._output.unlike_input)   # (a .gltf cannot hold meshopt, KTX2)
        return f"Baked '{shown}' at up to {result['size']} px a side into {report['file']}{unlike}"


def new_uv_map(context, layout, texture) -> tuple[frozenset, object, dict]:
    """(the materials baked into a new UV map, the asset read through it, each object's new UVs per loop):
    a texture adapted per surface on UVs that share texels (core.game_bake.materials_to_remap), as
    `scenefit bake` does; nothing otherwise. Made on copies, so the artist's meshes keep their UVs."""
    from ..blender_io.material import material_wrap
    from ..blender_io.uv_unwrap import unwrapped_copies
    from ..core.stages.bake.game_bake import materials_to_remap
    from ..core.texture.bake import load_neural_texture

    loaded = load_neural_texture(texture)
    if loaded.layout is None:
        return frozenset(), None, {}
    remap = materials_to_remap(loaded, layout.mesh, [material_wrap(m) for m in layout.artists])
    if not remap:
        return remap, None, {}
    objects = [bpy.data.objects[name] for name in layout.objects]

    def read(copies: list):
        from ..blender_io.material import object_mesh_and_slots
        from ..blender_io.scene_asset import scene_mesh

        depsgraph = context.evaluated_depsgraph_get()
        if len(copies) == 1:
            return object_mesh_and_slots(copies[0], depsgraph)[0]
        return scene_mesh(copies, depsgraph, layout.name, strict=True).mesh

    remapped, loops = unwrapped_copies(objects, [layout.materials[i] for i in sorted(remap)], read)
    return remap, remapped, loops


class SCENEFIT_OT_open_bake_folder(bpy.types.Operator):
    """Open the folder of the last file Bake Asset wrote in the system's file browser"""

    bl_idname = "scenefit.open_bake_folder"
    bl_label = "Open Folder"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        if getattr(context.scene, "scenefit", None) is not None and context.scene.scenefit.bake_path:
            return True
        cls.poll_message_set("Nothing baked yet")
        return False

    def execute(self, context):
        folder = Path(bpy.path.abspath(context.scene.scenefit.bake_path)).parent
        if not folder.is_dir():
            self.report({"ERROR"}, f"The folder '{folder}' is gone.")
            return {"CANCELLED"}
        bpy.ops.wm.path_open(filepath=str(folder))
        return {"FINISHED"}


classes = (SCENEFIT_OT_bake_asset, SCENEFIT_OT_open_bake_folder)

register, unregister = bpy.utils.register_classes_factory(classes)
