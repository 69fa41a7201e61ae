"""Light estimation against ground truth: Blender's CC0 HDR maps (studio, interior, city, forest).

For each map, photos are perspective crops of it (several view directions, 8-bit, highlights clipped
by the camera's auto-exposure), and the estimated map is compared with the true one expressed in the
photo's exposure (a photo fixes radiance only up to its exposure). Methods:
- constant: a uniform environment of the photo's mean linear colour (what the demo used before);
- prior: the LDR panorama with the inverse-tone-mapping prior's scales;
- reference: the scales optimised by the apparatus (object + white sphere) with the reference critic.

Writes benchmarks/results/light.md (the table), light.json and light_error_curve.png (the object's MSE
under the estimated vs the true map over iterations: the paper's "effectiveness of light estimation").
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from scenefit.core.imageio import read_image, srgb_to_linear
from scenefit.core.lighting import estimate_light
from scenefit.core.presets import stage_config
from scenefit.core.lighting.estimate import default_object
from scenefit.core.lighting.hdr import ApparatusScene, hdr_from_scales
from scenefit.core.lighting.measure import SphereProbe, compare_maps, object_mse
from scenefit.core.photo import PhotoCamera, camera_exposure, develop_photo, perspective_view, studiolight_path

RESULTS = Path(__file__).resolve().parent / "results"
MAPS = {"studio": "indoor", "interior": "indoor", "city": "outdoor", "forest": "outdoor"}
YAWS = (60.0, 240.0)
METHODS = ("constant", "prior", "reference")


def resize(envmap: np.ndarray, shape) -> np.ndarray:
    import cv2

    return cv2.resize(np.ascontiguousarray(envmap, np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA)


def run_one(name: str, scene_type: str, yaw: float, config, curve_every: int) -> dict:
    hdr = read_image(studiolight_path(name))[..., :3]
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=-10.0, fov_deg=60.0, width=320, height=240)
    radiance = perspective_view(hdr, camera)
    exposure = camera_exposure(radiance)
    photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
    shape = (config.map_height, 2 * config.map_height)
    truth = resize(hdr * exposure, shape)
    placement = (160.0, 200.0)

    # The same object views as the optimisation, for the paper's object MSE (more samples, fixed seed).
    mesh, maps = default_object()
    scene = ApparatusScene(mesh, maps, shape, config.apparatus, photo_azimuth_deg=yaw - 90.0)
    render = lambda env: scene.render(env, spp=16, seed=4242)[0]
    curve: list[tuple[int, float]] = []
    result_holder = {}

    def on_iteration(it: int, log_scales: dict) -> None:
        if it % curve_every == 0 or it == config.optimise.iterations - 1:
            res = result_holder["pano"]
            est = hdr_from_scales(res["ldr"], res["regions"], {k: math.exp(v) for k, v in log_scales.items()})
            curve.append((it + 1, object_mse(render, est, truth)))

    # Prior only first (it also gives the panorama the curve needs), then the reference optimisation.
    t = time.perf_counter()
    prior = estimate_light(photo, placement, replace(config, critic_type="none", scene_type=scene_type), photo_camera=camera)
    prior_seconds = time.perf_counter() - t
    result_holder["pano"] = {"ldr": prior.ldr, "regions": prior.regions}
    curve.append((0, object_mse(render, prior.hdr, truth)))
    t = time.perf_counter()
    ref = estimate_light(photo, placement, replace(config, critic_type="reference", scene_type=scene_type),
                         photo_camera=camera, reference_envmap=truth, on_iteration=on_iteration)
    ref_seconds = time.perf_counter() - t
    constant = np.broadcast_to(srgb_to_linear(photo).reshape(-1, 3).mean(0), truth.shape).astype(np.float32).copy()

    probe = SphereProbe(shape, azimuth_deg=yaw - 90.0, spp=64)
    rows = {}
    for method, est in (("constant", constant), ("prior", prior.hdr), ("reference", ref.hdr)):
        m = compare_maps(est, truth, probe)
        m["object_mse"] = object_mse(render, est, truth)
        rows[method] = m
    return {"map": name, "scene_type": scene_type, "yaw": yaw, "exposure": exposure,
            "auto_sky_score": prior.decisions["scene_type"]["sky_score"],
            "auto_says": prior.decisions["scene_type"]["scene_type"],
            "prior_scales": prior.scales, "reference_scales": ref.scales, "metrics": rows, "curve": curve,
            "seconds_prior": prior_seconds, "seconds_reference": ref_seconds,
            "iterations": config.optimise.iterations}


def table(runs: list[dict]) -> str:
    keys = [("diffuse RMSE", "diffuse_rmse"), ("diffuse si-RMSE", "diffuse_si_rmse"), ("glossy si-RMSE", "glossy_si_rmse"),
            ("dominant light err (deg)", "dominant_angle_deg"), ("object MSE", "object_mse")]
    lines = ["| map | method | " + " | ".join(k for k, _ in keys) + " |", "|" + "---|" * (len(keys) + 2)]
    for name in MAPS:
        mine = [r for r in runs if r["map"] == name]
        if not mine:
            continue
        for method in METHODS:
            vals = [np.mean([r["metrics"][method][k] for r in mine]) for _, k in keys]
            lines.append(f"| {name} ({mine[0]['scene_type']}) | {method} | " + " | ".join(f"{v:.4g}" for v in vals) + " |")
    return "\n".join(lines)


def plot(runs: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in runs:
        its, mse = zip(*r["curve"])
        ax.plot(its, np.asarray(mse) / max(mse[0], 1e-12), alpha=0.35, linewidth=1)
    # The mean of the curves normalised by their start: the average trend.
    grid = sorted({i for r in runs for i, _ in r["curve"]})
    mean = [np.mean([np.interp(g, *zip(*r["curve"])) / max(r["curve"][0][1], 1e-12) for r in runs]) for g in grid]
    ax.plot(grid, mean, color="black", linewidth=2.5, label="mean over maps and views")
    ax.set_xlabel("iteration")
    ax.set_ylabel("object MSE (estimated vs true map) / MSE at the prior")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("Effectiveness of light estimation (reference critic)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="one view per map, fewer iterations (smoke run)")
    args = parser.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    config = stage_config("light", "draft", map_height=64)
    if args.quick:
        config = replace(config, optimise=replace(config.optimise, iterations=20))
    yaws = YAWS[:1] if args.quick else YAWS
    runs = []
    for name, scene_type in MAPS.items():
        for yaw in yaws:
            torch.manual_seed(0)
            run = run_one(name, scene_type, yaw, config, curve_every=max(1, config.optimise.iterations // 10))
            runs.append(run)
            print(f"{name} yaw {yaw:.0f}: " + ", ".join(f"{m} objMSE {run['metrics'][m]['object_mse']:.4g}"
                                                         for m in METHODS), flush=True)
    md = [f"Light estimation against Blender's CC0 HDR maps: {len(yaws)} photo(s) per map (320x240, 60 deg, "
          f"pitch -10, yaws {', '.join(f'{y:.0f}' for y in yaws)}), map {config.map_height}x{2 * config.map_height}, "
          f"{config.optimise.iterations} iterations (lr {config.optimise.lr}), renders {config.apparatus.render_size}^2 "
          f"at {config.apparatus.spp} spp, geometric depth (no depth weights). Truth in the photo's exposure. "
          f"Means over the views; lower is better. Total {time.perf_counter() - started:.0f} s.", "", table(runs), "",
          "Error over iterations: `light_error_curve.png`."]
    (RESULTS / "light.md").write_text("\n".join(md) + "\n")
    (RESULTS / "light.json").write_text(json.dumps(runs, indent=1, default=float))
    plot(runs, RESULTS / "light_error_curve.png")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
