"""Why the light stage's unseen light cannot be right on both sides of the light (issue 21).

The done-when asks the estimate to beat the constant environment (the photo's mean colour) on the
diffuse sphere's RMSE on every view. The sphere is seen from the camera, so its visible side is lit
mostly by what is behind the camera: the part of the map the photo never saw. This bench measures,
on the light bench's real views (bench_light.py --real: the corpus's 12 maps and the 18 held-out ones,
toward and away from the dominant light, both meterings):

- how bright the truth is behind the camera, as the camera-facing irradiance over the photo's mean
  (E / c): a constant environment has 1; and the light stage's estimate (balanced, no critic);
- what a single brighter or darker flat environment (k times the constant, k from 1/4 to 16) buys on
  diffuse RMSE against the constant, with one k for both sides and with k chosen apart for the two
  sides (what knowing the side would buy);
- whether the photo tells the side: each of six whole-photo measures split at the threshold that
  is best on the development views, and that threshold's accuracy on the held-out views.

    python benchmarks/bench_light_sides.py   -> results/light_sides.md, light_sides.json, light_sides.png
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import bench_light as B
from heldout_hdri import FETCH_FAILED, HELD_OUT_MAPS, fetch_or_say, read_heldout
from scenefit.core.data.imageio import srgb_to_linear
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.render.photo import develop_photo, perspective_view
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.frame import equirect_directions
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.cues import LUMINANCE, solid_angles, surface_radiance
from scenefit.core.stages.light.measure import probe_geometry, render_probe, rmse
from scenefit.core.stages.light.regions import RegionThresholds

CONFIG = stage_config("light", "balanced")   # the light bench's estimate (no critic: no weights here)
LEVELS = tuple(float(k) for k in 2.0 ** np.arange(-2.0, 4.01, 0.25))   # k x the constant, 1/4 to 16
FEATURES = {   # whole-photo measures a side decision could rest on (photo: stored sRGB; linear: its radiance)
    "clipped fraction": lambda photo, lin: float((photo.max(-1) >= 0.98).mean()),
    "clipped fraction, upper half": lambda photo, lin: float((photo[: len(photo) // 2].max(-1) >= 0.98).mean()),
    "top third / bottom third": lambda photo, lin: float(_lum(lin)[: len(lin) // 3].mean()
                                                         / max(_lum(lin)[-(len(lin) // 3):].mean(), 1e-6)),
    "99th percentile / median": lambda photo, lin: float(np.percentile(_lum(lin), 99) / max(np.median(_lum(lin)), 1e-6)),
    "saturation": lambda photo, lin: float(np.mean((lin.max(-1) - lin.min(-1)) / np.maximum(lin.max(-1), 1e-4))),
    "surfaces / mean": lambda photo, lin: surface_radiance(photo, RegionThresholds().near)[1] / max(float(lin.mean()), 1e-6),
}


def _lum(linear: np.ndarray) -> np.ndarray:
    return linear @ LUMINANCE


def view_rows(name: str, hdr: np.ndarray, subset: str) -> list[dict]:
    h, w = B.REAL_MAP
    dirs, omega = equirect_directions(h, w), solid_angles(h, w) * np.ones((1, w))
    rows = []
    for side, yaw in B.real_views(hdr):
        camera = PhotoCamera(yaw_deg=yaw, pitch_deg=B.REAL_PITCH, fov_deg=60.0, width=B.REAL_PHOTO[0],
                             height=B.REAL_PHOTO[1])
        radiance = perspective_view(hdr, camera)
        forward = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), 0.0])
        for metering in B.METERINGS:
            exposure = B.metered_exposure(radiance, metering)
            photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
            linear = srgb_to_linear(photo)
            truth = B.resize(hdr, B.REAL_MAP) * exposure
            c = float(linear.mean())
            facing = np.maximum(dirs @ -forward, 0.0)
            irradiance = float((truth.mean(-1) * facing * omega).sum() / math.pi)
            estimate = B.resize(estimate_light(photo, B.REAL_PLACEMENT, CONFIG, photo_camera=camera).hdr, B.REAL_MAP)
            estimated = float((estimate.mean(-1) * facing * omega).sum() / math.pi)
            mask = probe_geometry(forward)[0]
            true_sphere = render_probe(truth, "diffuse", forward)[mask]
            flat = render_probe(np.broadcast_to(linear.reshape(-1, 3).mean(0), (*B.REAL_MAP, 3)).astype(np.float32),
                                "diffuse", forward)[mask]
            # A flat environment k times brighter renders a sphere k times brighter: one render serves every k.
            errors = [rmse(k * flat, true_sphere) for k in LEVELS]
            rows.append({"set": subset, "map": name, "side": side, "metering": metering, "ratio": irradiance / c,
                         "estimate_ratio": estimated / c,
                         "rmse_by_level": errors, "constant_rmse": rmse(flat, true_sphere),
                         "features": {f: fn(photo, linear) for f, fn in FEATURES.items()}})
    return rows


def level_table(rows: list[dict]) -> dict:
    """A flat environment k times the constant against the constant, per side: the median over the views
    of its diffuse RMSE / the constant's (below 1: better) and the views it beats the constant on, at the
    one k best for both sides at once (the smaller worst-side median) and at each side's own best k
    (what knowing the side would buy)."""
    ratios = np.array([[e / max(r["constant_rmse"], 1e-12) for e in r["rmse_by_level"]] for r in rows])
    toward = np.array([r["side"] == "toward" for r in rows])
    medians = {side: np.median(ratios[m], axis=0) for side, m in (("toward", toward), ("away", ~toward))}

    def at(index: int) -> dict:
        return {"level": LEVELS[index], **{side: {"median_ratio": round(float(medians[side][index]), 3),
                                                  "beats": int((ratios[m, index] < 1.0).sum()), "views": int(m.sum())}
                                           for side, m in (("toward", toward), ("away", ~toward))}}

    one = int(np.argmin(np.maximum(medians["toward"], medians["away"])))
    return {"one_level": at(one), "toward_best": at(int(np.argmin(medians["toward"]))),
            "away_best": at(int(np.argmin(medians["away"])))}


def side_split(train: list[dict], test: list[dict]) -> dict:
    """Each feature's best threshold on `train` (midway between two views' values, either direction) and
    its accuracy on both sets."""
    out = {}
    for feature in FEATURES:
        x = np.array([r["features"][feature] for r in train])
        t = np.array([r["side"] == "toward" for r in train])
        values = np.unique(x)
        cuts = (values[:-1] + values[1:]) / 2 if len(values) > 1 else values   # between neighbouring views
        best = max(((float(np.mean((x > th) == t if up else (x <= th) == t)), float(th), up)
                    for th in cuts for up in (True, False)))
        xt = np.array([r["features"][feature] for r in test])
        tt = np.array([r["side"] == "toward" for r in test])
        held = float(np.mean((xt > best[1]) == tt if best[2] else (xt <= best[1]) == tt)) if len(test) else None
        out[feature] = {"threshold": best[1], "toward_if_above": best[2], "development": best[0], "held_out": held}
    return out


def median_ratio(rows: list[dict], side: str, key: str = "ratio") -> float:
    return float(np.median([r[key] for r in rows if r["side"] == side]))


def report(rows: list[dict], seconds: float, load: str) -> tuple[str, dict]:
    dev = [r for r in rows if r["set"] == "development"]
    held = [r for r in rows if r["set"] == "held-out"]
    result = {"seconds": round(seconds, 1), "load": load, "levels": list(LEVELS),
              "ratio_medians": {s: {side: {key: round(median_ratio(part, side, key), 3)
                                           for key in ("ratio", "estimate_ratio")} for side in ("toward", "away")}
                                for s, part in (("development", dev), ("held-out", held)) if part},
              "levels_development": level_table(dev), "split": side_split(dev, held)}
    if held:
        result["levels_held_out"] = level_table(held)
    lines = ["# The light behind the camera: toward and away views (issue 21)", "",
             f"The light bench's real views (bench_light.py --real), toward and away from the dominant light, each "
             f"under median and log-average metering: {len(dev)} development (the corpus's 12 maps) and {len(held)} "
             "held-out (18 maps); the two meterings of a view barely move these ratios, so they rest on half as "
             "many distinct views. E / c: the truth's irradiance on a surface facing the camera over the photo's mean linear "
             "radiance (a constant environment has 1). A flat environment k times the constant, scored on the "
             "diffuse sphere's RMSE (bench_light.py's protocol) against the constant.", "",
             f"Run time {seconds:.0f} s; load: `{load}`.", "",
             "| views | E / c toward, truth | the estimate | E / c away, truth | the estimate |", "|---|---|---|---|---|"]
    for name, part in (("development", dev), ("held-out", held)):
        if part:
            lines.append(f"| {name} | " + " | ".join(f"{median_ratio(part, side, key):.2f}" for side in ("toward", "away")
                                                      for key in ("ratio", "estimate_ratio")) + " |")
    lines += ["", "A flat environment k times the constant: the median over each side's views of its diffuse RMSE / the "
              "constant's (below 1: better), with the views on which it beats the constant; at the one k best for "
              "both sides at once, and at each side's own best k.", "",
              "| views | k | toward: median ratio, beats | away: median ratio, beats |", "|---|---|---|---|"]
    for name in ("development", "held_out"):
        table = result.get(f"levels_{name}")
        for label, key in (("one k for both", "one_level"), ("toward's best k", "toward_best"),
                           ("away's best k", "away_best")):
            if table:
                row = table[key]
                lines.append(f"| {name.replace('_', '-')}, {label} | {row['level']:.2g} | "
                             + " | ".join(f"{row[side]['median_ratio']:.2f}, {row[side]['beats']} of {row[side]['views']}"
                                          for side in ("toward", "away")) + " |")
    lines += ["", "Telling the side from the photo: each measure split at its best threshold on the development views.", "",
              "| measure | toward when | development accuracy | held-out accuracy |", "|---|---|---|---|"]
    for feature, s in result["split"].items():
        held_text = f"{s['held_out']:.2f}" if s["held_out"] is not None else "-"
        lines.append(f"| {feature} | {'above' if s['toward_if_above'] else 'at most'} {s['threshold']:.3g} | "
                     f"{s['development']:.2f} | {held_text} |")
    return "\n".join(lines) + "\n", result


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    bins = np.logspace(-1.5, 2.0, 29)
    for ax, subset in zip(axes, ("development", "held-out")):
        for side, colour in (("toward", "tab:orange"), ("away", "tab:blue")):
            values = [r["ratio"] for r in rows if r["set"] == subset and r["side"] == side]
            ax.hist(values, bins=bins, alpha=0.6, color=colour, label=side)
        ax.axvline(1.0, color="k", lw=1, ls="--")
        ax.set_xscale("log")
        ax.set_title(f"{subset}: E / c behind the camera")
        ax.set_xlabel("camera-facing irradiance / photo mean (1: the constant)")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    import os

    folder = fetch_or_say("bench_light_sides")
    if folder is None:   # the committed results stay as they are: half a run would replace them
        return FETCH_FAILED
    started = time.perf_counter()
    rows = []
    for name in B.REAL_MAPS:
        rows += view_rows(name, B.read_corpus_map(B.CORPUS_HDRI / f"{name}_1k.hdr"), "development")
    for name in HELD_OUT_MAPS:
        rows += view_rows(name, read_heldout(folder / f"{name}.exr"), "held-out")
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    text, result = report(rows, time.perf_counter() - started, load)
    B.RESULTS.mkdir(parents=True, exist_ok=True)
    (B.RESULTS / "light_sides.md").write_text(text + "\n![E / c by side](light_sides.png)\n")
    (B.RESULTS / "light_sides.json").write_text(json.dumps({**result, "views": [
        {k: v for k, v in r.items() if k != "rmse_by_level"} for r in rows]}, indent=1) + "\n")
    plot(rows, B.RESULTS / "light_sides.png")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
