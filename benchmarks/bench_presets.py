"""Speed against accuracy per preset: each stage and the whole demo, for draft / balanced / final.

Every measurement runs in its own child process, so its peak memory (the child's maximum resident
set, imports included; the baseline of importing SceneFit is given separately) is its own. Quality is
what the stage is for:
- convert: PSNR of the baked neural texture against the example's maps (covered texels);
- light (prior; no diffusion weights here): the error of the estimated map against the true HDR map,
  as diffuse-sphere RMSE and glossy-sphere si-RMSE (photos cut from Blender's `interior` and `city`);
- end to end (`scenefit demo --guidance none`: light, convert, bake, render): conversion PSNR and the
  PSNR of renders of the converted texture against renders of the original maps.

Writes benchmarks/results/presets.md, presets.json and presets.png (seconds and peak memory against
quality, one panel per stage). `python benchmarks/bench_presets.py [--quick]`.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
PRESETS = ("draft", "balanced", "final")

# Each child prints one line "RESULT {json}" with its measurements and its own peak memory.
# SCENEFIT_BENCH_THREADS sets torch's threads in every child (on a machine shared with other jobs, two
# torch threads spin against each other: a 20-step fit took 47 s with 2 threads and 6 s with 1).
PEAK = ("import os, resource, torch; peak_mb = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024\n"
        "torch.set_num_threads(int(os.environ.get('SCENEFIT_BENCH_THREADS', torch.get_num_threads())))")

BASELINE = f"""
{PEAK}
import scenefit.core.pipeline, scenefit.core.lighting
print("RESULT", json.dumps({{"peak_mb": peak_mb()}}))
"""

CONVERT = f"""
{PEAK}
import time
from scenefit.core.asset_io import load_asset_folder
from scenefit.core.convert import convert_preset, convert_asset
mesh, maps = load_asset_folder(ASSET)
config = convert_preset(PRESET, resolution=RESOLUTION, iterations=ITERATIONS or convert_preset(PRESET).iterations)
t = time.perf_counter()
result = convert_asset(mesh, maps, config)
print("RESULT", json.dumps({{"seconds": time.perf_counter() - t, "psnr_db": result.psnr, "peak_mb": peak_mb(),
                             "iterations": config.iterations, "resolution": result.raster.resolution[0]}}))
"""

LIGHT = f"""
{PEAK}
import time
import numpy as np
from scenefit.core.imageio import read_image
from scenefit.core.lighting import estimate_light, light_preset
from scenefit.core.lighting.depth import DepthConfig
from scenefit.core.lighting.measure import SphereProbe, compare_maps
from scenefit.core.photo import PhotoCamera, camera_exposure, develop_photo, perspective_view, studiolight_path
import cv2
rows, seconds = [], 0.0
for name, scene_type in (("interior", "indoor"), ("city", "outdoor")):
    hdr = read_image(studiolight_path(name))[..., :3]
    camera = PhotoCamera(yaw_deg=60.0, pitch_deg=-10.0, fov_deg=60.0, width=320, height=240)
    radiance = perspective_view(hdr, camera)
    exposure = camera_exposure(radiance)
    photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
    truth = cv2.resize(np.ascontiguousarray(hdr * exposure, np.float32), (128, 64), interpolation=cv2.INTER_AREA)
    config = light_preset(PRESET, scene_type=scene_type, depth=DepthConfig(depth_type="geometric"))
    t = time.perf_counter()
    result = estimate_light(photo, (160.0, 200.0), config, photo_camera=camera)
    seconds += time.perf_counter() - t
    rows.append(compare_maps(result.hdr, truth, SphereProbe((64, 128), azimuth_deg=60.0 - 90.0, spp=64)))
mean = lambda key: float(np.mean([r[key] for r in rows]))
print("RESULT", json.dumps({{"seconds": seconds, "diffuse_rmse": mean("diffuse_rmse"),
                             "glossy_si_rmse": mean("glossy_si_rmse"), "peak_mb": peak_mb(),
                             "map_height": config.map_height}}))
"""

DEMO = f"""
{PEAK}
import runpy, sys, time
sys.argv = ["scenefit", "demo", "--out", OUT, "--preset", PRESET, "--guidance", "none", "--quiet", "--replace"]
t = time.perf_counter()
try:
    runpy.run_module("scenefit.cli", run_name="__main__")
except SystemExit as stop:
    assert not stop.code, stop.code
report = json.loads(open(OUT + "/report.json").read())
print("RESULT", json.dumps({{"seconds": time.perf_counter() - t, "peak_mb": peak_mb(),
                             "psnr_db": report["convert"]["psnr_covered_texels_db"],
                             "compose_spp": report["compose"]["spp"],
                             "timings": report["timings_seconds"]}}))
