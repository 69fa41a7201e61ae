"""The artist's sun from a shadow's three clicks: how far slipped clicks turn it, whether the reported
uncertainty says so, and what the unseen light's lobe widening with it (cues.sun_lobe) changes.

On every view of the light bench's real maps (the corpus's 12 and the 18 held-out ones, toward and away
from the dominant light, median metering) whose dominant light is above 3 deg, a post stands on the
floor in the photo's camera; the true light casts its shadow. Its foot, top and tip are projected into
the 640x480 photo and each click slips by a Gaussian of 1.5 px per axis (two draws per view). The slipped
clicks give the sun (shadow_hint.sun_from_shadow) and its uncertainty (shadow_hint.sun_uncertainty_deg);
the light is estimated with that sun and the narrow lobe (as before the uncertainty existed) and with the
lobe it calls for, and scored with the field's protocol (bench_light.py --real) against the constant.
Setups: a 1 m post where the asset stands (low in the frame, a few metres away), and a 1 m and a 0.5 m
post about 15 m away (near the horizon), where a slip turns the sun far more.

    python benchmarks/bench_sun_clicks.py   -> results/sun_clicks.md, sun_clicks.json
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import bench_light as B
from heldout_hdri import FETCH_FAILED, HELD_OUT_MAPS, fetch_or_say, read_heldout
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import srgb_to_linear
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.render.photo import develop_photo, perspective_view
from scenefit.core.scene.camera import CAMERA_HEIGHT, PhotoCamera
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.measure import dominant_direction
from scenefit.core.stages.light.shadow_hint import floor_point, sun_from_shadow, sun_uncertainty_deg

SETUPS = {"1 m post where the asset stands": (1.0, 5 / 6), "1 m post ~15 m away": (1.0, 0.4167),
          "0.5 m post ~15 m away": (0.5, 0.4167)}   # (height in metres, foot's row as a fraction of the photo)
SLIP_SIGMA_PX = 1.5
DRAWS = 2
ORIGIN = np.array([0.0, 0.0, CAMERA_HEIGHT])


def unit(azimuth: float, elevation: float) -> np.ndarray:
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def views(folder: Path):
    """(map, side, camera, photo, truth) for every view of both map sets (the held-out ones in `folder`),
    median metering."""
    maps = [(n, B.CORPUS_HDRI / f"{n}_1k.hdr", B.read_corpus_map) for n in B.REAL_MAPS]
    maps += [(n, folder / f"{n}.exr", read_heldout) for n in HELD_OUT_MAPS]
    for name, path, reader in maps:
        hdr = reader(path)
        for side, yaw in B.real_views(hdr):
            camera = PhotoCamera(yaw_deg=yaw, pitch_deg=B.REAL_PITCH, fov_deg=60.0, width=B.REAL_PHOTO[0],
                                 height=B.REAL_PHOTO[1])
            radiance = perspective_view(hdr, camera)
            exposure = B.metered_exposure(radiance, "median")
            photo = develop_photo(radiance, exposure).astype(np.float32) / 255.0
            yield name, side, camera, photo, B.resize(hdr, B.REAL_MAP) * exposure


def one_view(camera, photo, truth, height: float, foot_row: float, rng, config) -> dict | None:
    d = dominant_direction(truth)
    if d[2] < 0.05:
        return None
    foot = floor_point(camera, (camera.width / 2, camera.height * foot_row), "foot")
    top = foot + np.array([0.0, 0.0, height])
    pixels = camera.project(np.stack([foot, top, top - d * (top[2] / d[2])]), ORIGIN)
    if not all(0 <= x < camera.width and 0 <= y < camera.height for x, y in pixels):
        return {"in_frame": False}
    exact = B.sun_hint(truth, camera)
    estimate = lambda cfg: B.resize(estimate_light(photo, B.REAL_PLACEMENT, cfg, photo_camera=camera).hdr, B.REAL_MAP)
    maps = {"constant": np.broadcast_to(srgb_to_linear(photo).reshape(-1, 3).mean(0), (*B.REAL_MAP, 3)).astype(np.float32),
            "exact": estimate(replace(config, sun_deg=exact))}
    draws = []
    for k in range(DRAWS):
        slipped = [tuple(p + rng.normal(0.0, SLIP_SIGMA_PX, 2)) for p in pixels]
        try:
            sun, spread = sun_from_shadow(camera, *slipped), sun_uncertainty_deg(camera, *slipped)
        except InputError:   # a slip off the floor: the artist would be told and click again
            continue
        error = math.degrees(math.acos(float(np.clip(unit(*sun) @ unit(*exact), -1.0, 1.0))))
        draws.append({"uncertainty_deg": spread, "error_deg": error})
        maps[f"narrow {k}"] = estimate(replace(config, sun_deg=sun))
        maps[f"by uncertainty {k}"] = estimate(replace(config, sun_deg=sun, sun_uncertainty_deg=spread))
    forward = np.array([math.cos(math.radians(camera.yaw_deg)), math.sin(math.radians(camera.yaw_deg)), 0.0])
    scores = B.score_methods(maps, truth, forward)
    return {"in_frame": True, "draws": draws,
            "scores": {m: {"diffuse_si": s["diffuse"]["linear"]["si_rmse"], "diffuse_rmse": s["diffuse"]["linear"]["rmse"],
                           "matte_si": s["matte"]["linear"]["si_rmse"]} for m, s in scores.items()}}


def summary(rows: list[dict]) -> list[str]:
    lines = ["| setup | views (shadow in frame) | uncertainty median / 90th / max (deg) | error median / 90th (deg) | "
             "error within the uncertainty / within 2x | lobe | both-wins | matte si-RMSE / constant's (median) |",
             "|---|---|---|---|---|---|---|---|"]
    for setup in SETUPS:
        mine = [r for r in rows if r["setup"] == setup and r.get("in_frame")]
        draws = [d for r in mine for d in r["draws"]]
        spread = np.array([d["uncertainty_deg"] for d in draws])
        error = np.array([d["error_deg"] for d in draws])
        head = (f"| {setup} | {len(mine)} of {sum(r['setup'] == setup for r in rows)} | {np.median(spread):.1f} / "
                f"{np.percentile(spread, 90):.1f} / {spread.max():.1f} | {np.median(error):.1f} / "
                f"{np.percentile(error, 90):.1f} | {100 * np.mean(error <= spread):.0f}% / {100 * np.mean(error <= 2 * spread):.0f}% |")
        for lobe, keys in (("exact direction, narrow", ["exact"]), ("narrow", [f"narrow {k}" for k in range(DRAWS)]),
                           ("by uncertainty", [f"by uncertainty {k}" for k in range(DRAWS)])):
            pairs = [(r["scores"][k], r["scores"]["constant"]) for r in mine for k in keys if k in r["scores"]]
            both = sum(s["diffuse_si"] < c["diffuse_si"] and s["diffuse_rmse"] < c["diffuse_rmse"] for s, c in pairs)
            matte = np.median([s["matte_si"] for s, _ in pairs]) / np.median([c["matte_si"] for _, c in pairs])
            lines.append(f"{head if lobe.startswith('exact') else '| | | | | |'} {lobe} | {both} of {len(pairs)} | {matte:.3f} |")
    return lines


def main() -> int:
    folder = fetch_or_say("bench_sun_clicks")
    if folder is None:
        return FETCH_FAILED
    missing = [n for n in B.REAL_MAPS if not (B.CORPUS_HDRI / f"{n}_1k.hdr").is_file()]
    if missing:
        print(f"bench_sun_clicks: {B.CORPUS_HDRI} lacks the corpus map {missing[0]}_1k.hdr.", file=sys.stderr)
        return 2
    started = time.perf_counter()
    config = stage_config("light", "balanced", critic_type="none")
    rng = np.random.default_rng(0)
    rows = []
    for name, side, camera, photo, truth in views(folder):
        for setup, (height, foot_row) in SETUPS.items():
            row = one_view(camera, photo, truth, height, foot_row, rng, config)
            if row is not None:
                rows.append({"map": name, "side": side, "setup": setup, **row})
        print(name, side, flush=True)
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    seconds = time.perf_counter() - started
    text = "\n".join(["# The sun from a shadow's three clicks", "", __doc__.split("\n\n")[1].replace("\n", " "), "",
                      f"Run time {seconds:.0f} s; load: `{load}`.", ""] + summary(rows)) + "\n"
    out = B.RESULTS
    (out / "sun_clicks.md").write_text(text)
    (out / "sun_clicks.json").write_text(json.dumps({"rows": rows, "load": load, "seconds": seconds}, indent=1, default=float))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
