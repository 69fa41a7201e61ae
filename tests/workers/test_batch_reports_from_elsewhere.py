"""A batch's reports keep the README's promise (paths relative to the report, never a staging folder or a
worker's temporary folder, which are gone once the job ends), and a job report read back is data: a
planted one that is a list, 100,000 deep or not UTF-8 reads as no report (the job runs again)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.core.base.report import relative_paths, write_report
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.workers.batch import job_report, run_batch
from scenefit.workers.jobs import load_jobs

from batch_inputs import CONVERT_JOB

JOBS = CONVERT_JOB


def strings(value):
    if isinstance(value, dict):
        for v in value.values():
            yield from strings(v)
    elif isinstance(value, list):
        for v in value:
            yield from strings(v)
    elif isinstance(value, str):
        yield value


def test_a_batch_jobs_report_names_no_temporary_or_staging_folder(tmp_path):
    save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((8, 8, 3), 0.5, np.float32)), tmp_path / "ball")
    (tmp_path / "jobs.toml").write_text(JOBS)
    [outcome] = run_batch(load_jobs(tmp_path / "jobs.toml"), tmp_path / "out")
    assert outcome.status == "done"
    report = json.loads((tmp_path / "out" / "a" / "report.json").read_text())
    texts = list(strings(report))
    assert not [t for t in texts if "scenefit-job-" in t or ".partial" in t], texts
    assert any(str(tmp_path / "ball") in t for t in texts)   # the asset named as the user's folder
    for text in texts:   # a whole-string path inside the job's folder is relative to it, and there
        if text.endswith((".png", ".pt")) and not text.startswith("/"):
            assert (tmp_path / "out" / "a" / text).is_file(), text


def test_write_report_names_a_staging_folder_as_the_folder_it_becomes(tmp_path):
    staging = tmp_path / ".out.partial"
    report = write_report(staging / "report.json", {
        "outputs": {"map": str(staging / "maps" / "a.png")},
        "notes": [f"read asset folder '{staging / 'asset'}'", f"job '{tmp_path / 'runs' / '.j.partial-ab12_x' / 'q'}'"],
        "why": "a word like partial stays"})
    saved = json.loads(report.read_text())
    assert saved["outputs"]["map"] == "maps/a.png"
    assert saved["notes"] == ["read asset folder 'asset'", f"job '{tmp_path / 'runs' / 'j' / 'q'}'"]
    assert saved["why"] == "a word like partial stays"
    assert relative_paths(Path("/elsewhere/.run.partial/z"), tmp_path) == "/elsewhere/run/z"


@pytest.mark.parametrize("raw", [b"[1]", b"[" * 100_000, b"\xff\xfe", b'{"status": "done", "stages": {"run": 7}}',
                                 b'{"status": ["done"]}'])
def test_a_planted_job_report_reads_as_none(tmp_path, raw):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "report.json").write_bytes(raw)
    assert job_report(tmp_path, "a") is None
    (tmp_path / "a" / "report.json").write_text('{"status": "done", "digest": "d", "seconds": 2}')
    assert job_report(tmp_path, "a")["digest"] == "d"


@settings(derandomize=True, max_examples=150, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
                    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.sampled_from(
                        ["status", "digest", "attempts", "seconds", "quality", "stages", "run", "x"]), c, max_size=4),
                    max_leaves=15), st.binary(max_size=8))
def test_fuzz_job_reports_read_as_a_report_or_none(tmp_path, value, tail):
    (tmp_path / "a").mkdir(exist_ok=True)
    (tmp_path / "a" / "report.json").write_bytes(json.dumps(value).encode() + (tail if tail[:1] == b"\xff" else b""))
    report = job_report(tmp_path, "a")
    if report is not None:   # what the batch reads of it is of the types it uses
        assert isinstance(report["status"], str) and isinstance(report["digest"], str)
        assert isinstance(report["stages"]["run"]["stages"], dict) and isinstance(report["quality"], dict)
