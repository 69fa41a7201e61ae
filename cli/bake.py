"""scenefit bake: the asset with its fitted or adapted texture as a glTF 2.0 file for game engines."""
from __future__ import annotations

from pathlib import Path

from ..core.stages.bake.engine_targets import AS_IMPORTED, TARGET_NAMES
from ..core.stages.bake.gltf_output import COMPRESSIONS, DEFAULT_MAX_TEXTURE, TEXTURE_FORMATS
from .options import add_asset_args


def run(args) -> int:
    import json

    from ..blender_io.gltf_export import bake_asset_file
    from ..core.data.asset_files import asset_files, refuse_overwriting, refuse_replacing
    from ..core.data.asset_io import is_asset_folder
    from ..core.base.errors import InputError
    from ..core.stages.bake.game_bake import check_texture_size
    from ..core.stages.bake.gltf_ktx2 import basisu_path
    from ..core.stages.bake.gltf_output import check_output_format, output_like_input

    if is_asset_folder(args.asset):
        raise InputError(f"'{args.asset}' is a SceneFit asset folder; scenefit bake rewrites the asset's own file "
                         "(.glb, .gltf, .obj, .fbx, .blend), so give the file it came from.")
    if args.texture_size is not None:
        check_texture_size(args.texture_size)
    # The asset's own files (a .gltf's buffers and images too) and the texture are never written over.
    protect = tuple(asset_files(args.asset)) + tuple(asset_files(args.texture))
    out = Path(args.out)
    if args.format is None:   # the file name says which: a.gltf is the separate layout, anything else a .glb
        args.format = "gltf" if out.suffix.lower() == ".gltf" else "glb"
    targets = [out] + ([out.with_suffix(".bin")] if args.format == "gltf" else [])
    if args.report:
        _check_report_path(Path(args.report), targets)
        targets.append(Path(args.report))
    refuse_overwriting(targets, list(protect))
    if not args.replace:   # before any work; the images of a .gltf are checked once their names are known
        refuse_replacing(targets)
    output = output_like_input(args.asset, args.compress, args.textures, args.max_texture, args.format,
                               args.target)
    check_output_format(output, args.format)
    if output.textures == "ktx2":   # (asked for, or the input's KTX2 written as KTX2 again)
        basisu_path() if args.textures is not None else \
            basisu_path("Writing the input's KTX2 textures as KTX2 again", "; or give --textures png, jpeg or webp")
    report = bake_asset_file(args.asset, Path(args.texture), args.out, args.format, args.texture_size, args.object,
                             protect=protect, output=output, replace=args.replace)
    for material in report["materials"]:
        print(f"material '{material['name']}': base colour texture, roughness {material['roughness']}, "
              f"metallic {material['metallic']} at {material['width']}x{material['height']}")
        for line in material["done"]:
            print(f"  {line}")
    if "uv_map" in report:
        print(f"  {report['uv_map']}")
    if args.report:
        Path(args.report).write_text(json.dumps(report, indent=2) + "\n")
    for why in (*output.unlike_input, *report["output"].get("notes", ())):
        print(f"  {why}")
    print(f"wrote {', '.join(report['files'])} (glTF 2.0 by Blender's exporter)")
    return 0


def _check_report_path(report: Path, outputs: list[Path]) -> None:
    """--report refused before any work when it names a file the bake writes (the .glb, the .gltf's .bin),
    or a folder that does not exist."""
    import os

    from ..core.base.errors import InputError

    for output in outputs:
        if os.path.abspath(report) == os.path.abspath(output) or (
                report.exists() and output.exists() and os.path.samefile(report, output)):
            raise InputError(f"--report '{report}' is a file the bake itself writes ('{output}'); give the report "
                             "another path.")
    folder = report.absolute().parent
    if not folder.is_dir():
        raise InputError(f"The folder of --report '{report}' ('{folder}') does not exist; make it or give "
                         "another path.")


def add_parser(sub) -> None:
    p = sub.add_parser("bake", help="write the asset with its fitted/adapted texture as glTF 2.0 (.glb/.gltf)")
    add_asset_args(p)
    p.add_argument("--texture", required=True, help="texture.pt from `scenefit convert` or `scenefit adapt`")
    p.add_argument("--format", choices=("glb", "gltf"),
                   help="glb: one binary file; gltf: .gltf + .bin + image files (default: from --out's extension)")
    p.add_argument("--out", required=True, help="output file, ending in .glb or .gltf")
    p.add_argument("--texture-size", type=int, help="power of two, for every material (default: each material's own images' size, "
                                                        "rounded up to a power of two, at most --max-texture)")
    p.add_argument("--target", choices=TARGET_NAMES, default=AS_IMPORTED,
                   help="the engine the file is for: only the compression, texture format and extensions its "
                        "importer reads (web: three.js / model-viewer, meshopt; godot: Godot 4; unity: glTFast; "
                        "unreal; see docs/technical/engine-targets.md) (default: as-imported, as the input file)")
    p.add_argument("--compress", choices=COMPRESSIONS,
                   help="mesh compression: none, draco (Blender's exporter) or meshopt (.glb only, meshoptimizer's "
                        "encoder) (default: as the input, or the --target's choice)")
    p.add_argument("--textures", choices=TEXTURE_FORMATS, help="image format of the textures; ktx2: KHR_texture_basisu, ETC1S for colour and UASTC for data, "
                        "with mipmaps (.glb only; needs Basis Universal's basisu) (default: the input's)")
    p.add_argument("--max-texture", type=int, default=DEFAULT_MAX_TEXTURE,
                   help=f"largest baked texture side, a power of two (default: {DEFAULT_MAX_TEXTURE})")
    p.add_argument("--report", help="also write what was baked as JSON here")
    p.add_argument("--replace", action="store_true",
                   help="write over files of an earlier bake at --out (and --report) (default: refuse)")
    p.set_defaults(func=run)
