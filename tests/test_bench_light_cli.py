"""`bench_light.py --real` pointed at a folder without the corpus's maps says so in one sentence and
exits 2, writing nothing (it gave a traceback from deep in the image reader)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


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
