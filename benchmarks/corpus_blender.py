"""`make corpus`, its Blender part: every asset of the development corpus through the extension as an
artist uses it. In a fresh Blender (bpy) with the extension installed from its zip and an object of
the artist's own in the scene: Import Asset, the asset's visible meshes selected, a photo cut from a
real HDR panorama, Pick Placement, Run All (preset draft, no prompt), Bake Asset (.glb); then the
Khronos validator on the bake, what it kept and lost of the input, and whether the artist's object
stayed as it was. Writes benchmarks/results/corpus_blender.md (+ .json, corpus_blender_sheet.png).

Each asset runs in a child process of its own (a fresh Blender), timed. The corpus is for development
only: nothing of it is copied into the repository.

    python benchmarks/corpus_blender.py [--only NAME ...] [--timeout 900]   (--only prints, writes nothing)
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from corpus import RESULTS, RUN_ON, ROOT, corpus_assets, corpus_ready, kept_and_lost, load_average, photo_from, \
    validate

DEFAULT_PHOTO = "autoshop_01_1k"   # an indoor photo for the assets RUN_ON gives none

# One asset in a fresh Blender: the steps an artist takes, each operator through EXEC_DEFAULT.
ARTIST = r"""
import json, sys, time
from pathlib import Path
import bpy

asset, photo, work, zip_path = (Path(a) for a in sys.argv[-4:])
bpy.ops.extensions.package_install_files(repo="user_default", filepath=str(zip_path), enable_on_install=True)
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_cube_add(location=(5.0, 5.0, 0.0))
mine = bpy.context.object
mine.name = "Artist's Cube"
mine.data.materials.append(bpy.data.materials.new("Artist's Paint"))
def artists():
    return [list(mine.location), len(mine.data.vertices), [s.material.name for s in mine.material_slots],
            bpy.context.scene.world.name if bpy.context.scene.world else None]
before = artists()
row = {"steps": {}}
def step(name, **kw):
    started = time.perf_counter()
    try:
        result = sorted(getattr(bpy.ops.scenefit, name)(**kw))
        message = ""
    except RuntimeError as error:
        result, message = ["ERROR"], str(error).strip()
    row["steps"][name] = {"result": result, "seconds": round(time.perf_counter() - started, 1), "message": message}
    return result == ["FINISHED"]
if step("import_asset", filepath=str(asset)):
    meshes = [o for o in bpy.context.view_layer.objects if o.type == "MESH" and o.visible_get() and o != mine]
    for o in bpy.context.view_layer.objects:
        o.select_set(o in meshes)
    row["objects"] = len(meshes)
    settings = bpy.context.scene.scenefit
    settings.preset, settings.photo_path, settings.prompt = "draft", str(photo), ""
    bpy.ops.wm.save_as_mainfile(filepath=str(work / "scene.blend"))
    if step("pick_placement", x=0.5, y=0.75) and step("run"):
        row["composite"] = bpy.path.abspath(settings.composite_path)
        if step("bake_asset"):
            baked = sorted((work / "scenefit").glob("*/bake-*/*.glb"))
            row["bake"] = str(baked[-1]) if baked else None
