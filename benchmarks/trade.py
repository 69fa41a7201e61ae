"""Speed against accuracy per preset (issue 10): each stage and the whole `scenefit run`, for draft /
balanced / final.

Every measurement runs in its own child process, so its peak memory (the child's maximum resident
set, imports included; the baseline of importing SceneFit is given separately) is its own. Quality is
what the stage is for:
- convert: PSNR of the neural texture against the example's maps (covered texels);
- light: error of the estimated map against the true HDR map on the development maps (photos cut
  from Blender's CC0 `studio`, `interior`, `city`, `forest`), as diffuse-sphere RMSE and
  glossy-sphere si-RMSE; without diffusion weights the stage is the cue prior, so the critic's cost
  per iteration (apparatus renders + backward, the reference critic standing in for the diffusion
  one) is measured and projected to the preset's iterations;
- compose: RMSE (display sRGB, over the pixels the object and its shadow change) of the composite
  against the same composite at a high sample count;
- adapt: seconds per iteration with TINY random-weight models (devtools/tiny_models.py) and the
  preset's render sizes, samples and views per step; no quality (random weights have none);
- end to end (core.run.run_pipeline, what `scenefit run --guidance none` does): the example in a
  photo cut from `city` with the true camera; conversion PSNR, light error against the true map and
  composite RMSE against the ideal composite (the asset's own maps under the true map, high spp).

Where the full preset is too slow for a 2-core machine the cut is the same for every preset and the
table says so. Writes trade_<stage>.md/.json/.png for convert, light, compose, adapt and run.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

PRESETS = ("draft", "balanced", "final")

# Each child prints one line "RESULT {json}" with its measurements and its own peak memory.
# SCENEFIT_BENCH_THREADS sets torch's threads in every child (on a machine shared with other jobs, two
# torch threads spin against each other).
PRELUDE = ("import os, resource, json, time, torch; peak_mb = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024\n"
           "torch.set_num_threads(int(os.environ.get('SCENEFIT_BENCH_THREADS', torch.get_num_threads())))\n")

BASELINE = """
import scenefit.core.pipeline.run, scenefit.core.stages.light, scenefit.core.stages.compose
print("RESULT", json.dumps({"peak_mb": peak_mb()}))
"""

# The development photos: 320x240, 60 deg, pitch -10, cut from each map at YAWS and exposed as a
# camera meters; the truth is the map in the photo's exposure.
PHOTOS = """
import numpy as np, cv2
from scenefit.core.data.imageio import read_image
from scenefit.core.render.photo import camera_exposure, develop_photo, perspective_view, studiolight_path
from scenefit.core.scene.camera import PhotoCamera
def development_photo(name, yaw):
    hdr = read_image(studiolight_path(name))[..., :3]
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=-10.0, fov_deg=60.0, width=320, height=240)
    radiance = perspective_view(hdr, camera)
    exposure = camera_exposure(radiance)
    return camera, develop_photo(radiance, exposure).astype(np.float32) / 255.0, (hdr * exposure).astype(np.float32)
def resized(envmap, height):
    return cv2.resize(np.ascontiguousarray(envmap, np.float32), (2 * height, height), interpolation=cv2.INTER_AREA)
"""

CONVERT = """
from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.stages.convert import convert_asset
from scenefit.core.pipeline.presets import stage_config
mesh, maps = load_asset_folder(ASSET)
config = stage_config("convert", PRESET, init_type="fit", resolution=RESOLUTION,   # the paper's fit, per preset
                      iterations=max(5, round(stage_config("convert", PRESET).iterations * FRACTION)))
t = time.perf_counter()
result = convert_asset(mesh, maps, config)
print("RESULT", json.dumps({"seconds": time.perf_counter() - t, "psnr_db": result.psnr, "peak_mb": peak_mb(),
                            "iterations": config.iterations, "resolution": result.raster.resolution[0]}))
"""

LIGHT = PHOTOS + """
from dataclasses import replace
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.depth import DepthConfig
from scenefit.core.stages.light.measure import SphereProbe, compare_maps
from scenefit.core.pipeline.presets import stage_config
config = stage_config("light", PRESET, critic_type="none", depth=DepthConfig(depth_type="geometric"))
views = [(name, yaw) for name in MAPS for yaw in YAWS]
camera, photo, _ = development_photo(*views[0])
t = time.perf_counter()
estimate_light(photo, (160.0, 200.0), config, photo_camera=camera)       # first call: imports, caches
first_s = time.perf_counter() - t
rows, seconds, working = [], 0.0, None
for name, yaw in views:
    camera, photo, hdr = development_photo(name, yaw)
    t = time.perf_counter()
    result = estimate_light(photo, (160.0, 200.0), config, photo_camera=camera)
    seconds += time.perf_counter() - t
    working = result.panorama.ldr.shape[0]
    truth = resized(hdr, config.map_height)
    rows.append(compare_maps(result.hdr, truth, SphereProbe(truth.shape[:2], azimuth_deg=yaw - 90.0, spp=PROBE_SPP)))
