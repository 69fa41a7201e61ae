"""A stage is one record: a throwaway stage added through the registry alone (one module of its own, one
registry entry) runs in a pipeline, is configured by its preset and a run's overrides, and is reused
exactly when its config and the stages it reads are unchanged."""
from __future__ import annotations

import json
import threading
import textwrap

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.pipeline.registry import BUILT_IN, Stage, names, registered
from scenefit.core.pipeline.run import run_pipeline
from scenefit.core.pipeline.run_config import RunConfig, stage_subset

# The stage's one module: its config and its work (a histogram of convert's base colour map).
MODULE = textwrap.dedent('''
    from dataclasses import dataclass
    import json

    import numpy as np

    from scenefit.core.data.imageio import read_image


    @dataclass(frozen=True)
    class HistogramConfig:
        bins: int = 8


    def configure(run):
        return run.config_of("histogram")


    def work(run, config, folder):
        maps = run.output("texture").parent
        counts, _ = np.histogram(read_image(maps / "base_color.png"), bins=config.bins, range=(0.0, 1.0))
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "histogram.json").write_text(json.dumps(counts.tolist()))
        return {"stage": "histogram", "outputs": {"histogram": str(folder / "histogram.json")}}
''')


@pytest.fixture()
def histogram_stage(tmp_path, monkeypatch):
    (tmp_path / "histogram_stage.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    import histogram_stage

    record = Stage("histogram", "histogram_stage",
                   config=lambda table, overrides: histogram_stage.HistogramConfig(**{**table, **overrides}),
                   presets={"draft": {"bins": 4}, "balanced": {}, "final": {"bins": 16}},
                   reads=("convert",), writes={"histogram": "histogram.json"}, alone=True)
    with registered(record, after="convert"):
        yield record


def _run(tmp_path, **overrides):
    mesh, maps = uv_sphere(0.5, 16, 8), PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    config = RunConfig(preset="draft", guidance_type="none", stage_overrides=overrides)
    return run_pipeline(mesh, maps, None, None, tmp_path / "run", config, cancel=threading.Event(),
                        stages=("convert", "histogram"))


def test_a_stage_added_by_one_entry_runs_and_is_reused(tmp_path, histogram_stage):
    assert "histogram" in names().STAGES and "histogram" in names().CONFIG_STAGES
    assert "histogram" not in BUILT_IN.STAGES   # (the built-in names are the registry's as shipped)
    assert stage_config("histogram", "final").bins == 16
    assert stage_subset(["histogram", "convert"]) == ("convert", "histogram")

    first = _run(tmp_path)
    assert [first.stages[s].status for s in ("convert", "histogram")] == ["ran", "ran"]
    counts = json.loads((tmp_path / "run" / "histogram" / "histogram.json").read_text())
    assert len(counts) == 4 and sum(counts) > 0   # the draft preset's bins, of convert's map

    again = _run(tmp_path)
    assert again.reused == ("convert", "histogram")

    # Its own settings change: it runs again, and what it reads is reused.
    finer = _run(tmp_path, histogram={"bins": 6})
    assert [finer.stages[s].status for s in ("convert", "histogram")] == ["reused", "ran"]
    assert len(json.loads((tmp_path / "run" / "histogram" / "histogram.json").read_text())) == 6

    # What it reads changes (convert's key): its key holds convert's, so it runs again too.
    refit = _run(tmp_path, histogram={"bins": 6}, convert={"iterations": 3})
    assert [refit.stages[s].status for s in ("convert", "histogram")] == ["ran", "ran"]
    assert refit.stages["histogram"].key != finer.stages["histogram"].key


def test_the_added_stage_leaves_the_registry_when_done(histogram_stage):
    assert "histogram" in names().RUN_ORDER
    with pytest.raises(InputError, match="registered already"):
        with registered(histogram_stage):
            pass


def test_the_added_stage_is_gone_after_its_block():
    assert names() == BUILT_IN
    with pytest.raises(InputError, match="unknown stage 'histogram'"):
        RunConfig(stage_overrides={"histogram": {"bins": 3}})
    with pytest.raises(InputError, match="unknown stage 'histogram'"):
        stage_subset(["histogram"])
