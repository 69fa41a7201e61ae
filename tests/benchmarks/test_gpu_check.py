"""`make gpu-check` works the first time a GPU is lent: its dry run is the same code path
with the tiny models on the CPU, and without a GPU the real check says so in one sentence."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from conftest import ROOT  # noqa: E402
SCRIPT = ROOT / "benchmarks" / "gpu_check.py"


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=600,
                          cwd=ROOT, env=dict(os.environ))


def test_the_dry_run_measures_every_preset_with_tiny_models(tmp_path):
    proc = run("--dry-run", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((tmp_path / "gpu.json").read_text())
    assert data["machine"]["dry_run"] and data["machine"]["models"] == "tiny"
    assert data["machine"]["model_build_s"] > 0
    assert [row["preset"] for row in data["rows"]] == ["final", "draft", "balanced"]
    for row in data["rows"]:
        assert row["iterations"] == 1
        assert math.isfinite(row["iteration_s"]) and row["iteration_s"] > 0
        assert {"constants", "render", "vae", "unet", "vae_backward", "step"} <= set(row["phases"])
        assert row["phases"]["unet"] > 0 and row["peak_memory_mb"] > 0
    assert [row["preset"] for row in data["light_rows"]] == ["draft", "balanced", "final"]
    for row in data["light_rows"]:
        assert row["iterations"] == 1 and math.isfinite(row["per_iteration_s"]) and row["per_iteration_s"] > 0
    # Both renderers: the loop renderer (adapt's default) and the paper's path tracing, per preset.
    assert [row["preset"] for row in data["loop_rows"]] == ["final", "draft", "balanced"]
    assert {row["renderer"] for row in data["loop_rows"]} == {"loop"} and {row["renderer"] for row in data["rows"]} == {"path"}
    assert all(row["phases"]["render"] > 0 for row in data["loop_rows"])
    # Final and balanced step through 2 views in the dry run: the loop renderer's in one pass per model,
    # path tracing's one at a time (Mitsuba replays a render from the scene's state at backward).
    views = {row["preset"]: row["views_per_step"] for row in data["loop_rows"]}
    assert views == {"final": 2, "draft": 1, "balanced": 2}
    assert [row["batched_steps"] for row in data["loop_rows"]] == [1, 0, 1]
    assert all(row["batched_steps"] == 0 for row in data["rows"])
    # The loop renderer's one-off tracing is its own phase; path tracing has none.
    assert all(row["phases"]["trace"] > 0 for row in data["loop_rows"])
    assert all(row["phases"]["trace"] == 0 for row in data["rows"])
    table = (tmp_path / "gpu.md").read_text()
    assert "| final |" in table and "| balanced |" in table and "DRY RUN" in table and "loop renderer" in table
    assert "| one pass per model |" in table and "| one at a time |" in table and "without tracing" in table
    assert "s per critic iteration" in table


def test_the_paper_estimate_takes_one_view_per_gpu_from_the_gpu_check():
    """bench_batch's paper-settings estimate from results/gpu.json: the final preset's step split into
    its views (one per GPU at the paper's 4), 4000 iterations, floor(N / 4) jobs at once."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_batch import gpu_check_rows, paper_estimate

    (row,) = [r for r in json.loads((ROOT / "benchmarks/results/gpu.json").read_text())["rows"] if r["preset"] == "final"]
    p = row["phases"]
    per_view = (row["iteration_s"] - p["constants"] - p["step"]) / row["views_per_step"] + p["step"]
    (derived,) = gpu_check_rows()
    assert derived["iteration_s"] == pytest.approx(per_view) and per_view < row["iteration_s"] / 2
    batch = [{"setup": "in-process", "workers": 1, "jobs": 4, "wall_s": 8.0, "mean_job_s": 1.5}]
    estimate = paper_estimate([], batch, gpus=(4, 8))
    assert estimate["overhead_s"] == pytest.approx(0.5)
    assert estimate["per_gpus"][4] == pytest.approx(3600 / (4000 * per_view + 0.5))
    assert estimate["per_gpus"][8] == pytest.approx(2 * estimate["per_gpus"][4])


@pytest.mark.skipif(torch.cuda.is_available(), reason="on a GPU machine the real check runs instead")
def test_without_a_gpu_the_real_check_is_one_sentence_and_builds_nothing(tmp_path):
    proc = run("--models", tmp_path / "models", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "no CUDA GPU" in proc.stderr
    assert not (tmp_path / "models").exists() and not (tmp_path / "out").exists()