# The critic's cost: apparatus renders at the preset's size and spp, per iteration (reference critic).
camera, photo, hdr = development_photo(*views[0])
truth = resized(hdr, config.map_height)
def optimised(iterations):
    critic = replace(config, critic_type="reference", optimise=replace(config.optimise, iterations=iterations))
    return estimate_light(photo, (160.0, 200.0), critic, photo_camera=camera, reference_envmap=truth).optimisation
optimised(1)                                                             # compiles the apparatus kernels
critic_s = optimised(CRITIC_ITERATIONS).seconds / CRITIC_ITERATIONS
mean = lambda key: float(np.mean([r[key] for r in rows]))
print("RESULT", json.dumps({"seconds": seconds / len(views), "first_call_s": first_s, "views": len(views),
                            "diffuse_rmse": mean("diffuse_rmse"), "diffuse_si_rmse": mean("diffuse_si_rmse"),
                            "glossy_si_rmse": mean("glossy_si_rmse"), "peak_mb": peak_mb(),
                            "map_height": config.map_height, "working_height": working,
                            "critic_iteration_s": critic_s, "critic_iterations": config.optimise.iterations,
                            "critic_render": f"{config.apparatus.render_size}px {config.apparatus.spp}spp"}))
"""

COMPOSE = PHOTOS + """
from dataclasses import replace
from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.stages.compose import ComposeInputs, compose
from scenefit.core.stages.convert import target_stack
from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.pipeline.presets import stage_config
camera, photo, hdr = development_photo("city", 90.0)
mesh, maps = load_asset_folder(ASSET)
inputs = ComposeInputs(mesh, target_stack(maps, 512), photo, (160.0, 200.0), resized(hdr, 128), camera)
config = stage_config("compose", PRESET, size=0.4) if PRESET != "reference" else \\
    stage_config("compose", "final", size=0.4, spp=REFERENCE_SPP, denoiser_type="none")
t = time.perf_counter()
if PRESET != "reference":
    compose(inputs, config)                          # first call: Mitsuba compiles the kernels for this spp
first_s = time.perf_counter() - t
t = time.perf_counter()
result = compose(inputs, config)
seconds = time.perf_counter() - t
np.savez(OUT, composite=result.composite_srgb, changed=result.changed)
print("RESULT", json.dumps({"seconds": seconds, "first_call_s": first_s, "peak_mb": peak_mb(), "spp": result.report["spp"],
                            "denoiser": str(result.report.get("denoiser")), "changed_px": int(result.changed.sum())}))
"""

ADAPT = """
import sys
sys.path.insert(0, BENCHMARKS)
from bench_adapt import preset_row
row = preset_row(PRESET, ITERATIONS)
print("RESULT", json.dumps({**row, "peak_mb": peak_mb()}))
"""

RUN = PHOTOS + """
from dataclasses import replace
from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.stages.compose import ComposeInputs, compose
from scenefit.core.stages.convert import target_stack
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.stages.light.measure import SphereProbe, compare_maps
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.pipeline.run import RunConfig, run_pipeline
camera, photo, hdr = development_photo("city", 90.0)
photo_path = write_image(OUT + "/photo.png", photo)
mesh, maps = load_asset_folder(ASSET)
t = time.perf_counter()
report = run_pipeline(mesh, maps, photo_path, (160.0, 200.0), OUT + "/run",
                      RunConfig(preset=PRESET, guidance_type="none", size=0.4, photo_camera=camera)).to_report()
seconds = time.perf_counter() - t
peak = peak_mb()
stages = report["stages"]
light = read_image(OUT + "/run/light/light.exr")[..., :3]
truth = resized(hdr, light.shape[0])
light_error = compare_maps(light, truth, SphereProbe(light.shape[:2], azimuth_deg=0.0, spp=64))
import os
if not os.path.exists(IDEAL):                        # the same for every preset: made once
    ideal = compose(ComposeInputs(mesh, target_stack(maps, 512), read_image(photo_path)[..., :3],
                                  (160.0, 200.0), resized(hdr, 256), camera),
                    stage_config("compose", "final", size=0.4, spp=REFERENCE_SPP, denoiser_type="none"))
    np.savez(IDEAL, composite=ideal.composite_srgb, changed=ideal.changed)
