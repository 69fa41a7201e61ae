"""Noise in the compose stage's final render: error against a high-sample reference at equal time.

The bundled example (Suzanne, its own maps) stands in a 256² photo under Blender's CC0 `city` map (a
sun and a sky), rendered by the compose stage's own object pass (core/stages/compose.py) at 1..256 samples
per pixel with each of Mitsuba's samplers, raw and denoised by Intel Open Image Denoise with the
albedo and normal AOVs. Error: RMSE in display sRGB over the pixels the reference covers, against
an independent-sampler render at REFERENCE_SPP. Writes benchmarks/results/compose.md, compose.json
and compose_noise.png (error against seconds).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from scenefit.core.data.asset_io import load_asset_folder
from scenefit.core.stages.compose import ComposeConfig, ComposeInputs, build_compose
from scenefit.core.stages.convert import target_stack
from scenefit.core.render.denoise import denoise
from scenefit.core.data.imageio import linear_to_srgb
from scenefit.core.render.photo import studiolight_path
from scenefit.core.render.environment import load_environment
from scenefit.core.scene.camera import PhotoCamera

RESULTS = Path(__file__).resolve().parent / "results"
REFERENCE_SPP = 1024
SAMPLERS = ("independent", "multijitter", "ldsampler", "orthogonal")
SPPS = (1, 2, 4, 8, 16, 32, 64, 128)


def display(rgb: np.ndarray) -> np.ndarray:
    return linear_to_srgb(np.clip(rgb, 0.0, 1.0))


def rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.sqrt(np.mean((display(a)[mask] - display(b)[mask]) ** 2)))


def job_for(asset: Path, sampler: str, size: int):
    mesh, maps = load_asset_folder(asset)
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=40.0, width=size, height=size)
    photo = np.full((size, size, 3), 0.5, np.float32)
    env = load_environment(studiolight_path("city"), max_height=128)
    inputs = ComposeInputs(mesh, target_stack(maps, 512), photo, (size / 2, size * 0.9), env, camera)
    return build_compose(inputs, ComposeConfig(size=0.8, spp=1, sampler_type=sampler, shadow_type="none"))


def render(job, spp: int, seed: int) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    image = job._render(job.object_scene, job._object_integrator(), job.object_window, job._sampler_spp(spp), seed)
    return image, time.perf_counter() - t0


def bench(asset: Path, quick: bool = False) -> dict:
    # `make bench` keeps to ~35 min on 2 cores: 128², three samplers, up to 64 spp (the reference at
    # 1024 spp; --quick: 256). The orthogonal sampler and 128 spp add little (see git history of compose.md).
    size = 128
    spps = SPPS[:6] if quick else SPPS[:7]
    samplers = SAMPLERS[:3]
    reference_job = job_for(asset, "independent", size)
    render(reference_job, 4, 99)  # compile outside the timings
    reference, reference_s = render(reference_job, REFERENCE_SPP // (4 if quick else 1), 12345)
    mask = reference[..., 3] > 0.5
    rows = []
    for sampler in samplers:
        job = job_for(asset, sampler, size)
        done = set()
        for spp in spps:
            if job._sampler_spp(spp) in done:  # the sampler rounded it to a count already measured
                continue
            done.add(job._sampler_spp(spp))
            render(job, spp, 98)  # a new sample count compiles a new kernel: keep that out of the timing
            image, seconds = render(job, spp, 7)
            t0 = time.perf_counter()
            clean = denoise(image[..., :3], image[..., 4:7], image[..., 7:10])
            denoise_s = time.perf_counter() - t0
            rows.append({"sampler": sampler, "spp": job._sampler_spp(spp), "render_s": seconds,
                         "denoise_s": denoise_s, "rmse_raw": rmse(image[..., :3], reference[..., :3], mask),
                         "rmse_denoised": rmse(clean, reference[..., :3], mask)})
            print(rows[-1], flush=True)
    return {"size": size, "reference_spp": REFERENCE_SPP // (4 if quick else 1), "reference_s": reference_s,
            "covered_pixels": int(mask.sum()), "rows": rows}


def equal_time(result: dict) -> list[dict]:
    """For each raw render, the best denoised render that took no longer (render + denoise)."""
    rows = result["rows"]
    out = []
    for raw in sorted((r for r in rows if r["sampler"] == "independent"), key=lambda r: r["spp"]):
        budget = raw["render_s"]
        fits = [r for r in rows if r["render_s"] + r["denoise_s"] <= budget]
        if not fits:
            continue
        best = min(fits, key=lambda r: r["rmse_denoised"])
        out.append({"budget_s": budget, "raw_spp": raw["spp"], "raw_rmse": raw["rmse_raw"],
                    "denoised": f"{best['sampler']} {best['spp']} spp", "denoised_rmse": best["rmse_denoised"],
                    "ratio": raw["rmse_raw"] / max(best["rmse_denoised"], 1e-9)})
    return out


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for sampler in dict.fromkeys(r["sampler"] for r in result["rows"]):
        rows = [r for r in result["rows"] if r["sampler"] == sampler]
        line, = ax.loglog([r["render_s"] for r in rows], [r["rmse_raw"] for r in rows], "o--", ms=3,
                          label=f"{sampler} raw")
        ax.loglog([r["render_s"] + r["denoise_s"] for r in rows], [r["rmse_denoised"] for r in rows], "s-", ms=3,
                  color=line.get_color(), label=f"{sampler} + OIDN")
    ax.set_xlabel("seconds (render, + denoise)")
    ax.set_ylabel(f"RMSE vs {result['reference_spp']} spp (display sRGB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title(f"Compose object pass, {result['size']}², example under `city`")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def markdown(result: dict) -> str:
    lines = [f"Object pass of the example at {result['size']}² under `city`, reference {result['reference_spp']} spp "
             f"({result['reference_s']:.1f} s), {result['covered_pixels']} covered pixels; RMSE in display sRGB.", "",
             "| sampler | spp | render s | RMSE raw | OIDN s | RMSE denoised |", "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['sampler']} | {r['spp']} | {r['render_s']:.3f} | {r['rmse_raw']:.4f} | "
                     f"{r['denoise_s']:.3f} | {r['rmse_denoised']:.4f} |")
    lines += ["", "At equal time (render + denoise no longer than the raw independent render):", "",
              "| time budget s | raw spp | RMSE raw | best denoised | RMSE denoised | raw / denoised |",
              "|---|---|---|---|---|---|"]
    for r in equal_time(result):
        lines.append(f"| {r['budget_s']:.3f} | {r['raw_spp']} | {r['raw_rmse']:.4f} | {r['denoised']} | "
                     f"{r['denoised_rmse']:.4f} | {r['ratio']:.1f}x |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--asset", help="an asset folder (default: the bench's example)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="where compose.md/json/png go")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import example_asset

    asset = Path(args.asset) if args.asset else example_asset()
    result = bench(asset, args.quick)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "compose.json").write_text(json.dumps(result, indent=1))
    plot(result, args.out / "compose_noise.png")
    (args.out / "compose.md").write_text(markdown(result) + "\n")
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
