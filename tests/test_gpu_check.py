"""`make gpu-check` works the first time a GPU is lent (issue 24): its dry run is the same code path
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

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "gpu_check.py"


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=600,
                          cwd=ROOT, env=dict(os.environ))


def test_the_dry_run_measures_the_final_preset_with_tiny_models(tmp_path):
    proc = run("--dry-run", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((tmp_path / "gpu.json").read_text())
    assert data["machine"]["dry_run"] and data["machine"]["models"] == "tiny"
    (row,) = data["rows"]
    assert row["preset"] == "final" and row["iterations"] == 1
    assert math.isfinite(row["iteration_s"]) and row["iteration_s"] > 0
    assert {"render", "vae", "unet", "vae_backward", "step"} <= set(row["phases"])
    assert row["phases"]["unet"] > 0 and row["peak_memory_mb"] > 0
    table = (tmp_path / "gpu.md").read_text()
    assert "| final |" in table and "DRY RUN" in table


@pytest.mark.skipif(torch.cuda.is_available(), reason="on a GPU machine the real check runs instead")
def test_without_a_gpu_the_real_check_is_one_sentence_and_builds_nothing(tmp_path):
    proc = run("--models", tmp_path / "models", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "no CUDA GPU" in proc.stderr
    assert not (tmp_path / "models").exists() and not (tmp_path / "out").exists()