ideal = np.load(IDEAL)
composite = read_image(OUT + "/run/compose/composite.png")[..., :3]
region = ideal["changed"] | np.any(np.abs(composite - ideal["composite"]) > 2 / 255, axis=-1)
print("RESULT", json.dumps({"seconds": seconds, "peak_mb": peak,
                            "stage_seconds": {k: v.get("seconds") for k, v in stages.items() if v["status"] == "ran"},
                            "psnr_db": stages["convert"]["report"]["psnr_covered_texels_db"],
                            "texture": stages["convert"]["report"]["decisions"]["resolution"],
                            "map_height": int(light.shape[0]), "light_diffuse_rmse": light_error["diffuse_rmse"],
                            "compose_spp": stages["compose"]["report"]["spp"],
                            "composite_rmse": float(np.sqrt(np.mean((composite[region] - ideal["composite"][region]) ** 2)))}))
"""


def child(code: str, **values) -> dict:
    header = "".join(f"{k} = {v!r}\n" for k, v in values.items())
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run([sys.executable, "-c", PRELUDE + header + textwrap.dedent(code)], capture_output=True,
                          text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"bench child failed:\n{proc.stderr[-3000:]}")
    line = next(l for l in proc.stdout.splitlines() if l.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


@dataclass(frozen=True)
class Cut:
    """How far `make bench` shrinks the presets' work (the same for every preset; the tables say so)."""

    convert_resolution: int = 128    # the example's 512² maps fitted at 128² (the preset's network and iterations)
    convert_fraction: float = 1.0    # of the preset's conversion iterations
    light_maps: tuple[str, ...] = ("studio", "interior", "city", "forest")
    light_yaws: tuple[float, ...] = (0.0, 120.0, 240.0)
    probe_spp: int = 64
    critic_iterations: int = 2
    reference_spp: int = 1024
    adapt_iterations: int = 1

    @staticmethod
    def quick() -> "Cut":
        return Cut(convert_resolution=64, convert_fraction=0.1, light_maps=("interior", "city"), light_yaws=(0.0,),
                   probe_spp=16, critic_iterations=1, reference_spp=128, adapt_iterations=1)


