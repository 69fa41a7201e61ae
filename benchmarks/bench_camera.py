"""The photo camera estimate against known cameras: views rendered from real HDR panoramas (issue 22).

Each of the 12 Poly Haven maps in ../shared/corpus/hdri/ (development data, read in place, never copied)
gives VIEWS_PER_MAP perspective views with a known horizontal field of view (40-90 deg), pitch (-25 to
+10 deg) and roll (-5 to +5 deg) at a random yaw, developed to 8-bit PNGs (core/photo.develop_photo),
and `estimate_photo_camera` is run on each file as `scenefit camera` would (PNGs carry no EXIF, so
the field of view comes from the lines or the default). The maps are only 1024x512, 2.8 px per
degree, so every view is upsampled (a 40 deg view 4.5x, a 90 deg one 2x at 512 px wide): edges are
soft, which is why the views are kept at 512x384 (one portrait 384x512 per map), not larger.

Errors are split by maps with architecture (straight walls, columns, frames) and without (sky,
meadow, hills, forest, beach, garden); the table also counts how often each field fell back to the
default. Writes benchmarks/results/camera.md and camera.json (camera_seedN.* for --seed N, a held-out
check). About 3 minutes on a quiet 2-core machine (each estimate profiles 21 lenses: 1-3 s).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.render.photo import develop_photo, perspective_view
from scenefit.core.stages.camera import estimate_photo_camera
from scenefit.core.scene.camera import PhotoCamera

RESULTS = Path(__file__).resolve().parent / "results"
CORPUS_HDRI = Path(__file__).resolve().parents[2] / "shared" / "corpus" / "hdri"
# Looked at (four yaws each): these six show walls, columns, frames or stands with straight edges.
ARCHITECTURE = ("artist_workshop", "studio_small_05", "vestibule", "autoshop_01", "circus_arena",
                "st_peters_square_night")
OTHER = ("aristea_wreck_puresky", "chinese_garden", "noon_grass", "hilly_terrain_01", "phalzer_forest_01",
         "blouberg_sunrise_2")
VIEWS_PER_MAP = 6
LANDSCAPE, PORTRAIT = (512, 384), (384, 512)
FIELDS = ("fov", "pitch", "roll")
SEED = 22


def views(seed: int, per_map: int) -> list[dict]:
    """The known cameras, the same for every run of the bench."""
    rng = np.random.default_rng(seed)
    out = []
    for name in ARCHITECTURE + OTHER:
        for k in range(per_map):
            width, height = PORTRAIT if k == per_map - 1 else LANDSCAPE
            out.append({"map": name, "architecture": name in ARCHITECTURE, "yaw": float(rng.uniform(0, 360)),
                        "fov": float(rng.uniform(40, 90)), "pitch": float(rng.uniform(-25, 10)),
                        "roll": float(rng.uniform(-5, 5)), "width": width, "height": height})
    return out


def measure(view: dict, env: np.ndarray, folder: Path) -> dict:
    camera = PhotoCamera(yaw_deg=view["yaw"], pitch_deg=view["pitch"], fov_deg=view["fov"], width=view["width"],
                         height=view["height"], roll_deg=view["roll"])
    path = folder / f"{view['map']}_{view['yaw']:.0f}.png"
    write_image(path, develop_photo(perspective_view(env, camera)).astype(np.float32) / 255.0, dtype="uint8")
    start = time.perf_counter()
    est = estimate_photo_camera(path)
    seconds = time.perf_counter() - start
    return {**view, "seconds": round(seconds, 2), "estimate": est.to_dict(),
            **{f"{f}_error": abs(getattr(est, f"{f}_deg") - view[f]) for f in FIELDS},
            **{f"{f}_source": getattr(est, f"{f}_source") for f in FIELDS}}


def summary(rows: list[dict]) -> dict:
    out = {"views": len(rows), "fallback_views": sum(r["estimate"]["fallback"] for r in rows)}
    for f in FIELDS:
        errors = np.array([r[f"{f}_error"] for r in rows])
        lines = np.array([r[f"{f}_error"] for r in rows if r[f"{f}_source"] == "lines"])
        out[f] = {"median": float(np.median(errors)), "p90": float(np.percentile(errors, 90)),
                  "lines": int(len(lines)), "default": int(sum(r[f"{f}_source"] == "default" for r in rows)),
                  "lines_median": float(np.median(lines)) if len(lines) else None,
                  "lines_p90": float(np.percentile(lines, 90)) if len(lines) else None}
    return out


def _cell(value) -> str:
    return "-" if value is None else f"{value:.2f}"


def markdown(rows: list[dict], splits: dict, load: str, seconds: float, seed: int) -> str:
    md = ["# Photo camera estimate (benchmarks/bench_camera.py)", "",
          f"{len(rows)} views ({VIEWS_PER_MAP} per map, {LANDSCAPE[0]}x{LANDSCAPE[1]} and one {PORTRAIT[0]}x"
          f"{PORTRAIT[1]} per map) cut from the 12 Poly Haven panoramas in `../shared/corpus/hdri/` (1024x512, so "
          "each view is upsampled 2-4.5x and its edges are soft), with known field of view 40-90 deg, pitch -25 to "
          "+10 deg and roll -5 to +5 deg; `estimate_photo_camera` on each 8-bit PNG (no EXIF). Error in degrees, "
          "all views (whatever source each field came from), and over the views whose field came from the lines.",
          "", f"Seed {seed}" + (" (the views core/stages/camera.py's thresholds were set on)" if seed == SEED else
                                " (held out for the thresholds; the lens prior's two widths were picked among six "
                                "on both seeds' views)") + f"; {seconds:.0f} s in all; "
                                                                                 f"load: `{load}`", "",
          "| maps | field | median err | p90 err | from lines | lines median | lines p90 | fell back to default |",
          "|---|---|---|---|---|---|---|---|"]
    for split, s in splits.items():
        for f in FIELDS:
            v = s[f]
            md.append(f"| {split} | {f} | {v['median']:.2f} | {v['p90']:.2f} | {v['lines']}/{s['views']} | "
                      f"{_cell(v['lines_median'])} | {_cell(v['lines_p90'])} | {v['default']}/{s['views']} |")
    md += ["", "Views with any field at its default (the estimate reports `fallback`): " + ", ".join(
        f"{split} {s['fallback_views']}/{s['views']}" for split, s in splits.items()), "",
           "## Every view", "", "| map | true fov / pitch / roll | estimate | sources | s |", "|---|---|---|---|---|"]
    for r in rows:
        e = r["estimate"]
        md.append(f"| {r['map']} | {r['fov']:.1f} / {r['pitch']:.1f} / {r['roll']:.1f} | {e['fov_deg']:.1f} / "
                  f"{e['pitch_deg']:.1f} / {e['roll_deg']:.1f} | {r['fov_source']}, {r['pitch_source']}, "
                  f"{r['roll_source']} | {r['seconds']:.1f} |")
    return "\n".join(md) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-map", type=int, default=VIEWS_PER_MAP, help="views per map")
    parser.add_argument("--out", default=str(RESULTS), help="folder for camera.md and camera.json")
    parser.add_argument("--seed", type=int, default=SEED,
                        help=f"other views (the thresholds were set on seed {SEED}'s: another is a held-out check)")
    args = parser.parse_args(argv)
    if not CORPUS_HDRI.is_dir():
        print(f"bench_camera: no corpus at {CORPUS_HDRI}; nothing measured.", file=sys.stderr)
        return 1
    start, rows = time.perf_counter(), []
    with tempfile.TemporaryDirectory() as tmp:
        envs: dict[str, np.ndarray] = {}
        for view in views(args.seed, args.per_map):
            if view["map"] not in envs:
                envs[view["map"]] = read_image(CORPUS_HDRI / f"{view['map']}_1k.hdr")[..., :3]
            rows.append(measure(view, envs[view["map"]], Path(tmp)))
            print(f"{view['map']}: " + ", ".join(f"{f} {rows[-1][f'{f}_error']:.2f} ({rows[-1][f'{f}_source']})"
                                                  for f in FIELDS), flush=True)
    splits = {"architecture": summary([r for r in rows if r["architecture"]]),
              "other": summary([r for r in rows if not r["architecture"]])}
    seconds = time.perf_counter() - start
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "camera" if args.seed == SEED else f"camera_seed{args.seed}"
    (out / f"{stem}.md").write_text(markdown(rows, splits, load, seconds, args.seed))
    (out / f"{stem}.json").write_text(json.dumps({"seed": args.seed, "splits": splits, "views": rows, "load": load,
                                                  "seconds": seconds}, indent=1, allow_nan=False) + "\n")
    print((out / f"{stem}.md").read_text().split("## Every view")[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
