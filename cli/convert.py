"""scenefit convert: fit a neural texture to the asset's own maps and bake it."""
from __future__ import annotations

from pathlib import Path

from .options import add_preset_args, add_asset_args, load_asset, progress


def run(args) -> int:
    from ..core.asset_io import save_asset_folder
    from ..core.presets import stage_config
    from ..core.pipeline import convert_and_bake, environment_info, write_report

    mesh, maps = load_asset(args.asset, args.object)
    overrides = {k: v for k, v in (("method_type", args.method), ("iterations", args.iterations),
                                   ("resolution", args.resolution), ("seed", args.seed)) if v is not None}
    config = stage_config("convert", args.preset, **overrides)
    out = Path(args.out)
    result, report = convert_and_bake(mesh, maps, out / "maps", config, progress=progress(args))
    save_asset_folder(mesh, maps, out / "asset")
    report["environment"] = environment_info()
    write_report(out / "report.json", report)
    print(f"converted '{mesh.name}': {result.psnr:.2f} dB on covered texels in {result.seconds:.1f} s "
          f"({config.method_type}) -> {out}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("convert", help="fit a neural texture to the asset's own maps and bake it")
    add_asset_args(p)
    p.add_argument("--out", required=True, help="output folder")
    add_preset_args(p)
    p.add_argument("--method", choices=("direct", "inverse"), help="direct texture-space fit (default) or inverse rendering")
    p.add_argument("--iterations", type=int)
    p.add_argument("--resolution", type=int, help="texture size (default: the asset's, capped by the preset)")
    p.add_argument("--seed", type=int)
    p.set_defaults(func=run)
