"""The docs' generators read the code as written: a dataclass's fields and their meanings in each style
the code uses, a benchmark page's tables, the presets' resolved values."""
from __future__ import annotations

import importlib.util
import sys
import textwrap

import pytest

from conftest import ROOT

EXT = ROOT / "docs" / "_ext"


@pytest.fixture(scope="module", autouse=True)
def extensions_importable():
    sys.path.insert(0, str(EXT))
    yield
    sys.path.remove(str(EXT))


def module_from(tmp_path, name: str, source: str):
    path = tmp_path / f"{name}.py"
    path.write_text(textwrap.dedent(source))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


TOY = '''
    """A module with an example:

        colour = "red"      # the example's word for colour
    """
    from dataclasses import dataclass, field


    @dataclass(frozen=True)
    class Inner:
        a: int = 1
        b: int = 2


    @dataclass(frozen=True)
    class Toy:
        """A toy config.

        shape / size: how it looks, said once for both. speed: how fast, in m/s.
        """

        name: str
        """Its name, as a docstring."""
        count: int = 3          # how many, said on its line
                                # and carried on the next
        # said above it
        # over two lines
        ratio: float = 0.5
        shape: str = "round"
        size: float = 1.0
        speed: float = 2.0
        colour: str = "blue"
        inner: Inner = Inner(b=5)
        tags: tuple = field(default_factory=tuple)
        silent: int = 0
'''


def test_field_meanings_come_from_each_place_the_code_writes_them(tmp_path):
    from dataclass_fields import dataclass_rows

    toy = module_from(tmp_path, "toy_config", TOY)
    rows = {row[0]: row[1:] for row in dataclass_rows(toy.Toy)}
    assert list(rows) == ["name", "count", "ratio", "shape", "size", "speed", "colour", "inner", "tags", "silent"]
    assert rows["name"] == ["str", "required", "Its name, as a docstring."]
    assert rows["count"] == ["int", "3", "how many, said on its line and carried on the next"]
    assert rows["ratio"][2] == "said above it over two lines"
    assert rows["shape"][2] == rows["size"][2] == "how it looks, said once for both."
    assert rows["speed"][2] == "how fast, in m/s."
    assert rows["colour"][2] == "the example's word for colour"
    assert rows["inner"][1] == "Inner(b=5)" and rows["tags"][1] == "()"
    assert rows["silent"] == ["int", "0", ""]


def test_an_excluded_field_is_left_out(tmp_path):
    from dataclass_fields import dataclass_rows

    toy = module_from(tmp_path, "toy_config2", TOY)
    assert "count" not in [row[0] for row in dataclass_rows(toy.Toy, exclude={"count"})]


def test_a_benchmark_pages_tables_are_read_cell_by_cell():
    from results_table import markdown_tables

    text = "# Title\n\nWords | not a table\n\n| a | b |\n|---|:-:|\n| 1 | 2 |\n| 3 | 4 |\n\nmore\n\n| c |\n|---|\n| x |\n"
    assert markdown_tables(text) == [[["a", "b"], ["1", "2"], ["3", "4"]], [["c"], ["x"]]]


def test_the_presets_rows_are_the_tables_and_the_resolved_defaults():
    from presets_table import stage_rows
    from scenefit.core.pipeline.preset_tables import TABLES
    from scenefit.core.pipeline.presets import stage_config

    rows = {row[0]: row[1:] for row in stage_rows("compose")}
    assert rows["noise_target"] == [str(TABLES["compose"][p]["noise_target"]) for p in ("draft", "balanced", "final")]
    assert rows["max_side"][1] == f"{stage_config('compose', 'balanced').max_side} (default)"
    adapt = {row[0]: row[1:] for row in stage_rows("adapt")}
    assert adapt["iterations"][2] == f"{stage_config('adapt', 'final', prompt='x').iterations}"   # (in the table)
    assert adapt["views_per_step"][2] == f"{stage_config('adapt', 'final', prompt='x').views_per_step} (default)"
    assert adapt["size_scale"][2] == "1.0 (default)"


def test_the_jobs_file_tables_describe_every_key_in_the_files_words():
    """The jobs-file page's tables (docs/technical/jobs-file.md): every key has a meaning, and no meaning names a
    Python field the file has no key for (the run's camera_overrides is the file's `camera`)."""
    import dataclasses
    import re

    from dataclass_fields import dataclass_rows

    from scenefit.core.guidance.models import ModelConfig
    from scenefit.core.pipeline.run_config import RunConfig
    from scenefit.core.pipeline.run_table import RUN_KEYS
    from scenefit.workers.jobs import BatchSettings, Job

    tables = {"run": (RunConfig, dataclass_rows(RunConfig, keys=RUN_KEYS)),
              "job": (Job, dataclass_rows(Job, exclude={"run"})),
              "batch": (BatchSettings, dataclass_rows(BatchSettings)),
              "models": (ModelConfig, dataclass_rows(ModelConfig))}
    for name, (cls, rows) in tables.items():
        keys = {row[0] for row in rows}
        hidden = {f.name for f in dataclasses.fields(cls) if "_" in f.name} - keys
        for key, _type, _default, meaning in rows:
            assert meaning.strip(), f"[{name}] {key} has no meaning in the table"
            named = set(re.findall(r"[a-z]+_[a-z_]+", meaning)) & hidden
            assert not named, f"[{name}] {key}'s meaning names {named}, which a jobs file does not spell"
