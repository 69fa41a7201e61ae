"""scenefit convert: the asset's own maps as the neural texture's exact start (or a fit to them), baked."""
from __future__ import annotations

from pathlib import Path

from .options import add_asset_args, add_output_args, add_preset_args, output, positive_int, progress


def print_material_report(asset) -> None:
    """What was read from each material, what is carried unchanged, and what was dropped and why."""
    for material in asset.materials:
        print(f"material '{material.name}':")
        for kind, lines in (("read", material.read), ("kept", material.kept), ("dropped", material.dropped)):
            for line in lines:
                print(f"  {kind:8s}{line}")
    for note in asset.notes:
        print(f"  note    {note}")


def run(args) -> int:
    from ..blender_io.asset_file import load_asset_materials
    from ..core.data.asset_io import save_asset_folder
    from ..core.pipeline.run_table import run_config
    from ..core.pipeline.stage_configs import convert_config
    from ..core.base.report import write_report
    from ..core.render.backend import environment_info
    from ..core.stages.convert import convert_and_bake

    # The run this asks for, read through the run table as a jobs file's convert job is (a fitting method or
    # iterations imply --init fit: core/pipeline/resolve.py).
    settings = {k: v for k, v in (("init_type", args.init), ("method_type", args.method), ("iterations", args.iterations),
                                  ("resolution", args.resolution)) if v is not None}
    table = {"preset": args.preset, "overrides": {"convert": settings},
             **({"seed": args.seed} if args.seed is not None else {})}
    config = convert_config(run_config(table, "scenefit convert", stages=("convert",)), args.screen_px)
    with output(args) as out:
        asset = load_asset_materials(args.asset, args.object)
        print_material_report(asset)
        result, report = convert_and_bake(asset, None, out / "maps", config, progress=progress(args),
                                          keep_constants=True)
        mesh, maps = asset.fitting_view()
        save_asset_folder(mesh, maps, out / "asset")
        report["environment"] = environment_info()
        write_report(out / "report.json", report)
    per_material = ", ".join(f"'{m['name']}' {m['psnr_db']:.2f} dB" for m in result.decisions["materials"])
    how = "exact start: the asset's own maps" if config.init_type == "exact" else f"{config.method_type} fit"
    print(f"converted '{mesh.name}': {result.psnr:.2f} dB on covered texels ({per_material}) in "
          f"{result.seconds:.1f} s ({how}) -> {Path(args.out)}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("convert", help="fit a neural texture to the asset's own maps and bake it")
    add_asset_args(p)
    add_output_args(p)
    add_preset_args(p)
    p.add_argument("--init", choices=("exact", "fit"),
                   help="exact (default): the texture is the asset's own maps plus a residual that starts at zero, "
                        "nothing fitted; fit: the paper's neural texture fitted to the maps")
    p.add_argument("--method", choices=("direct", "inverse"),
                   help="with --init fit: direct texture-space fit (default) or inverse rendering")
    p.add_argument("--iterations", type=positive_int, help="with --init fit (implies it): fitting steps")
    p.add_argument("--resolution", type=positive_int, help="texture size (default: the asset's, capped by the preset)")
    p.add_argument("--seed", type=int)
    p.add_argument("--screen-px", type=positive_int,
                   help="the object's height in the final image, pixels: the texture gets no more texels than it shows")
    p.set_defaults(func=run)
