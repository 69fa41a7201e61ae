"""The toward/away bench's two judgements (benchmarks/bench_light_sides.py) on rows with known answers."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

from conftest import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_light_sides import LEVELS, level_table, side_split  # noqa: E402


def _row(side: str, best_level: float, feature: float) -> dict:
    """A view whose flat environment is best at `best_level` x the constant (its RMSE grows with the log
    distance to it; the constant, k = 1, scores as its own level does)."""
    errors = [1.0 + abs(math.log(k / best_level)) for k in LEVELS]
    return {"side": side, "rmse_by_level": errors, "constant_rmse": errors[LEVELS.index(1.0)],
            "features": {name: feature for name in ("clipped fraction", "clipped fraction, upper half",
                                                    "top third / bottom third", "99th percentile / median",
                                                    "saturation", "surfaces / mean")}}


def test_each_side_finds_its_own_level_and_one_level_for_both_is_a_compromise():
    rows = [_row("toward", 0.5, 1.0) for _ in range(3)] + [_row("away", 8.0, 0.0) for _ in range(3)]
    table = level_table(rows)
    assert table["toward_best"]["level"] == pytest.approx(0.5) and table["away_best"]["level"] == pytest.approx(8.0)
    assert table["toward_best"]["toward"]["beats"] == 3 and table["toward_best"]["away"]["beats"] == 0
    # Sides 16x apart: any level but the constant's own loses on one side, so one level for both is 1.
    assert table["one_level"]["level"] == 1.0 and table["one_level"]["toward"]["beats"] == 0
    # Sides 2x apart: one level between them beats the constant on both.
    close = level_table([_row("toward", 2.0, 1.0), _row("away", 4.0, 0.0)])["one_level"]
    assert 2.0 <= close["level"] <= 4.0 and close["toward"]["beats"] == close["away"]["beats"] == 1


def test_a_measure_that_tells_the_side_is_found_and_scored_on_views_it_was_not_set_on():
    train = [_row("toward", 1.0, 0.9), _row("toward", 1.0, 0.8), _row("away", 1.0, 0.1), _row("away", 1.0, 0.2)]
    held = [_row("toward", 1.0, 0.7), _row("away", 1.0, 0.3)]
    split = side_split(train, held)["clipped fraction"]
    assert split["development"] == 1.0 and split["held_out"] == 1.0 and split["toward_if_above"]
    flipped = [_row("toward", 1.0, 0.0), _row("away", 1.0, 1.0)]   # the same threshold, the sides the other way
    assert side_split(train, flipped)["clipped fraction"]["held_out"] == 0.0
    # a measure that says nothing of the side: the same value on both sides is at chance on either set
    blind = [_row("toward", 1.0, 0.5), _row("away", 1.0, 0.5)]
    assert side_split(blind, blind)["clipped fraction"] == {"threshold": 0.5, "toward_if_above": True,
                                                            "development": 0.5, "held_out": 0.5}
