"""The exact start against the paper's fit (issue 23), on real assets of the corpus, as a user runs them.

`scenefit convert --preset draft` with `--init exact` (the asset's own maps and a zero residual: the
default) and with `--init fit` (the paper's network fitted to the maps), each in a fresh process:
wall seconds, peak memory, PSNR on covered texels overall and of the worst material (a material
fitted badly can hide in a good overall number). Writes benchmarks/results/start.md and .json.

    python benchmarks/bench_start.py [--only NAME ...] [--timeout 900]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_files import machine_load, write_results  # noqa: E402
from corpus import CORPUS, timed  # noqa: E402  (the corpus bench's runner: exit code, seconds, peak memory)

RESULTS = Path(__file__).resolve().parent / "results"
# One 1k skinned character, a multi-material 2k-texture asset, a Draco file with several materials.
ASSETS = ("khronos_Fox/Fox.glb", "khronos_ToyCar/ToyCar.gltf", "khronos_CesiumMilkTruck_draco/CesiumMilkTruck.gltf")
STARTS = ("exact", "fit")


def convert(asset: Path, start: str, work: Path, timeout: float) -> dict:
    out = work / start
    result = timed([sys.executable, "-m", "scenefit.cli", "convert", str(asset), "--out", str(out), "--preset",
                    "draft", "--init", start, "--quiet"], timeout)
    report = out / "report.json"
    if report.is_file():
        data = json.loads(report.read_text())
        materials = data.get("decisions", {}).get("materials", [])
        result["psnr_db"] = data.get("psnr_covered_texels_db")
        result["worst_material_db"] = min((m["psnr_db"] for m in materials if m.get("psnr_db") is not None),
                                          default=None)
        result["materials"] = len(materials)
    return {"asset": asset.parent.name, "start": start, **result}


def markdown(rows: list[dict], load: str) -> str:
    lines = ["# The exact start against the paper's fit, on real assets\n",
             f"`scenefit convert --preset draft --init exact|fit`, each a fresh process; load: {load}. "
             "PSNR on the texels the mesh covers, of the rendered maps against the asset's own (an exact "
             "start is written as 100 dB: strict JSON has no infinity).\n",
             "| asset | materials | start | exit | seconds | peak GB | PSNR dB | worst material dB |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['asset']} | {r.get('materials', '-')} | {r['start']} | {r['rc']} | {r['seconds']} | "
                     f"{r['peak_gb']} | {r.get('psnr_db', '-')} | {r.get('worst_material_db', '-')} |")
    by = {(r["asset"], r["start"]): r for r in rows}
    ratios = [by[(a, "fit")]["seconds"] / max(0.1, by[(a, "exact")]["seconds"])
              for a in {r["asset"] for r in rows} if (a, "fit") in by and (a, "exact") in by]
    if ratios:
        lines.append(f"\nThe fit takes {min(ratios):.0f}-{max(ratios):.0f}x the exact start's time.")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="asset folder names (default: all of ASSETS)")
    parser.add_argument("--timeout", type=float, default=900)
    args = parser.parse_args()
    load = machine_load()
    rows = []
    with tempfile.TemporaryDirectory(prefix="scenefit-start-") as tmp:
        for name in ASSETS:
            asset = CORPUS / "assets" / name
            if args.only and asset.parent.name not in args.only:
                continue
            for start in STARTS:
                rows.append(convert(asset, start, Path(tmp) / asset.parent.name, args.timeout))
                print(f"{rows[-1]['asset']} {start}: exit {rows[-1]['rc']} in {rows[-1]['seconds']} s, "
                      f"{rows[-1].get('psnr_db')} dB", flush=True)
    path = write_results(RESULTS, "start", markdown(rows, f"{load} (at the end: {machine_load()})"), {"rows": rows})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
