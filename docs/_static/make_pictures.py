"""Regenerate the docs' pictures from the project's own output (never a mock-up).

    python docs/_static/make_pictures.py [--preset draft] [--corpus-sheet]

Runs `scenefit demo` into a temporary folder and copies its sheet (photo | composite under a constant
light | composite under the estimated light), its composite and its light preview here. With
`--corpus-sheet` it also copies `make corpus`'s sheet of real assets taken through the Blender extension
(benchmarks/results/corpus_blender_sheet.png, made by benchmarks/corpus_blender.py), reduced to 1024 px.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
# What `scenefit demo` writes -> the name the docs use.
DEMO_PICTURES = {
    "sheet.png": "demo_sheet.png",
    "compose/composite.png": "demo_composite.png",
    "input/photo.png": "demo_photo.png",
    "light/light_preview.png": "demo_light_preview.png",
}
CORPUS_SHEET = ROOT / "benchmarks" / "results" / "corpus_blender_sheet.png"


def demo_pictures(preset: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        subprocess.run([sys.executable, "-m", "scenefit.cli", "demo", "--out", str(out), "--preset", preset,
                        "--guidance", "none", "--quiet"], check=True)
        for made, name in DEMO_PICTURES.items():
            shutil.copyfile(out / made, HERE / name)
            print(f"docs/_static/{name} <- scenefit demo's {made}")


def corpus_sheet(max_side: int = 1024) -> None:
    import cv2

    sheet = cv2.imread(str(CORPUS_SHEET), cv2.IMREAD_UNCHANGED)
    scale = max_side / max(sheet.shape[:2])
    if scale < 1:
        sheet = cv2.resize(sheet, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(HERE / "corpus_blender_sheet.png"), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print("docs/_static/corpus_blender_sheet.png <- benchmarks/results/corpus_blender_sheet.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="draft", choices=("draft", "balanced", "final"))
    parser.add_argument("--corpus-sheet", action="store_true")
    args = parser.parse_args()
    demo_pictures(args.preset)
    if args.corpus_sheet:
        corpus_sheet()


if __name__ == "__main__":
    main()