row["artists_object_unchanged"] = artists()[:3] == before[:3]
print("JSON" + json.dumps(row))
"""


def one_asset(path: Path, photo: Path, zip_path: Path, work: Path, timeout: float) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(work / "blender_user"))
    started = time.perf_counter()
    row: dict = {"asset": path.parent.name, "file": path.name, "photo": photo.stem}
    try:
        done = subprocess.run([sys.executable, "-c", ARTIST, str(path), str(photo), str(work), str(zip_path)],
                              capture_output=True, text=True, timeout=timeout, env=env, cwd=work)
        line = next((l for l in done.stdout.splitlines() if l.startswith("JSON")), None)
        row.update(json.loads(line[4:]) if line else {"crash": (done.stderr.strip().splitlines() or ["?"])[-1][:300]})
    except subprocess.TimeoutExpired:
        row["crash"] = f"timed out after {timeout:.0f} s"
    row["seconds"] = round(time.perf_counter() - started, 1)
    if row.get("bake"):
        baked = Path(row["bake"])
        row["validator"] = validate(baked)
        row["kept"], row["lost"] = kept_and_lost(path, baked)
    row["status"] = status(row)
    return row


def status(row: dict) -> str:
    if "crash" in row:
        return "crashed"
    failed = next((name for name, s in row["steps"].items() if s["result"] != ["FINISHED"]), None)
    if failed:
        message = row["steps"][failed]["message"]
        return f"{failed} failed (traceback)" if "Traceback" in message else f"{failed} refused"
    if not row.get("artists_object_unchanged"):
        return "changed the artist's object"
    errors = row.get("validator", {}).get("errors", 0)
    return f"{errors} validator errors" if errors else "ok"


SHEET_COLUMNS = 4


def contact_sheet(rows: list[dict], path: Path) -> None:
    """The composites as a grid, SHEET_COLUMNS to a row, each captioned with its asset and photo."""
    import cv2
    import numpy as np

    from scenefit.core.data.imageio import read_image, write_image
    from scenefit.core.texture.views import contact_sheet as sheet

    tiles = []
    for r in rows:
        if r.get("composite") and Path(r["composite"]).is_file():
            tile = np.ascontiguousarray(cv2.resize(read_image(r["composite"])[..., :3], (320, 240),
                                                   interpolation=cv2.INTER_AREA), np.float32)
            tile[-20:] = 0.12
            cv2.putText(tile, f"{r['asset']} / {r['photo'].removesuffix('_1k')}"[:44], (5, 234),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0.95, 0.95, 0.95), 1, cv2.LINE_AA)
            tiles.append(tile)
    if not tiles:
        return
    shown = len(tiles)
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % SHEET_COLUMNS)
    grid = {f"{k + 1}-{min(k + SHEET_COLUMNS, shown)} of {shown}": tiles[k:k + SHEET_COLUMNS]
            for k in range(0, len(tiles), SHEET_COLUMNS)}
    write_image(path, sheet(grid))


def markdown(rows: list[dict], measured: str) -> str:
    ok = sum(r["status"] == "ok" for r in rows)
    lines = ["# The corpus in Blender: Import Asset -> Run All -> Bake Asset -> validator\n",
             f"Made by `make corpus` (benchmarks/corpus_blender.py) on {time.strftime('%Y-%m-%d')}; load average "
             f"{measured}. A fresh Blender per asset, the extension installed from its zip, an object of the "
             "artist's own in the scene; the asset's visible meshes selected as one asset; preset draft, no prompt "
             f"(adapt skipped); photos as `scenefit run`'s part of corpus.md. **{ok} of {len(rows)}** pass (every "
             "step finished, 0 validator errors, the artist's object as it was). Bake Asset writes the selection, "
             "what carries it and the cameras and lights of the asset's own file (Cameras and Lights, on by "
             "default); \"kept / lost\" compares the bake with the input file. Composites in "
             "[corpus_blender_sheet.png](corpus_blender_sheet.png).\n",
             "| asset | file | status | objects | import s | Run All s | Bake Asset s | validator errors / warnings | "
             "kept | lost | message |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        steps = r.get("steps", {})
        seconds = [str(steps.get(k, {}).get("seconds", "-")) for k in ("import_asset", "run", "bake_asset")]
        message = r.get("crash") or next((s["message"] for s in steps.values() if s["message"]), "")
        v = r.get("validator", {})
        lines.append(f"| {r['asset']} | {r['file']} | {r['status']} | {r.get('objects', '-')} | {' | '.join(seconds)} | "
                     f"{v.get('errors', '-')}/{v.get('warnings', '-')} | {'; '.join(r.get('kept', []))} | "
                     f"{'; '.join(r.get('lost', []))} | {message.splitlines()[0][:300].replace('|', '/') if message else ''} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="asset folder names to run (prints their rows, writes nothing)")
    parser.add_argument("--timeout", type=float, default=900, help="seconds per asset")
    args = parser.parse_args()
    if not corpus_ready("corpus_blender"):
        return 2
    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension

    load = " ".join(load_average())
    rows = []
    with tempfile.TemporaryDirectory(prefix="scenefit-corpus-blender-") as tmp:
        zip_path = build_extension.build_without_wheels(Path(tmp) / "scenefit.zip")
        photos: dict[str, Path] = {}
        for path in corpus_assets():
            name = path.parent.name
            if args.only and name not in args.only:
                continue
            hdri = RUN_ON.get(name, DEFAULT_PHOTO)
            if hdri not in photos:
                photos[hdri] = photo_from(hdri, Path(tmp) / f"{hdri}.png")
            row = one_asset(path, photos[hdri], zip_path, Path(tmp) / name, args.timeout)
            rows.append(row)
            print(f"{name}: {row['status']} ({row['seconds']} s)", flush=True)
        if not args.only:
            RESULTS.mkdir(parents=True, exist_ok=True)
            contact_sheet(rows, RESULTS / "corpus_blender_sheet.png")
    end = " ".join(load_average())
    if args.only:
        print(json.dumps(rows, indent=2))
        return 0
    measured = f"{load} at the start, {end} at the end"
    (RESULTS / "corpus_blender.json").write_text(json.dumps({"measured": measured, "assets": rows}, indent=2) + "\n")
    (RESULTS / "corpus_blender.md").write_text(markdown(rows, measured))
    print(f"wrote {RESULTS / 'corpus_blender.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
