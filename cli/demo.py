"""scenefit demo: SceneFit on the bundled example (what `make demo` runs)."""
from __future__ import annotations

from pathlib import Path

from .options import PRESETS, progress


def run(args) -> int:
    from ..demo import run_demo

    report = run_demo(Path(args.out), preset=args.preset, progress=progress(args), refresh=args.refresh,
                      guidance=args.guidance)
    print(f"demo done in {report['seconds_total']:.1f} s: conversion {report['convert']['psnr_covered_texels_db']:.2f} dB, "
          f"composite {args.out}/compose/composite.png, sheet {report['sheet']}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="run SceneFit on the bundled example (what `make demo` runs)")
    p.add_argument("--out", default="out/demo")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--refresh", action="store_true", help="re-make the example asset and photo")
    p.add_argument("--guidance", choices=("auto", "sd2", "none"), default="auto",
                   help="texture adaptation: sd2 (needs the Stable Diffusion 2 weights), none, or auto (sd2 when "
                        "its weights are on this machine)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)
