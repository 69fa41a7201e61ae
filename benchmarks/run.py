"""`make bench`: speed and accuracy of the rendering core, texture conversion, light and composition.

Writes benchmarks/results/bench.md (the tables the README quotes), bench.json and
conversion_psnr.png (PSNR against iterations and seconds for both conversion methods).
Run on the machine named in the output; numbers from other machines are not comparable.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from scenefit.core.asset_io import load_asset_folder
from scenefit.core.camera import Camera
from scenefit.core.convert import CONVERT_PRESETS, convert_preset, target_stack
from scenefit.core.mesh import normalize_to_unit_sphere
from scenefit.core.pipeline import environment_info
from scenefit.core.primitives import uv_sphere
from scenefit.core.render import AssetRenderer
from scenefit.core.texture.fit_direct import fit_direct, masked_psnr
from scenefit.core.texture.fit_inverse import fit_inverse_rendering, studio_environment
from scenefit.core.texture.neural_texture import NeuralTexture, preset
from scenefit.core.texture.uv_raster import rasterize_uv

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}, no GPU" \
        if not torch.cuda.is_available() else f"{cpu} + {torch.cuda.get_device_name()}"


def example_asset() -> Path:
    folder = Path(tempfile.gettempdir()) / "scenefit-bench-example"
    if not (folder / "mesh.npz").is_file():
        code = f"from scenefit.blender_io import make_example_asset; make_example_asset({str(folder)!r})"
        subprocess.run([sys.executable, "-c", code], check=True)
    return folder


def bench_render(mesh, maps_hw, label: str, repeats: int = 10) -> dict:
    """Seconds per render+backward at 256² and 16 spp (gradient to all maps), after the first (compiling) call."""
    h, w = maps_hw
    env = studio_environment()
    renderer = AssetRenderer(mesh, (h, w), env)
    env_t = torch.from_numpy(env)
    base = torch.full((h, w, 3), 0.5, requires_grad=True)
    rough = torch.full((h, w, 1), 0.5, requires_grad=True)
    metal = torch.zeros((h, w, 1), requires_grad=True)
    times = []
    for i in range(repeats + 1):
        cam = Camera(azimuth_deg=37.0 * i, elevation_deg=15, width=256, height=256)
        t = time.perf_counter()
        out = renderer.render(cam, base, rough, metal, env_t, spp=16, seed=i)
        out.rgb.mean().backward()
        times.append(time.perf_counter() - t)
    return {"scene": label, "first_call_s": times[0], "render_backward_s": float(np.median(times[1:])),
            "triangles": int(len(mesh.faces)), "texture": f"{h}x{w}"}


def bench_texture(raster, preset_name: str, repeats: int = 5) -> dict:
    texture = NeuralTexture(preset(preset_name, resolution=raster.resolution[0]))
    plan = texture.plan(raster.position, raster.border, raster.fill_index)
    times = []
    for _ in range(repeats + 1):
        t = time.perf_counter()
        texture.texture_from_plan(plan).sum().backward()
        times.append(time.perf_counter() - t)
    return {"preset": preset_name, "texels": int(plan.texels.numel()), "resolution": raster.resolution[0],
            "forward_backward_s": float(np.median(times[1:]))}


def fit_setup(mesh, maps, preset_name: str):
    """What both conversion methods start from: normalised mesh, UV raster, target maps, fresh texture."""
    normalized, _ = normalize_to_unit_sphere(mesh)
    config = convert_preset(preset_name)
    res = min(max(maps.resolution), config.max_resolution)
    return normalized, res, rasterize_uv(normalized, res), torch.from_numpy(target_stack(maps, res)), \
        NeuralTexture(config.texture_config(res), seed=0)


def bench_direct(mesh, maps, preset_name: str, iterations: int) -> dict:
    _, res, raster, target, texture = fit_setup(mesh, maps, preset_name)
    stamps = []
    t0 = time.perf_counter()
    fit = fit_direct(texture, raster.position, raster.mask, target, iterations=iterations,
                     progress=lambda it, loss, psnr: stamps.append(time.perf_counter() - t0))
    return {"method": "direct", "preset": preset_name, "resolution": res, "iterations": fit.iterations,
            "seconds": fit.seconds, "final_psnr": fit.final_psnr,
            "curve_iterations": list(range(1, fit.iterations + 1)), "curve_psnr": fit.psnr_history,
            "curve_seconds": stamps}


def bench_inverse(mesh, maps, preset_name: str, iterations: int, every: int) -> dict:
    normalized, res, raster, target, texture = fit_setup(mesh, maps, preset_name)
    plan = texture.plan(raster.position, raster.border, raster.fill_index)
    curve_it, curve_psnr, curve_s = [], [], []
    t0 = time.perf_counter()
    eval_time = [0.0]

    def checkpoint(it: int) -> None:
        if (it + 1) % every == 0 or it + 1 == iterations:
            t = time.perf_counter()
            with torch.no_grad():
                psnr = masked_psnr(texture.texture_from_plan(plan), target, raster.mask)
            eval_time[0] += time.perf_counter() - t
            curve_it.append(it + 1)
            curve_psnr.append(psnr)
            curve_s.append(time.perf_counter() - t0 - eval_time[0])

    fit = fit_inverse_rendering(lambda: texture.texture_from_plan(plan), texture.parameters(), normalized, target,
                                iterations=iterations, render_size=256, spp=16, on_iteration=checkpoint)
    return {"method": "inverse", "preset": preset_name, "resolution": res, "iterations": iterations,
            "seconds": fit.seconds - eval_time[0], "final_psnr": curve_psnr[-1], "curve_iterations": curve_it,
            "curve_psnr": curve_psnr, "curve_seconds": curve_s}


def plot(conversions: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for run in conversions:
        label = f"{run['method']} ({run['preset']})"
        axes[0].plot(run["curve_iterations"], run["curve_psnr"], label=label)
        axes[1].plot(run["curve_seconds"], run["curve_psnr"], label=label)
    for ax, xlabel in zip(axes, ("iterations", "seconds")):
        ax.axhline(30.0, color="grey", linestyle=":", linewidth=1)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("PSNR on covered texels (dB)")
        ax.grid(alpha=0.3)
    axes[1].set_xscale("log")
    axes[0].legend()
    fig.suptitle("Converting the bundled example's maps into the neural texture")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    head = "| " + " | ".join(title for title, _, _ in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(format(row[key], fmt) if fmt else str(row[key]) for _, key, fmt in columns) + " |"
            for row in rows]
    return "\n".join([head, rule, *body])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer iterations (a smoke run, not for the README)")
    args = parser.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    scale = 0.2 if args.quick else 1.0
    started = time.perf_counter()

    mesh, maps = load_asset_folder(example_asset())
    normalized, _ = normalize_to_unit_sphere(mesh)
    renders = [bench_render(uv_sphere(), (256, 256), "UV sphere"),
               bench_render(normalized, maps.resolution, "example (Suzanne)")]
    raster_256 = rasterize_uv(normalized, 256)
    raster_512 = rasterize_uv(normalized, 512)
    textures = [bench_texture(r, p) for p in CONVERT_PRESETS for r in (raster_256, raster_512)]
    conversions = [bench_direct(mesh, maps, p, max(10, int(CONVERT_PRESETS[p].iterations * scale)))
                   for p in ("draft", "balanced")]
    conversions.append(bench_inverse(mesh, maps, "balanced", max(10, int(300 * scale)), every=max(5, int(25 * scale))))

    env = environment_info()
    md = [f"Machine: {machine()}; Mitsuba variant {env['mitsuba_variant']}; torch {env['torch']}, "
          f"{torch.get_num_threads()} threads. Total bench time {time.perf_counter() - started:.0f} s.", "",
          "Render + backward (gradients to base colour, roughness, metallic), 256², 16 spp, median of 10:", "",
          table(renders, [("scene", "scene", ""), ("triangles", "triangles", ""), ("texture", "texture", ""),
                          ("s / iteration", "render_backward_s", ".3f"), ("first call (compile) s", "first_call_s", ".2f")]),
          "", "Neural texture forward + backward over the example's texels (median of 5):", "",
          table(textures, [("preset", "preset", ""), ("resolution", "resolution", ""), ("texels", "texels", ""),
                           ("s / iteration", "forward_backward_s", ".3f")]),
          "", "Conversion of the example's 512² maps (PSNR on covered texels; sRGB base colour, linear roughness/metallic):", "",
          table(conversions, [("method", "method", ""), ("preset", "preset", ""), ("resolution", "resolution", ""),
                              ("iterations", "iterations", ""), ("seconds", "seconds", ".1f"),
                              ("PSNR dB", "final_psnr", ".2f")]), "",
          "PSNR against iterations and seconds: `conversion_psnr.png`."]
    plot(conversions, RESULTS / "conversion_psnr.png")

    # The adapt stage (tiny random-weight models on the CPU; an SD2-sized UNet where CUDA exists).
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_adapt import bench_adapt

    adapt = bench_adapt(quick=args.quick)
    md += ["", "## Adapt", "", adapt["markdown"]]

    # Batches: jobs per hour in-process and on 1 and 2 local Ray workers; the paper's settings on N GPUs.
    from bench_batch import bench_batch

    batch = bench_batch(quick=args.quick, adapt_rows=adapt["rows"])
    md += ["", "## Batches", "", batch["markdown"]]
    (RESULTS / "batch.md").write_text(batch["markdown"] + "\n")
    (RESULTS / "batch.json").write_text(json.dumps({"rows": batch["rows"], "estimate": batch["estimate"]},
                                                   indent=1, default=float))
    (RESULTS / "bench.json").write_text(json.dumps({"machine": machine(), "environment": env, "render": renders,
                                                     "texture": textures, "conversion": conversions,
                                                     "adapt": adapt["rows"]}, indent=1, default=float))

    # Speed against accuracy per preset, for each stage and end to end (each in its own process).
    from bench_presets import bench_presets

    presets = bench_presets(example_asset(), quick=args.quick,
                            demo_presets=("draft",) if args.quick else ("draft", "balanced", "final"))
    md += ["", "## Presets: speed against accuracy", "", presets["markdown"]]

    # Light estimation against ground-truth HDR maps (its own script: writes light.md/json and the curve).
    subprocess.run([sys.executable, str(Path(__file__).with_name("bench_light.py"))] + (["--quick"] if args.quick else []),
                   check=True)
    md += ["", "## Light estimation", "", (RESULTS / "light.md").read_text()]

    # Composition: noise of the final render against a high-sample reference, raw and denoised.
    subprocess.run([sys.executable, str(Path(__file__).with_name("bench_compose.py"))] + (["--quick"] if args.quick else []),
                   check=True)
    md += ["", "## Composition", "", (RESULTS / "compose.md").read_text()]
    (RESULTS / "bench.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