"""


def child(code: str, **values) -> dict:
    header = "import json\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items())
    proc = subprocess.run([sys.executable, "-c", header + textwrap.dedent(code)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"bench child failed:\n{proc.stderr[-3000:]}")
    line = next(l for l in proc.stdout.splitlines() if l.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def plot(stages: dict[str, tuple[list[dict], str, str, bool]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(stages), figsize=(4.2 * len(stages), 7), squeeze=False)
    for col, (title, (rows, key, label, higher_better)) in enumerate(stages.items()):
        for row_index, (cost, cost_label) in enumerate((("seconds", "seconds"), ("peak_mb", "peak memory (MB)"))):
            ax = axes[row_index][col]
            xs, ys = [r[cost] for r in rows], [r[key] for r in rows]
            ax.plot(xs, ys, "o-")
            for r, x, y in zip(rows, xs, ys):
                ax.annotate(r["preset"], (x, y), textcoords="offset points", xytext=(4, 4))
            ax.set_xlabel(cost_label)
            ax.set_ylabel(label + (" (higher is better)" if higher_better else " (lower is better)"))
            ax.grid(alpha=0.3)
            if row_index == 0:
                ax.set_title(title)
    fig.suptitle("Presets: cost against the quality each stage is for")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def bench_presets(asset: Path, quick: bool = False, presets=PRESETS, demo_presets=PRESETS) -> dict:
    from run import table  # benchmarks/ is on sys.path (run.py and main() below put it there)
    from scenefit.core.convert import CONVERT_PRESETS

    started = time.perf_counter()
    baseline = child(BASELINE)["peak_mb"]
    resolution = 256
    convert = [{"preset": p, **child(CONVERT, ASSET=str(asset), PRESET=p, RESOLUTION=resolution,
                                     ITERATIONS=max(10, CONVERT_PRESETS[p].iterations // 5) if quick else None)}
               for p in presets]
    light = [{"preset": p, **child(LIGHT, PRESET=p)} for p in presets]
    demo = []
    with tempfile.TemporaryDirectory(prefix="scenefit-bench-demo-") as tmp:
        for p in demo_presets:
            out = Path(tmp) / p
            shutil.copytree(asset, out / "input" / "asset")        # the demo reuses the example asset
            demo.append({"preset": p, **child(DEMO, OUT=str(out), PRESET=p)})
    seconds = time.perf_counter() - started
    import os

    threads = os.environ.get("SCENEFIT_BENCH_THREADS", "torch's default")
    md = [f"Peak memory is each child process's maximum resident set; importing SceneFit alone takes "
          f"{baseline:.0f} MB. torch threads: {threads}. Total {seconds:.0f} s.", "",
          f"Convert (the example's 512² maps fitted at {resolution}², the preset's network and "
          f"{'a fifth of its' if quick else 'its'} iterations):", "",
          table(convert, [("preset", "preset", ""), ("iterations", "iterations", ""), ("seconds", "seconds", ".1f"),
                          ("peak MB", "peak_mb", ".0f"), ("PSNR dB", "psnr_db", ".2f")]), "",
          "Light (inverse-tone-mapping prior, geometric depth; photos of `interior` and `city`; error of the map "
          "against the true one at 64x128, mean of the two):", "",
          table(light, [("preset", "preset", ""), ("map rows", "map_height", ""), ("seconds", "seconds", ".2f"),
                        ("peak MB", "peak_mb", ".0f"), ("diffuse RMSE", "diffuse_rmse", ".4g"),
                        ("glossy si-RMSE", "glossy_si_rmse", ".4g")]), "",
          "End to end (`scenefit demo --guidance none`: light, convert at the asset's 512², bake, compose twice):", "",
          table(demo, [("preset", "preset", ""), ("seconds", "seconds", ".1f"), ("peak MB", "peak_mb", ".0f"),
                       ("conversion PSNR dB", "psnr_db", ".2f"), ("composite spp", "compose_spp", "")]), "",
          "Cost against quality: `presets.png`."]
    RESULTS.mkdir(parents=True, exist_ok=True)
    plot({"convert": (convert, "psnr_db", "texture PSNR dB", True),
          "light (prior)": (light, "diffuse_rmse", "diffuse RMSE vs true map", False),
          "end to end (demo)": (demo, "psnr_db", "conversion PSNR dB", True)}, RESULTS / "presets.png")
    data = {"baseline_mb": baseline, "convert": convert, "light": light, "demo": demo, "seconds": seconds}
    (RESULTS / "presets.json").write_text(json.dumps(data, indent=1))
    (RESULTS / "presets.md").write_text("\n".join(md) + "\n")
    return {"rows": data, "markdown": "\n".join(md)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="a fifth of the conversion iterations, draft demo only (smoke run)")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import example_asset

    out = bench_presets(example_asset(), quick=args.quick, demo_presets=("draft",) if args.quick else PRESETS)
    print(out["markdown"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
