"""A partial `make bench` (benchmarks/run.py --parts) replaces only its own sections of bench.md and its
own numbers in bench.json; an earlier pass's others stay (a parts run used to leave bench.md holding only
its parts)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from conftest import ROOT

_SPEC = importlib.util.spec_from_file_location("bench_run", ROOT / "benchmarks" / "run.py")
bench_run = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench_run)

STUDY, CAMERA = f"## {bench_run.SECTION_TITLES['study']}", f"## {bench_run.SECTION_TITLES['camera']}"
REAL = "## " + next(title for part, *_, title in bench_run.SEPARATE if part == "light_real")


def _doc(*units: tuple[str, str]) -> str:
    return "\n".join([f"{heading}\n\n{body}\n" for heading, body in units])


EARLIER = "# `make bench` results\n\n**Full `make bench`.** Total 43 min.\n\n" + _doc(
    ("## Presets: speed against accuracy", ""), ("### Convert", "convert table, old"),
    ("### Light", "light table, old"), ("## Building blocks", "blocks, old"),
    (STUDY, "study, old\n\n## Development maps\n\nper-map table, old"), (CAMERA, "camera, old"))


def test_a_partial_pass_replaces_its_sections_in_place_and_adds_new_ones_in_order():
    new = _doc(("## Presets: speed against accuracy", ""), ("### Light", "light table, new"), (REAL, "real, new"))
    merged = bench_run.merged_sections(EARLIER, new, "(Re-run since, on their own: light, light_real; today.)")
    assert "light table, new" in merged and "light table, old" not in merged
    for kept in ("convert table, old", "blocks, old", "camera, old", "per-map table, old"):
        assert merged.count(kept) == 1   # a quoted file's own "## " heading stays inside its section
    # bench.md's order: the presets' stages, then the fixed sections, then the separate benches
    order = [merged.index(text) for text in ("convert table", "light table, new", "blocks, old", "study, old",
                                              "per-map table", "camera, old", "real, new")]
    assert order == sorted(order)
    assert merged.startswith("# `make bench` results\n\n**Full `make bench`.** Total 43 min.\n\n(Re-run since")
    # a second partial pass says only its own parts, once
    again = bench_run.merged_sections(merged, _doc((CAMERA, "camera, newer")), "(Re-run since, on their own: camera.)")
    assert again.count("(Re-run since") == 1 and "on their own: camera." in again
    assert "camera, newer" in again and "real, new" in again and "camera, old" not in again


def test_every_heading_a_pass_writes_is_known_once():
    titles = bench_run.section_titles()
    assert len(titles) == len(set(titles))
    assert {f"### {title}" for title in bench_run.TITLES.values()} <= set(titles)
    assert {STUDY, CAMERA, REAL, f"## {bench_run.SECTION_TITLES['conversion']}"} <= set(titles)


def test_a_partial_pass_keeps_the_numbers_it_did_not_measure():
    earlier = {"mode": "full", "seconds": 2600.0, "render": [{"scene": "sphere"}], "adapt": [{"phase": "old"}],
               "trade": {"convert": [1], "light": [2]}}
    numbers = {"mode": "full", "seconds": 90.0, "render": [], "adapt": [{"phase": "new"}], "trade": {"light": [3]}}
    merged = bench_run.merged_numbers(earlier, numbers)
    assert merged["render"] == [{"scene": "sphere"}] and merged["adapt"] == [{"phase": "new"}]
    assert merged["trade"] == {"convert": [1], "light": [3]}
    assert merged["seconds"] == pytest.approx(2600.0)   # the full pass's total, which bench.md's head quotes
