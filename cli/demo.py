"""scenefit demo: SceneFit on the bundled example (what `make demo` runs)."""
from __future__ import annotations

from ..core.base.names import GUIDANCE_TYPES

import json
import shutil
from pathlib import Path

from .options import PRESETS, add_output_args, output, progress


def _previous_demo(out: Path) -> bool:
    """Whether `out` holds an earlier demo run (which `make demo` may replace without --replace)."""
    if out.is_dir() and [p.name for p in out.iterdir()] == ["input"]:
        return True  # only the demo's inputs, put there to be reused
    try:
        return json.loads((out / "report.json").read_text()).get("stage") == "demo"
    except (OSError, ValueError, AttributeError):
        return False


def run(args) -> int:
    from ..core.pipeline.result import skipped_lines, stage_words
    from ..demo import run_demo

    previous = Path(args.out)
    args.replace = args.replace or _previous_demo(previous)
    if args.replace and previous.is_dir() and [p.name for p in previous.iterdir()] == ["input"]:
        # Only the demo's own inputs, put there to be reused: they are copied into the new run below,
        # so the folder may be replaced like an earlier demo run.
        from ..core.base.output_folder import write_marker

        write_marker(previous)
    with output(args) as out:
        # The example asset and photo of the earlier run are reused (Blender takes a while to make them).
        if not args.refresh and (previous / "input").is_dir():
            shutil.copytree(previous / "input", out / "input", dirs_exist_ok=True)
        report = run_demo(out, preset=args.preset, progress=progress(args), refresh=args.refresh,
                          guidance=args.guidance)
    print(f"demo done in {report['seconds_total']:.1f} s ({stage_words(report['stage_status'])}): conversion "
          f"{report['convert']['psnr_covered_texels_db']:.2f} dB, composite {args.out}/compose/composite.png, "
          f"sheet {args.out}/sheet.png")
    for line in skipped_lines(report["stage_status"]):
        print(line)
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="run SceneFit on the bundled example (what `make demo` runs)")
    add_output_args(p, default="out/demo", help="output folder (an earlier demo run there is replaced)")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--refresh", action="store_true", help="re-make the example asset and photo")
    p.add_argument("--guidance", choices=GUIDANCE_TYPES, default="auto",
                   help="texture adaptation: sd2 (needs the Stable Diffusion 2 weights), none, or auto (sd2 when "
                        "its weights are on this machine)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)
