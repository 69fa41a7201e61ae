"""`make gpu-check`: the adapt stage at its real size on the first GPU this project is lent.

Builds Stable Diffusion 2-sized random-weight models on the machine (devtools/tiny_models.py's
SD2_SIZED: the 865M UNet, the 8x VAE, a ViT-H-sized text encoder; text-to-image and inpainting, in
the hub's layout), loads them through the real loading code (folders as `--base-model DIR --inpaint-model DIR`
take them), runs each preset's adapt iterations on CUDA (fp16, Mitsuba's cuda_ad_rgb; final first) and
writes seconds per iteration by phase and peak VRAM to benchmarks/results/gpu.md (and gpu.json). On one
H200 the whole check took about 3 minutes (models built in 50 s).

`--dry-run` is the same code path with the tiny models on the CPU, one iteration, one view, small
renders: the test suite runs it, so the check works the first time a GPU is there.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_adapt import PHASES, _run  # noqa: E402  (the adapt bench's measured run)

RESULTS = Path(__file__).resolve().parent / "results"
ITERATIONS = 3


def build_models(folder: Path, dry_run: bool) -> tuple[Path, Path]:
    from scenefit.devtools.tiny_models import SD2_SIZED, build_tiny_pair, build_tiny_sd

    if dry_run:
        return build_tiny_pair(folder)
    return (build_tiny_sd(folder / "sd2-base", 4, seed=0, **SD2_SIZED),
            build_tiny_sd(folder / "sd2-inpaint", 9, seed=1, **SD2_SIZED))


def measure(base: Path, inpaint: Path, preset: str, dry_run: bool) -> dict:
    """One preset's seconds per iteration by phase and peak memory (after a warm-up iteration)."""
    from scenefit.core.pipeline.presets import stage_config

    config = stage_config("adapt", preset, prompt="x")
    stages, resolution, iterations, warmup = config.stages, config.model_resolution, ITERATIONS, 1
    views = config.views_per_step
    if dry_run:   # the tiny models' 32-px latents, 8 samples, one view: seconds on two cores
        stages = tuple(replace(s, render_size=min(s.render_size, 32), spp=min(s.spp, 8)) for s in stages)
        resolution, iterations, warmup, views = 32, 1, 0, 1
    started = time.perf_counter()
    row = _run(base, inpaint, resolution, stages, iterations, config.views_type, views_per_step=views, warmup=warmup)
    return {"preset": preset, "render_size": stages[0].render_size, "spp": stages[0].spp,
            "model_resolution": resolution, "views_per_step": views, "iterations": iterations,
            "seconds": round(time.perf_counter() - started, 1), **row}


def markdown(rows: list[dict], machine: dict) -> str:
    head = "| preset | render px / spp | views / step | " + " | ".join(t for t, _ in PHASES) + \
           " | s / iteration | peak memory MB |"
    lines = ["# `make gpu-check` (benchmarks/gpu_check.py)", "", " ".join(__doc__.split("\n\n")[1].split()), "",
             f"Machine: {machine['device']}; torch {machine['torch']}, CUDA {machine['cuda']}; Mitsuba "
             f"{machine['variant']}; models: {machine['models']} (built in {machine.get('model_build_s', '?')} s); "
             f"{'DRY RUN (tiny models, CPU)' if machine['dry_run'] else ''}",
             "", head, "|" + "---|" * (len(PHASES) + 5)]
    for r in rows:
        lines.append(f"| {r['preset']} | {r['render_size']} / {r['spp']} | {r['views_per_step']} | "
                     + " | ".join(f"{r['phases'][k]:.3f}" for _, k in PHASES)
                     + f" | {r['iteration_s']:.3f} | {r['peak_memory_mb'] or 0:.0f} |")
    lines += ["", "Peak memory: torch.cuda.max_memory_allocated on the GPU (Dr.Jit's own CUDA allocations for "
              "the scene and its renders are not in it); the process's resident set on the CPU. Seconds per "
              "iteration: the mean of the measured iterations after a warm-up one, so each preset's constant "
              "work (a view's reference render and latents, computed once per view) is in it while new views "
              "come up and falls away over a run."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dry-run", action="store_true", help="tiny models on the CPU, one iteration")
    parser.add_argument("--presets", default="final,draft,balanced", help="comma-separated presets")
    parser.add_argument("--models", help="a folder to build the models in and keep (default: a temporary one)")
    parser.add_argument("--out", default=str(RESULTS))
    args = parser.parse_args(argv)
    if not args.dry_run and not torch.cuda.is_available():
        print("gpu-check: torch sees no CUDA GPU on this machine; run it where one is lent, or --dry-run here.",
              file=sys.stderr)
        return 2
    from scenefit.core.render.backend import init_mitsuba

    machine = {"device": torch.cuda.get_device_name() if torch.cuda.is_available() and not args.dry_run else "CPU",
               "torch": torch.__version__, "cuda": torch.version.cuda, "variant": init_mitsuba().variant,
               "models": "tiny" if args.dry_run else "SD2-sized, random weights", "dry_run": args.dry_run}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="scenefit-gpu-check-") as tmp:
        folder = Path(args.models) if args.models else Path(tmp)
        started = time.perf_counter()
        base, inpaint = build_models(folder, args.dry_run)
        machine["model_build_s"] = round(time.perf_counter() - started, 1)
        print(f"gpu-check: models built in {machine['model_build_s']} s", flush=True)
        for preset in args.presets.split(","):
            rows.append(measure(base, inpaint, preset, args.dry_run))
            # Written after each preset: a lease that ends mid-run still leaves the presets measured so far.
            (out / "gpu.md").write_text(markdown(rows, machine))
            (out / "gpu.json").write_text(json.dumps({"machine": machine, "rows": rows}, indent=1, default=str) + "\n")
            print(f"gpu-check: {preset} done ({rows[-1]['seconds']} s)", flush=True)
    print((out / "gpu.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
