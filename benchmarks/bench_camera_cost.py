"""What a wrong photo camera costs downstream: the composite under a camera 10 deg off in pitch or
15 deg off in field of view, against the composite with the right camera.

Each view is cut from a real HDR panorama of the corpus (`../shared/corpus/hdri/`) with a known camera
(60 deg wide, 12 deg down, toward the map's dominant light), metered by median luminance. The bundled
example (Suzanne, its own maps) stands at the same point of the photo at the same size in every run.
The ground truth is the compose stage lit by the panorama itself through the true camera; each run
estimates the light (draft) and composes (draft) through its camera. Errors: RMSE in display sRGB over
the pixels where any composite of the view differs from the photo (asset or shadow), and the IoU of
the asset's silhouette with the ground truth's. Writes benchmarks/results/camera_cost.md and .json.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.stages.compose import ComposeInputs, compose
from scenefit.core.stages.convert import target_stack
from scenefit.core.data.imageio import read_image
from scenefit.core.stages.light import estimate_light
from scenefit.core.render.photo import develop_photo, perspective_view
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.scene.camera import PhotoCamera

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_files import machine_load, write_results  # noqa: E402
from bench_light import metered_exposure, real_views, resize  # noqa: E402  (the light bench's protocol)
from bench_camera import CORPUS_HDRI  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
MAPS = ("vestibule", "autoshop_01", "noon_grass", "chinese_garden")   # two built, two open scenes
PHOTO = (320, 240)
TRUE = {"fov_deg": 60.0, "pitch_deg": -12.0}
WRONG = {"right camera": {}, "pitch +10": {"pitch_deg": -2.0}, "pitch -10": {"pitch_deg": -22.0},
         "fov +15": {"fov_deg": 75.0}, "fov -15": {"fov_deg": 45.0}}
AT = (0.5, 0.8)          # where the asset stands, as fractions of the photo
SIZE = 0.3


def view(name: str) -> tuple[PhotoCamera, np.ndarray, np.ndarray]:
    """(true camera, 8-bit photo as float sRGB, the panorama at the photo's exposure)."""
    hdr = read_image(CORPUS_HDRI / f"{name}_1k.hdr")[..., :3]
    yaw = real_views(hdr)[0][1]
    camera = PhotoCamera(yaw_deg=yaw, width=PHOTO[0], height=PHOTO[1], **TRUE)
    radiance = perspective_view(hdr, camera)
    exposure = metered_exposure(radiance, "median")
    return camera, develop_photo(radiance, exposure).astype(np.float32) / 255.0, hdr * exposure


def composite(mesh, stack, photo: np.ndarray, envmap: np.ndarray, camera: PhotoCamera):
    pixel = (AT[0] * PHOTO[0], AT[1] * PHOTO[1])
    return compose(ComposeInputs(mesh, stack, photo, pixel, envmap, camera), stage_config("compose", "draft", size=SIZE))


def measure(name: str, mesh, stack) -> list[dict]:
    camera, photo, truth = view(name)
    reference = composite(mesh, stack, photo, resize(truth, (128, 256)), camera)
    runs = {}
    for label, change in WRONG.items():
        wrong = replace(camera, **change)
        started = time.perf_counter()
        light = estimate_light(photo, (AT[0] * PHOTO[0], AT[1] * PHOTO[1]), stage_config("light", "draft"),
                               photo_camera=wrong)
        runs[label] = (composite(mesh, stack, photo, light.hdr, wrong), time.perf_counter() - started)
    # Where any composite of the view is not the photo: the asset and its shadow, in any of the cameras.
    touched = reference.changed.copy()
    for result, _ in runs.values():
        touched |= result.changed
    silhouette = reference.alpha > 0.5
    rows = []
    for label, (result, seconds) in runs.items():
        mine = result.alpha > 0.5
        error = (result.composite_srgb - reference.composite_srgb)[touched]
        rows.append({"map": name, "camera": label, "rmse": float(np.sqrt(np.mean(error ** 2))),
                     "iou": float((mine & silhouette).sum() / max((mine | silhouette).sum(), 1)),
                     "pixels": int(touched.sum()), "seconds": round(seconds, 2)})
    return rows


def markdown(rows: list[dict], load: str, seconds: float) -> str:
    lines = ["# What a wrong photo camera costs (benchmarks/bench_camera_cost.py)", "", __doc__.split("\n\n")[1].replace("\n", " "),
             "", f"{seconds:.0f} s in all; load: `{load}`", "",
             "| camera | median RMSE (display sRGB) | x the right camera's | median silhouette IoU |", "|---|---|---|---|"]
    right = {r["map"]: r["rmse"] for r in rows if r["camera"] == "right camera"}
    for label in WRONG:
        mine = [r for r in rows if r["camera"] == label]
        ratio = np.median([r["rmse"] / max(right[r["map"]], 1e-9) for r in mine])
        lines.append(f"| {label} | {np.median([r['rmse'] for r in mine]):.4f} | {ratio:.2f} | "
                     f"{np.median([r['iou'] for r in mine]):.3f} |")
    lines += ["", "## Every view", "", "| map | camera | RMSE | IoU | pixels | s |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['map']} | {r['camera']} | {r['rmse']:.4f} | {r['iou']:.3f} | {r['pixels']} | {r['seconds']} |"
              for r in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--asset", help="an asset folder (default: the bundled example, made by Blender once)")
    parser.add_argument("--maps", default=",".join(MAPS), help="comma-separated panoramas of the corpus")
    parser.add_argument("--out", default=str(RESULTS))
    args = parser.parse_args(argv)
    if not CORPUS_HDRI.is_dir():
        print(f"bench_camera_cost: no corpus at {CORPUS_HDRI}; nothing measured.", file=sys.stderr)
        return 1
    if args.asset:
        asset = Path(args.asset)
    else:
        from run import example_asset

        asset = example_asset()
    mesh, maps = load_asset_folder(asset)
    stack = target_stack(maps, 256)
    started, rows = time.perf_counter(), []
    for name in args.maps.split(","):
        rows += measure(name, mesh, stack)
        print(f"{name}: " + ", ".join(f"{r['camera']} {r['rmse']:.4f}/{r['iou']:.2f}" for r in rows[-len(WRONG):]),
              flush=True)
    load, seconds = machine_load(), time.perf_counter() - started
    table = write_results(args.out, "camera_cost", markdown(rows, load, seconds),
                          {"rows": rows, "load": load, "seconds": seconds})
    print(table.read_text().split("## Every view")[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
