"""Which real assets adaptation re-maps, what xatlas costs, and what the new layout loses (issue 23).

For every corpus asset: the share of its surface whose UVs share texels (collapsed as palettes make
them, or overlapping: mirrored halves, repeats), so whether adaptation works in a new layout; the
seconds xatlas takes to make one at the texture's working size; and the fidelity of the asset read
through it: the exact start's base colour rendered (Mitsuba's albedo, one sample at each pixel
centre) from four sides in the new layout against the same in the asset's own UVs, as PSNR over the
pixels both hit. Each asset runs in a child process. Writes benchmarks/results/uv_layout.md and .json.

    python benchmarks/bench_uv_layout.py [--only NAME ...] [--timeout 900]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from corpus import corpus_assets  # noqa: E402
from results_files import machine_load, write_results  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
VIEWS, SIZE = 4, 256


def measure(path: Path) -> dict:
    """One asset, in this process: its sharing, xatlas's seconds and the new layout's fidelity."""
    import numpy as np

    from scenefit.blender_io.asset_file import load_asset_materials
    from scenefit.core.render.orbit_camera import Camera
    from scenefit.core.pipeline.preset_tables import texture_preset
    from scenefit.core.stages.convert import ConvertConfig, convert_materials
    from scenefit.core.data.mesh import normalize_to_unit_sphere
    from scenefit.core.render.renderer import AssetRenderer
    from scenefit.core.texture.surface_layout import new_layout, texture_view, uv_sharing

    asset = load_asset_materials(path)
    mesh, _ = asset.fitting_view()
    started = time.perf_counter()
    sharing = uv_sharing(mesh)
    row = {"faces": int(len(mesh.faces)), "materials": len(asset.materials), **sharing.report(),
           "re_maps": sharing.needs_new_layout(), "sharing_seconds": round(time.perf_counter() - started, 2)}
    texture = convert_materials(asset, ConvertConfig(texture=texture_preset("draft"))).texture
    normalized, _ = normalize_to_unit_sphere(mesh)
    layout = new_layout(normalized, texture.config.resolution, sharing)
    row.update(resolution=texture.config.resolution, xatlas_seconds=round(layout.seconds, 2))
    views = [texture_view(texture, normalized), texture_view(texture, normalized, layout)]
    albedo = []
    for view in views:
        stack = view.stack(texture)
        renderer = AssetRenderer(view.mesh, stack.shape[:2], np.ones((8, 16, 3), np.float32))
        cameras = [Camera(azimuth_deg=90.0 * k, elevation_deg=20.0, width=SIZE, height=SIZE) for k in range(VIEWS)]
        albedo.append([renderer.render_albedo(c, stack) for c in cameras])
    errors, hits = 0.0, 0
    for own, new in zip(*albedo):
        both = (own[..., 3] > 0) & (new[..., 3] > 0)
        errors += float(((own[..., :3] - new[..., :3])[both] ** 2).sum())
        hits += int(both.sum()) * 3
    mse = errors / max(hits, 1)
    row["albedo_psnr_db"] = round(min(100.0, 10 * np.log10(1.0 / max(mse, 1e-10))), 2)
    row["covered_texels_new"] = round(views[1].raster.coverage, 3)
    row["covered_texels_own"] = round(views[0].raster.coverage, 3)
    return row


def table(rows: list[dict]) -> str:
    lines = ["| asset | faces | materials | shared surface | collapsed | overlapping | re-mapped | xatlas s | "
             "texels used own / new | albedo PSNR new vs own |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['asset']} | | | | | | failed: {r['error'][:80]} | | | |")
            continue
        lines.append(f"| {r['asset']} | {r['faces']} | {r['materials']} | {r['shared_surface']:.0%} | "
                     f"{r['collapsed_surface']:.0%} | {r['overlapped_surface']:.0%} | "
                     f"{'yes' if r['re_maps'] else 'no'} | {r['xatlas_seconds']} | "
                     f"{r['covered_texels_own']:.0%} / {r['covered_texels_new']:.0%} | {r['albedo_psnr_db']} dB |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="asset folder names")
    parser.add_argument("--timeout", type=float, default=900)
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(Path(args.one))))
        return 0
    rows = []
    for path in corpus_assets():
        if args.only and path.parent.name not in args.only:
            continue
        done = subprocess.run([sys.executable, __file__, "--one", str(path)], capture_output=True, text=True,
                              timeout=args.timeout)
        try:
            row = json.loads(done.stdout.strip().splitlines()[-1])
        except (ValueError, IndexError):
            row = {"error": (done.stderr.strip().splitlines() or ["no output"])[-1]}
        rows.append({"asset": path.parent.name, **row})
        print(rows[-1], flush=True)
    load = machine_load()
    markdown = "\n".join([
        "# Adaptation's UV layout on the corpus", "",
        f"`python benchmarks/bench_uv_layout.py`; {load}.", "",
        "Adaptation works in a new layout made by xatlas when more than 5% of the surface shares texels in the "
        "asset's own UVs (palettes collapse UVs to points; mirrored halves and repeats overlap): a result there "
        "could otherwise not differ per surface. The exact start's base colour read through xatlas's layout (at "
        "the draft preset's working size) against the asset's own UVs, rendered from four sides: how much detail "
        "the new layout costs. Measured for every asset; only those marked re-mapped use it.", "",
        table(rows), ""])
    write_results(RESULTS, "uv_layout", markdown, {"rows": rows, "load": load})
    print(markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
