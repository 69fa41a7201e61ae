"""Batch throughput: jobs per hour in this process and on a local Ray cluster with 1 and 2 workers,
and what the paper's settings would give on N GPUs from a measured adapt-stage iteration cost.

The jobs are tiny (a 16x8-segment ball with 16² maps, a 64x48 photo, convert + light at the draft
preset), so the figures measure the batch machinery and these two stages, not diffusion. Ray's own
start-up (a few seconds) is left out; starting the workers is counted.

`bench_batch(quick, adapt_rows)` returns {"rows": [...], "estimate": {...}, "markdown": str};
`python benchmarks/bench_batch.py` prints the table.
"""
from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from scenefit.core.data.asset_io import save_asset_folder
from scenefit.workers.batch import InProcessDispatcher, run_batch
from scenefit.core.data.imageio import write_image
from scenefit.workers.jobs import load_jobs
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere

# The paper's adapt stage (appendix): 4000 iterations, 4 views per step, one view per GPU.
PAPER_ITERATIONS, PAPER_VIEWS_PER_STEP = 4000, 4


def write_jobs(folder: Path, count: int, workers: int | None = None) -> Path:
    rng = np.random.default_rng(0)
    maps = PBRMaps(base_color=rng.uniform(0.1, 0.9, (16, 16, 3)).astype(np.float32), roughness=0.5, metallic=0.0)
    save_asset_folder(uv_sphere(segments=16, rings=8), maps, folder / "ball")
    write_image(folder / "photo.png", rng.uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32))
    jobs = "\n".join(f'[[job]]\nname = "job{i}"\nseed = {i}\n' for i in range(count))
    batch = f"[batch]\nnum_cpus = 1\n" + (f"workers = {workers}\n" if workers else "")
    defaults = ('[defaults]\nasset = "ball"\nphoto = "photo.png"\nat = [0.5, 0.7]\npreset = "draft"\n'
                'stages = ["convert", "light"]\n')
    path = folder / f"jobs_{workers or 'auto'}.toml"
    path.write_text(batch + defaults + jobs)
    return path


def _timed(jobs_path: Path, out: Path, make_dispatcher) -> dict:
    jobs = load_jobs(jobs_path)
    t = time.perf_counter()
    outcomes = run_batch(jobs, out, make_dispatcher(jobs))
    wall = time.perf_counter() - t
    assert all(o.status == "done" for o in outcomes), [o.error for o in outcomes]
    busy = sum(o.seconds for o in outcomes)
    return {"jobs": len(outcomes), "wall_s": wall, "jobs_per_hour": 3600.0 * len(outcomes) / wall,
            "mean_job_s": busy / len(outcomes)}


def bench_batch(quick: bool = False, adapt_rows: list[dict] | None = None) -> dict:
    count = 4   # `make bench` keeps to ~35 min on 2 cores (the seconds per job are what matter)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        row = _timed(write_jobs(tmp, count), tmp / "out_local", lambda jobs: InProcessDispatcher(jobs.settings))
        rows.append({"setup": "in-process (1 thread per job)", "workers": 1, **row})
        try:
            import ray

            from scenefit.workers.batch_ray import RayDispatcher
        except ImportError:
            ray = None
        if ray is not None:
            ray.init(num_cpus=2, object_store_memory=100 * 2**20, include_dashboard=False, log_to_driver=False)
            try:
                for workers in (1, 2):
                    row = _timed(write_jobs(tmp, count, workers), tmp / f"out_ray{workers}",
                                 lambda jobs: RayDispatcher(jobs.settings, len(jobs.jobs)))
                    rows.append({"setup": f"Ray, local cluster of 2 CPUs", "workers": workers, **row})
            finally:
                ray.shutdown()
    estimate = paper_estimate(adapt_rows or [], rows)
    md = ["Batch throughput, tiny jobs (convert + light, draft preset; a 16x8-segment ball, 64x48 photo), "
          f"{count} jobs per run; Ray start-up left out:", "",
          "| setup | workers | jobs | wall s | s per job (in its worker) | jobs / hour |", "|---|---|---|---|---|---|"]
    md += [f"| {r['setup']} | {r['workers']} | {r['jobs']} | {r['wall_s']:.1f} | {r['mean_job_s']:.2f} | "
           f"{r['jobs_per_hour']:.0f} |" for r in rows]
    md += ["", estimate["text"]]
    return {"rows": rows, "estimate": estimate, "markdown": "\n".join(md)}


