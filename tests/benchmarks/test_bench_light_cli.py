"""`bench_light.py --real` pointed at a folder without the corpus's maps says so in one sentence and
exits 2, writing nothing (it gave a traceback from deep in the image reader)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from conftest import ROOT, takes_ctrl_c  # noqa: E402


def test_a_folder_without_the_maps_gets_one_sentence_and_exit_2(tmp_path):
    (tmp_path / "autoshop_01_1k.hdr").write_bytes(b"")   # one present (even empty), the rest missing
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_light.py"), "--real", "--corpus",
                           str(tmp_path), "--out", str(out)], capture_output=True, text=True, timeout=300,
                          cwd=ROOT, env=dict(os.environ))
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert str(tmp_path) in lines[0] and "11 of the 12" in lines[0]
    assert not out.exists()


def test_ctrl_c_half_way_gets_one_sentence_and_leaves_no_results(tmp_path):
    """Interrupted after its first view, the real protocol says so in one sentence, exits 130 and
    leaves no results folder (its files are written only when the run ends)."""
    import signal

    import numpy as np

    from scenefit.core.data.imageio import write_image

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_light import REAL_MAPS

    corpus = tmp_path / "hdri"
    sky = np.ones((16, 32, 3), np.float32)
    sky[:4, 10:12] = 50.0                                  # a small bright light, so the views have a direction
    for name in REAL_MAPS:
        write_image(corpus / f"{name}_1k.hdr", sky)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(ROOT / "benchmarks" / "bench_light.py"), "--real", "--no-draft",
                             "--corpus", str(corpus), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=dict(os.environ, PYTHONWARNINGS="ignore"),
                            preexec_fn=takes_ctrl_c)
    first = proc.stdout.readline()                         # the first view is done: the run is under way
    assert "wins" in first, proc.stderr.read()[-2000:] if proc.poll() is not None else first
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err[-2000:]
    lines = err.strip().splitlines()
    assert lines[-1] == "bench_light: interrupted (its results are written only when a run ends)."
    assert "Traceback" not in err
    assert not out.exists()


def test_the_confidence_line_counts_wins_on_both_at_and_below_full_confidence():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_light import confidence_line

    def row(confidence, si, rmse):   # the estimate's diffuse si-RMSE and RMSE; the constant's are 1 and 1
        metrics = {m: {"diffuse": {"linear": {"si_rmse": v[0], "rmse": v[1]}}}
                   for m, v in (("estimate", (si, rmse)), ("constant", (1.0, 1.0)))}
        return {"confidence": confidence, "metrics": metrics}

    rows = [row(1.0, 0.5, 0.5), row(1.0, 0.5, 2.0), row(1.0, 2.0, 0.5), row(0.5, 0.5, 0.5), row(0.25, 0.9, 0.9),
            row(None, 0.5, 0.5)]
    line = confidence_line(rows)
    assert "on both on 1 of the 3 views at confidence 1 and on 3 of the 3 below it" in line, line
