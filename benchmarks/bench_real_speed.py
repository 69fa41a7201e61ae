"""`scenefit run` on real assets with 2k textures and a 12-megapixel photo, as a user runs it.

Assets: the corpus's glTF files with 2048² textures (Khronos' MaterialsVariantsShoe, three JPEG maps
per material; CesiumMilkTruck, Draco-compressed). The photo: a 4000x3000 view of a real HDR panorama
of the corpus, 60° wide, auto-exposed, JPEG. `--guidance none` (no adaptation), presets draft and
balanced, each a fresh run folder in a fresh process: wall seconds (Python and the libraries
starting included), the pipeline's own total and each stage's seconds, and peak memory. The game
bake is a process of its own that runs beside light and compose: its seconds overlap theirs.
Writes benchmarks/results/real_speed.md and .json.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_files import machine_load, write_results  # noqa: E402
from corpus import CORPUS, timed  # noqa: E402  (the corpus bench's runner: exit code, seconds, peak memory)

RESULTS = Path(__file__).resolve().parent / "results"
ASSETS = ("khronos_MaterialsVariantsShoe/MaterialsVariantsShoe.gltf", "khronos_CesiumMilkTruck_draco/CesiumMilkTruck.gltf")
PRESETS = ("draft", "balanced")
PHOTO = (4000, 3000)
GOALS = {"draft": 30.0, "balanced": 120.0}   # seconds (issue 23)


def twelve_megapixels(path: Path, hdri: str = "vestibule_1k") -> Path:
    from scenefit.core.data.imageio import read_image, write_image
    from scenefit.core.render.photo import develop_photo, perspective_view
    from scenefit.core.scene.camera import PhotoCamera

    hdr = read_image(CORPUS / "hdri" / f"{hdri}.hdr")[..., :3]
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=PHOTO[0], height=PHOTO[1])
    return write_image(path, develop_photo(perspective_view(hdr, camera)).astype(np.float32) / 255.0)


def one(asset: Path, photo: Path, preset: str, out: Path, timeout: float) -> dict:
    result = timed([sys.executable, "-m", "scenefit.cli", "run", str(asset), "--photo", str(photo), "--at", "0.5,0.8",
                    "--out", str(out), "--preset", preset, "--guidance", "none", "--quiet"], timeout)
    row = {"asset": asset.parent.name, "preset": preset, **result}
    if (out / "report.json").is_file():
        report = json.loads((out / "report.json").read_text())
        row["pipeline_seconds"] = report.get("seconds_total")
        row["stages"] = {name: stage.get("seconds") for name, stage in report["stages"].items()}
        row["composite_size"] = report["stages"]["compose"]["report"].get("composite_size")
    return row


def markdown(rows: list[dict], load: str, seconds: float) -> str:
    lines = ["# `scenefit run` on real 2k assets and a 12 MP photo (benchmarks/bench_real_speed.py)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "", f"{seconds:.0f} s in all; load: `{load}`", "",
             "| asset | preset | exit | wall s | pipeline s | goal | composite | per stage (s) | peak GB |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        per = ", ".join(f"{k} {v}" for k, v in r.get("stages", {}).items() if v is not None)
        size = "x".join(str(v) for v in r.get("composite_size") or []) or "-"
        lines.append(f"| {r['asset']}{' (first run: warm-up, not counted)' if r.get('warm_up') else ''} | "
                     f"{r['preset']} | {r['rc']} | {r['seconds']} | {r.get('pipeline_seconds', '-')} | "
                     f"< {GOALS[r['preset']]:.0f} | {size} | {per} | {r['peak_gb']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(RESULTS))
    parser.add_argument("--timeout", type=float, default=900)
    args = parser.parse_args(argv)
    if not CORPUS.is_dir():
        print(f"bench_real_speed: no corpus at {CORPUS}; nothing measured.", file=sys.stderr)
        return 1
    started, rows = time.perf_counter(), []
    with tempfile.TemporaryDirectory(prefix="scenefit-speed-") as tmp:
        photo = twelve_megapixels(Path(tmp) / "photo_12mp.jpg")
        # The first run on a machine also fills the caches (Mitsuba's compiled kernels, the OS's file
        # cache): it is shown, as what a first run costs, and not counted with the others.
        first = one(CORPUS / "assets" / ASSETS[0], photo, "draft", Path(tmp) / "warm-up", args.timeout)
        rows.append({**first, "preset": "draft", "warm_up": True})
        for name in ASSETS:
            for preset in PRESETS:
                rows.append(one(CORPUS / "assets" / name, photo, preset, Path(tmp) / f"{Path(name).stem}-{preset}",
                                args.timeout))
                print(f"{rows[-1]['asset']} {preset}: exit {rows[-1]['rc']}, {rows[-1]['seconds']} s wall, "
                      f"{rows[-1].get('pipeline_seconds')} s pipeline", flush=True)
    load, seconds = machine_load(), time.perf_counter() - started
    table = write_results(args.out, "real_speed", markdown(rows, load, seconds),
                          {"rows": rows, "load": load, "seconds": seconds})
    print(table.read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