def cpu_sd2_jobs(overhead: float) -> str:
    """Jobs per hour on this CPU from the SD2-size adapt rows (results/adapt_sd2.json: bf16, cached, the
    warm step), per preset: iterations x seconds per iteration + the batch overhead per job."""
    path = Path(__file__).resolve().parent / "results" / "adapt_sd2.json"
    if not path.is_file():
        return ""
    rows = [r for r in json.loads(path.read_text())["rows"] if r.get("cache") and "bfloat16" in r.get("dtype", "")]
    parts = [f"{r['preset']} {r['iterations']} x {r['warm_s']:.0f} s = {(r['iterations'] * r['warm_s'] + overhead) / 3600:.1f} h "
             f"per job, {3600.0 / (r['iterations'] * r['warm_s'] + overhead):.3f} jobs/hour" for r in rows]
    return (" On this CPU, from adapt at SD2 size ([adapt_sd2.md](adapt_sd2.md)): " + "; ".join(parts) + "."
            if parts else "")


def gpu_check_rows() -> list[dict]:
    """The per-view step at the paper's settings from `make gpu-check` (results/gpu.json, SD2 size on one
    GPU, the final preset's 4 views rendered in turn): with one view per GPU each rank does one view's
    work, so (step - constant work - Adam) / views + Adam. Empty when no GPU has run the check."""
    path = Path(__file__).resolve().parent / "results" / "gpu.json"
    if not path.is_file():
        return []
    data = json.loads(path.read_text())
    if data["machine"].get("dry_run"):
        return []
    rows = []
    for r in data["rows"]:
        if r["preset"] == "final":
            adam = r["phases"]["step"]
            per_view = (r["iteration_s"] - r["phases"]["constants"] - adam) / r["views_per_step"] + adam
            rows.append({"setup": f"SD2 size on one {data['machine']['device']} ([gpu.md](gpu.md): final, "
                                  f"{r['iteration_s']:.2f} s for {r['views_per_step']} views in turn)",
                         "iteration_s": per_view})
    return rows


def paper_estimate(adapt_rows: list[dict], batch_rows: list[dict], gpus=(4, 8, 32)) -> dict:
    """Jobs per hour at the paper's settings on N GPUs: 4 GPUs per job (one view each), N/4 jobs at once,
    each 4000 iterations of the per-view iteration cost the adapt bench measured (the SD2-sized row on
    CUDA when there is one, else `make gpu-check`'s), plus the batch overhead per job measured here."""
    gpu_rows = [r for r in adapt_rows if "SD2" in r.get("setup", "")] or gpu_check_rows()
    overhead = 0.0
    local = next((r for r in batch_rows if r["setup"].startswith("in-process")), None)
    if local is not None:
        overhead = max(0.0, local["wall_s"] / local["jobs"] - local["mean_job_s"])
    if not gpu_rows:
        per = cpu_sd2_jobs(overhead)
        return {"iteration_s": None, "overhead_s": overhead, "per_gpus": {},
                "text": "Paper settings on N GPUs: needs the adapt bench's SD2-sized row, measured where CUDA exists "
                        "(`make bench` on a GPU machine); jobs/hour = floor(N / 4) x 3600 / (4000 x s per "
                        f"iteration + overhead). Batch overhead per job measured here: {overhead:.2f} s.{per}"}
    t = float(gpu_rows[0]["iteration_s"])
    job_s = PAPER_ITERATIONS * t + overhead
    per_gpus = {n: (n // PAPER_VIEWS_PER_STEP) * 3600.0 / job_s for n in gpus}
    text = (f"Paper settings ({PAPER_ITERATIONS} iterations, {PAPER_VIEWS_PER_STEP} views per step, one per GPU) "
            f"from the measured {t:.3f} s per iteration ({gpu_rows[0]['setup']}): {job_s / 3600:.2f} h per job; "
            + ", ".join(f"{n} GPUs: {v:.2f} jobs/hour" for n, v in per_gpus.items()) + "." + cpu_sd2_jobs(overhead))
    return {"iteration_s": t, "overhead_s": overhead, "per_gpus": per_gpus, "text": text}


def main() -> int:
    import argparse
    import json

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="kept for symmetry with the other benches (4 jobs per run either way)")
    parser.add_argument("--iteration-seconds", type=float,
                        help="an adapt iteration's cost measured elsewhere (one view, SD2 at 512 px on one GPU) "
                             "for the paper-settings estimate")
    args = parser.parse_args()
    adapt_rows = [{"setup": "SD2 (given on the command line)", "iteration_s": args.iteration_seconds}] \
        if args.iteration_seconds else None
    result = bench_batch(quick=args.quick, adapt_rows=adapt_rows)
    results = Path(__file__).resolve().parent / "results"
    results.mkdir(exist_ok=True)
    (results / "batch.md").write_text(result["markdown"] + "\n")
    (results / "batch.json").write_text(json.dumps({"rows": result["rows"], "estimate": result["estimate"]},
                                                   indent=1, default=float))
    print(result["markdown"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