def plot(rows: list[dict], quality: str, label: str, higher_better: bool, title: str, path: Path) -> None:
    """Seconds and peak memory against the stage's quality, one point per preset."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    for ax, (cost, cost_label) in zip(axes, (("seconds", "seconds"), ("peak_mb", "peak memory (MB)"))):
        xs, ys = [r[cost] for r in rows], [r[quality] for r in rows]
        ax.plot(xs, ys, "o-")
        for r, x, y in zip(rows, xs, ys):
            ax.annotate(r["preset"], (x, y), textcoords="offset points", xytext=(4, 4))
        ax.set_xlabel(cost_label)
        ax.set_ylabel(label + (" (higher is better)" if higher_better else " (lower is better)"))
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_stage(results: Path, stage: str, text: str, rows: list[dict], columns, quality: tuple[str, str, bool],
                title: str) -> str:
    """trade_<stage>.md (text + table + plot link), .json and .png; returns the markdown."""
    from run import table

    plot(rows, quality[0], quality[1], quality[2], title, results / f"trade_{stage}.png")
    md = "\n".join([text, "", table(rows, columns), "", f"![{stage}: cost against quality](trade_{stage}.png)"])
    (results / f"trade_{stage}.md").write_text(md + "\n")
    (results / f"trade_{stage}.json").write_text(json.dumps({"text": text, "rows": rows}, indent=1, default=float))
    return md


def bench_trade(asset: Path, results: Path, quick: bool = False, stages=("convert", "light", "compose", "adapt", "run"),
                log=print) -> dict:
    cut = Cut.quick() if quick else Cut()
    results.mkdir(parents=True, exist_ok=True)
    out: dict = {"baseline_mb": child(BASELINE)["peak_mb"]}
    bench_dir = str(Path(__file__).resolve().parent)
    common = (f"Peak memory: the measuring process's maximum resident set (importing SceneFit alone: "
              f"{out['baseline_mb']:.0f} MB).")

    if "convert" in stages:
        rows = []
        for p in PRESETS:
            rows.append({"preset": p, **child(CONVERT, ASSET=str(asset), PRESET=p, RESOLUTION=cut.convert_resolution,
                                               FRACTION=cut.convert_fraction)})
            log(f"convert {rows[-1]}")
        share = "all" if cut.convert_fraction == 1 else f"{cut.convert_fraction:g} of"
        text = (f"Convert: the example's 512² maps fitted at {cut.convert_resolution}² (cut: at the asset's 512² "
                f"each iteration costs about 10x more; the end-to-end table fits the size the composite shows) with "
                f"the preset's network and {share} its iterations; PSNR on covered texels. {common}")
        out["convert"] = write_stage(results, "convert", text, rows, [
            ("preset", "preset", ""), ("iterations", "iterations", ""), ("seconds", "seconds", ".1f"),
            ("peak MB", "peak_mb", ".0f"), ("PSNR dB", "psnr_db", ".2f")],
            ("psnr_db", "texture PSNR dB", True), "Convert: cost against texture PSNR")

    if "light" in stages:
        rows = []
        for p in PRESETS:
            rows.append({"preset": p, **child(LIGHT, PRESET=p, MAPS=list(cut.light_maps), YAWS=list(cut.light_yaws),
                                               PROBE_SPP=cut.probe_spp, CRITIC_ITERATIONS=cut.critic_iterations)})
            rows[-1]["critic_projected_s"] = rows[-1]["critic_iteration_s"] * rows[-1]["critic_iterations"]
            log(f"light {rows[-1]}")
        text = (f"Light on the development maps ({', '.join(cut.light_maps)}; {len(cut.light_yaws)} photo(s) each, "
                f"320x240, 60 deg, pitch -10; geometric depth, automatic scene type). Without diffusion weights the "
                f"stage is the cue prior: seconds are its mean per photo after a first call (imports, caches: first "
                f"s), errors are against the true map at the preset's map size (diffuse / glossy sphere, "
                f"{cut.probe_spp} spp). With weights a critic optimises the scales: its cost per iteration is "
                f"measured with the reference critic (the same apparatus renders and backward; the diffusion "
                f"critic adds a UNet pass, see adapt) and projected to the preset's iterations. {common}")
        out["light"] = write_stage(results, "light", text, rows, [
            ("preset", "preset", ""), ("map rows", "map_height", ""), ("built at rows", "working_height", ""),
            ("seconds", "seconds", ".3f"), ("first s", "first_call_s", ".2f"), ("peak MB", "peak_mb", ".0f"),
            ("diffuse RMSE", "diffuse_rmse", ".4g"), ("diffuse si-RMSE", "diffuse_si_rmse", ".4g"),
            ("glossy si-RMSE", "glossy_si_rmse", ".4g"), ("critic renders", "critic_render", ""),
            ("critic s / iteration", "critic_iteration_s", ".3f"), ("critic iterations", "critic_iterations", ""),
            ("critic s (projected)", "critic_projected_s", ".0f")],
            ("diffuse_rmse", "diffuse RMSE vs true map", False), "Light (cue prior): cost against error")

    if "compose" in stages:
        with tempfile.TemporaryDirectory(prefix="scenefit-bench-compose-") as tmp:
            import numpy as np

            ref = child(COMPOSE, ASSET=str(asset), PRESET="reference", REFERENCE_SPP=cut.reference_spp,
                        OUT=f"{tmp}/reference.npz")
            reference = np.load(f"{tmp}/reference.npz")
            rows = []
            for p in PRESETS:
                row = child(COMPOSE, ASSET=str(asset), PRESET=p, REFERENCE_SPP=cut.reference_spp, OUT=f"{tmp}/{p}.npz")
                mine = np.load(f"{tmp}/{p}.npz")
                region = reference["changed"] | mine["changed"]
                diff = mine["composite"][region] - reference["composite"][region]
                rows.append({"preset": p, **row, "rmse": float(np.sqrt(np.mean(diff ** 2)))})
                log(f"compose {rows[-1]}")
        text = (f"Compose: the example (its own maps) in a 320x240 photo cut from `city`, under the true map, "
                f"object 0.4 of the photo's height, ratio shadow; spp from the preset's noise target, OIDN. "
                f"Error: RMSE in display sRGB over the {ref['changed_px']} pixels the object and shadow change, "
                f"against the same composite at {cut.reference_spp} spp without denoising ({ref['seconds']:.0f} s). "
                f"Seconds: a second call (the first compiles Mitsuba's kernels for that spp: first call s). {common}")
        out["compose"] = write_stage(results, "compose", text, rows, [
            ("preset", "preset", ""), ("spp", "spp", ""), ("seconds", "seconds", ".2f"),
            ("first call s", "first_call_s", ".1f"), ("peak MB", "peak_mb", ".0f"),
            ("composite RMSE", "rmse", ".4f")],
            ("rmse", "composite RMSE vs high-spp", False), "Compose: cost against composite error")

    if "adapt" in stages:
        rows = []
        for p in PRESETS:
            rows.append({"preset": p, **child(ADAPT, BENCHMARKS=bench_dir, PRESET=p, ITERATIONS=cut.adapt_iterations)})
            rows[-1]["spp_text"] = f"{rows[-1]['spp']} ({rows[-1]['measured_spp']})"
            rows[-1]["seconds"] = rows[-1]["projected_iteration_s"]   # the plot's cost: s per iteration
            log(f"adapt {rows[-1]}")
        text = ("Adapt with TINY random-weight models (devtools/tiny_models.py, a few-channel UNet at 64 px, not "
                "SD2): the preset's render sizes and views per step on a UV sphere, local and global views, so "
                "these seconds are the stage's renders and bookkeeping, not Stable Diffusion; random weights give "
                "no quality to measure. Cut: 1/8 of the preset's samples per pixel (the same for every preset); "
                "rendering is linear in samples, so the per-iteration cost at the preset's own spp is projected "
                "as render + render backward x 8 + the rest, and times the preset's iterations. Measured: "
                f"{cut.adapt_iterations} iteration(s) after a warm-up. {common}")
        out["adapt"] = write_stage(results, "adapt", text, rows, [
            ("preset", "preset", ""), ("render px", "render_size", ""), ("views / step", "views_per_step", ""),
            ("spp (measured at)", "spp_text", ""),
            ("s / iteration measured", "iteration_s", ".2f"), ("of which render + backward", "render_s", ".2f"),
            ("s / iteration at the preset's spp (projected)", "projected_iteration_s", ".1f"),
            ("iterations", "preset_iterations", ""), ("stage s (projected, tiny)", "projected_s", ".0f"),
            ("peak MB", "peak_mb", ".0f")],
            ("render_size", "render size px (what the preset renders)", True),
            "Adapt (tiny models): s per iteration at the preset's spp (projected) and peak memory")

    if "run" in stages:
        rows = []
        with tempfile.TemporaryDirectory(prefix="scenefit-bench-run-") as tmp:
            for p in PRESETS:
                folder = Path(tmp) / p
                folder.mkdir()
                rows.append({"preset": p, **child(RUN, ASSET=str(asset), PRESET=p, OUT=str(folder),
                                                   REFERENCE_SPP=cut.reference_spp, IDEAL=f"{tmp}/ideal.npz")})
                for stage, s in rows[-1]["stage_seconds"].items():
                    rows[-1][f"{stage}_s"] = s
                log(f"run {rows[-1]}")
        text = (f"End to end: `run_pipeline` (what `scenefit run --guidance none` does; no SD2 weights here, so "
                f"adapt is skipped) on the example in a 320x240 photo cut from `city` with the true camera, the object "
                f"0.4 of the photo's height (so the texture is fitted at the size the composite shows, not at "
                f"512²; nothing is cut). Quality: conversion PSNR, "
                f"light diffuse RMSE against the true map, composite RMSE (display sRGB, object and shadow "
                f"pixels) against the ideal composite: the asset's own maps under the true map at "
                f"{cut.reference_spp} spp. {common}")
        out["run"] = write_stage(results, "run", text, rows, [
            ("preset", "preset", ""), ("seconds", "seconds", ".1f"), ("convert s", "convert_s", ".1f"),
            ("light s", "light_s", ".2f"), ("compose s", "compose_s", ".1f"), ("peak MB", "peak_mb", ".0f"),
            ("texture", "texture", ""), ("conversion PSNR dB", "psnr_db", ".2f"), ("map rows", "map_height", ""),
            ("light RMSE", "light_diffuse_rmse", ".4g"), ("compose spp", "compose_spp", ""),
            ("composite RMSE", "composite_rmse", ".4f")],
            ("composite_rmse", "composite RMSE vs ideal", False), "scenefit run: cost against composite error")
    return out


def main() -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="a smoke run (results in benchmarks/results/quick)")
    parser.add_argument("--stages", default="convert,light,compose,adapt,run")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import RESULTS, example_asset

    results = RESULTS / "quick" if args.quick else RESULTS
    out = bench_trade(example_asset(), results, quick=args.quick, stages=tuple(args.stages.split(",")))
    print("\n\n".join(v for v in out.values() if isinstance(v, str)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
