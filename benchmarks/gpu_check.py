"""`make gpu-check`: the adapt stage at its real size on the first GPU this project is lent.

Builds Stable Diffusion 2-sized random-weight models on the machine (devtools/tiny_models.py's
SD2_SIZED: the 865M UNet, the 8x VAE, a ViT-H-sized text encoder; text-to-image and inpainting, in
the hub's layout), loads them through the real loading code (folders as `--base-model DIR --inpaint-model DIR`
take them), runs each preset's adapt iterations on CUDA (fp16, Mitsuba's cuda_ad_rgb; final first) and
writes seconds per iteration by phase and peak VRAM to benchmarks/results/gpu.md (and gpu.json); then
the light stage's diffusion critic per preset (`scenefit light --critic diffusion`). On one H200 the
adapt part took about 3 minutes (models built in 50 s); the light part has not run on a GPU yet.

Both renderers per preset, each step by phase: the loop renderer (adapt's default; a step's views
through each model in one pass) and the paper's path tracing (each view rendered, scored and
back-propagated in turn). `--dry-run` is the same code path with the tiny models on the CPU, one
iteration, at most two views per step (so a batched step runs), small renders: the test suite runs it,
so the check works the first time a GPU is there. It writes into --out (a dry run never into
benchmarks/results unless told: its numbers are not a GPU's).
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


def measure(base: Path, inpaint: Path, preset: str, dry_run: bool, renderer: str = "path") -> dict:
    """One preset's seconds per iteration by phase and peak memory (after a warm-up iteration), rendered
    by `renderer` ("path": the paper's path tracing; "loop": cached G-buffers shaded in torch)."""
    from scenefit.core.pipeline.presets import stage_config

    config = stage_config("adapt", preset, prompt="x")
    # 0: the model's own size, which for SD2's shape is its UNet's 64 latents x the VAE's 8.
    stages, resolution, iterations, warmup = config.stages, config.model_resolution or 64 * 8, ITERATIONS, 1
    views = config.views_per_step
    if dry_run:   # the tiny models' 32-px latents, 8 samples, up to two views: seconds on two cores
        stages = tuple(replace(s, render_size=min(s.render_size, 32), spp=min(s.spp, 8)) for s in stages)
        resolution, iterations, warmup, views = 32, 1, 0, min(views, 2)
    started = time.perf_counter()
    row = _run(base, inpaint, resolution, stages, iterations, config.views_type, views_per_step=views, warmup=warmup,
               renderer=renderer)
    return {"preset": preset, "renderer": renderer, "render_size": stages[0].render_size, "spp": stages[0].spp,
            "model_resolution": resolution, "views_per_step": views, "iterations": iterations,
            "seconds": round(time.perf_counter() - started, 1), **row}


def measure_light(base: Path, inpaint: Path, preset: str, dry_run: bool, folder: Path) -> dict:
    """The light stage with the diffusion critic at `preset` on a made-up outdoor photo (the corpus does not
    travel to a lent machine), run as `scenefit light` and Estimate Light run it (run_pipeline, stages
    ("light",)): seconds per critic iteration from its report, after a one-iteration run that compiles the
    kernels, and peak memory. A dry run renders the critic's apparatus as small as adapt's dry run does."""
    import resource

    import numpy as np

    from scenefit.core.data.imageio import write_image
    from scenefit.core.guidance.models import ModelConfig
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.pipeline.run import run_pipeline
    from scenefit.core.pipeline.run_config import RunConfig

    photo = folder / "photo.png"
    if not photo.is_file():   # a sky brightening upwards over a darker, textured ground
        y = np.linspace(0.0, 1.0, 240)[:, None, None]
        sky = np.concatenate([0.55 - 0.3 * y, 0.65 - 0.3 * y, 0.9 - 0.2 * y], axis=2) * np.ones((1, 320, 1))
        ground = np.random.default_rng(0).uniform(0.15, 0.35, (240, 320, 1)) * np.array([0.8, 0.9, 0.6])
        write_image(photo, np.where(y < 0.45, sky, ground).astype(np.float32))
    iterations = 1 if dry_run else ITERATIONS
    light: dict = {"critic_type": "diffusion", "outpaint": {"completion_type": "prior"}}
    if dry_run:   # the tiny models' 32 px, at most 8 samples, as adapt's dry run
        apparatus = stage_config("light", preset).apparatus
        light.update(diffusion={"model_resolution": 32},
                     apparatus={"render_size": min(apparatus.render_size, 32), "spp": min(apparatus.spp, 8)})
    models = ModelConfig(base_model=str(base), inpaint_model=str(inpaint), local_files_only=True)

    def estimate(n: int, out: Path) -> dict:
        overrides = {**light, "optimise": {"iterations": n}}
        result = run_pipeline(None, None, photo, (0.5, 0.75), out, RunConfig(
            preset=preset, scene_type="outdoor", models=models, stage_overrides={"light": overrides}),
            stages=("light",))
        return result.stages["light"].report

    if not dry_run:
        estimate(1, folder / "light-warmup")
    if torch.cuda.is_available():
        torch.cuda.reset_peak_memory_stats()
    report = estimate(iterations, folder / f"light-{preset}")
    peak = (torch.cuda.max_memory_allocated() if torch.cuda.is_available() and not dry_run
            else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024) / 2 ** 20
    optimisation = report["decisions"]["optimisation"]
    return {"preset": preset, "iterations": iterations, "per_iteration_s": optimisation["seconds"] / iterations,
            "critic": report["decisions"]["critic"].get("dtype", "?"), "peak_memory_mb": peak}


def markdown(rows: list[dict], machine: dict, light_rows: list[dict] | None = None,
             loop_rows: list[dict] | None = None) -> str:
    head = "| preset | render px / spp | views / step | views through the models | " + \
           " | ".join(t for t, _ in PHASES) + " | s / iteration | peak memory MB |"
    lines = ["# `make gpu-check` (benchmarks/gpu_check.py)", "", " ".join(__doc__.split("\n\n")[1].split()), "",
             f"Machine: {machine['device']}; torch {machine['torch']}, CUDA {machine['cuda']}; Mitsuba "
             f"{machine['variant']}; models: {machine['models']} (built in {machine.get('model_build_s', '?')} s); "
             f"{'DRY RUN (tiny models, CPU)' if machine['dry_run'] else ''}",
             "", "Path tracing (the paper's renderer):", "", head, "|" + "---|" * (len(PHASES) + 6)]
    for r in rows:
        lines.append(f"| {r['preset']} | {r['render_size']} / {r['spp']} | {r['views_per_step']} | {_through(r)} | "
                     + " | ".join(f"{r['phases'][k]:.3f}" for _, k in PHASES)
                     + f" | {r['iteration_s']:.3f} | {r['peak_memory_mb'] or 0:.0f} |")
    if loop_rows:
        lines += ["", "The same with the loop renderer (the adapt stage's default: each view's G-buffers traced "
                  "once, then shaded in torch). Its tracing is the G-buffer trace column, paid the first time each "
                  "view comes up (a few iterations meet many new views; a run's thousands meet them once), so the "
                  "step is also given without it:", "",
                  head.replace("render px / spp", "render px").replace(" | peak memory MB |",
                                                                       " | s / iteration without tracing | peak memory MB |"),
                  "|" + "---|" * (len(PHASES) + 7)]
        lines += [f"| {r['preset']} | {r['render_size']} | {r['views_per_step']} | {_through(r)} | "
                  + " | ".join(f"{r['phases'][k]:.3f}" for _, k in PHASES)
                  + f" | {r['iteration_s']:.3f} | {r['iteration_s'] - r['phases'].get('trace', 0.0):.3f}"
                  f" | {r['peak_memory_mb'] or 0:.0f} |" for r in loop_rows]
    if light_rows:
        lines += ["", "The light stage's diffusion critic with the same models (`scenefit light --critic diffusion`, "
                  "a made-up outdoor photo, after a one-iteration warm-up run):", "",
                  "| preset | s per critic iteration | models' dtype | peak memory MB |", "|---|---|---|---|"]
        lines += [f"| {r['preset']} | {r['per_iteration_s']:.3f} | {r['critic']} | {r['peak_memory_mb']:.0f} |"
                  for r in light_rows]
    lines += ["", "Peak memory: torch.cuda.max_memory_allocated on the GPU (Dr.Jit's own CUDA allocations for "
              "the scene and its renders are not in it); the process's resident set on the CPU. Seconds per "
              "iteration: the mean of the measured iterations after a warm-up one, so each preset's constant "
              "work (a view's reference render and latents, computed once per view) is in it while new views "
              "come up and falls away over a run."]
    return "\n".join(lines) + "\n"


def _through(row: dict) -> str:
    """How the row's step took its views through the models: in one pass each, or one at a time."""
    if row["views_per_step"] == 1:
        return "one view"
    return "one pass per model" if row.get("batched_steps") == row["iterations"] else "one at a time"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dry-run", action="store_true", help="tiny models on the CPU, one iteration")
    parser.add_argument("--presets", default="final,draft,balanced", help="comma-separated presets")
    parser.add_argument("--light-presets", default="draft,balanced,final",
                        help="the light critic's presets, after adapt's ('' for none)")
    parser.add_argument("--models", help="a folder to build the models in and keep (default: a temporary one)")
    parser.add_argument("--out", help="where gpu.md and gpu.json go (default: benchmarks/results; a dry run's: "
                                      "benchmarks/results/quick, so it never stands in for a GPU's table)")
    args = parser.parse_args(argv)
    if not args.dry_run and not torch.cuda.is_available():
        print("gpu-check: torch sees no CUDA GPU on this machine; run it where one is lent, or --dry-run here.",
              file=sys.stderr)
        return 2
    from scenefit.core.render.backend import init_mitsuba

    machine = {"device": torch.cuda.get_device_name() if torch.cuda.is_available() and not args.dry_run else "CPU",
               "torch": torch.__version__, "cuda": torch.version.cuda, "variant": init_mitsuba().variant,
               "models": "tiny" if args.dry_run else "SD2-sized, random weights", "dry_run": args.dry_run}
    out = Path(args.out) if args.out else RESULTS / "quick" if args.dry_run else RESULTS
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="scenefit-gpu-check-") as tmp:
        folder = Path(args.models) if args.models else Path(tmp)
        started = time.perf_counter()
        base, inpaint = build_models(folder, args.dry_run)
        machine["model_build_s"] = round(time.perf_counter() - started, 1)
        print(f"gpu-check: models built in {machine['model_build_s']} s", flush=True)
        light_rows: list[dict] = []
        loop_rows: list[dict] = []

        def write() -> None:   # after each row: a lease that ends mid-run still leaves what was measured
            (out / "gpu.md").write_text(markdown(rows, machine, light_rows, loop_rows))
            (out / "gpu.json").write_text(json.dumps({"machine": machine, "rows": rows, "light_rows": light_rows,
                                                      "loop_rows": loop_rows}, indent=1, default=str) + "\n")

        for preset in args.presets.split(","):
            loop_rows.append(measure(base, inpaint, preset, args.dry_run, "loop"))
            write()
            print(f"gpu-check: adapt {preset}, loop renderer done ({loop_rows[-1]['seconds']} s)", flush=True)
            rows.append(measure(base, inpaint, preset, args.dry_run, "path"))
            write()
            print(f"gpu-check: adapt {preset}, path tracing done ({rows[-1]['seconds']} s)", flush=True)
        for preset in args.light_presets.split(",") if args.light_presets else ():
            light_rows.append(measure_light(base, inpaint, preset, args.dry_run, folder))
            write()
            print(f"gpu-check: light {preset} done ({light_rows[-1]['per_iteration_s']:.2f} s per iteration)", flush=True)
    print((out / "gpu.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
