"""Structured data from elsewhere is read one way (core/base/untrusted.py): limits on size and nesting,
finite numbers, a typed shape; every failure one InputError sentence naming the file and the field.
The fuzz half: random and mutated JSON bytes give a value or that sentence, never another exception."""
from __future__ import annotations

import json
import os

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.core.base.errors import InputError
from scenefit.core.base.untrusted import (MAX_DEPTH, StageRecord, checked, nesting_depth, parse_json, read_bytes,
                                          read_json, read_stage_record)

# Seeded and bounded: the same examples every run, a few seconds per reader.
FUZZ = settings(derandomize=True, max_examples=300, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])
GOOD = {"key": "abc", "report": {"stage": "light", "outputs": {"light_exr": "light.exr", "metallic": 0.0,
                                                                "maps": {"base": "maps/base.png"}}}}


def one_sentence(error: InputError, *words: str) -> None:
    text = str(error)
    assert text.endswith(".") and "\n" not in text and "Traceback" not in text, text
    for word in words:
        assert word in text, (word, text)


def test_a_good_record_reads_with_its_extra_fields_kept(tmp_path):
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(GOOD))
    record = read_stage_record(path)
    assert record.key == "abc" and record.report.model_dump() == GOOD["report"]


@pytest.mark.parametrize("raw, words", [
    (b"[]", ("its top level",)),                                     # a JSON list, not a record
    (b"[" * 100_000 + b"]" * 100_000, ("nests deeper",)),             # 100,000 deep
    (b"\xff\xfe{}", ("not UTF-8",)),
    (b'{"key": "abc", "report": {"outputs": []}}', ("report.outputs",)),
    (b'{"key": 7, "report": {}}', ("'key'",)),
    (b'{"key": "abc", "report": {"x": NaN}}', ("not usable",)),
    (b'{"key": "abc", "report": {"x": 1e999}}', ("not usable",)),
    (b'{"key": "abc", "report": {"x": ' + b"9" * 5000 + b"}}", ("not usable",)),
    (b'{"key": "abc", ', ("not valid JSON",)),
])
def test_a_planted_stage_record_is_one_sentence_naming_file_and_field(tmp_path, raw, words):
    path = tmp_path / "convert" / "stage.json"
    path.parent.mkdir()
    path.write_bytes(raw)
    with pytest.raises(InputError) as caught:
        read_stage_record(path)
    one_sentence(caught.value, str(path), *words)


def test_size_and_depth_limits_hold_at_their_edges(tmp_path):
    inside = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    assert nesting_depth(parse_json(inside, "x")) == MAX_DEPTH
    with pytest.raises(InputError, match="nests deeper"):
        parse_json("[" + inside + "]", "x")
    path = tmp_path / "big.json"
    path.write_bytes(b" " * 1000 + b"{}")
    assert parse_json(read_bytes(path, max_bytes=1002), "x") == {}
    with pytest.raises(InputError, match="over 1001 bytes"):
        read_bytes(path, max_bytes=1001)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")
def test_a_fifo_or_folder_is_refused_without_being_opened(tmp_path):
    fifo = tmp_path / "stage.json"
    os.mkfifo(fifo)   # opening it for reading would wait for a writer for ever
    with pytest.raises(InputError, match="not a regular file"):
        read_json(fifo, StageRecord)
    with pytest.raises(InputError, match="not a regular file"):
        read_json(tmp_path, StageRecord)


json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
                           lambda children: st.lists(children, max_size=4)
                           | st.dictionaries(st.text(max_size=8), children, max_size=4), max_leaves=20)


@FUZZ
@given(st.binary(max_size=300))
def test_fuzz_random_bytes_give_a_value_or_one_sentence(raw):
    try:
        checked(parse_json(raw, "the stage record 'x'"), StageRecord, "the stage record 'x'")
    except InputError as error:
        one_sentence(error, "'x'")


@FUZZ
@given(st.data())
def test_fuzz_mutated_records_give_a_record_or_one_sentence(data):
    text = json.dumps(data.draw(st.one_of(st.just(GOOD), json_values, st.fixed_dictionaries(
        {"key": json_values, "report": st.fixed_dictionaries({"outputs": json_values})}))))
    raw = bytearray(text.encode())
    for _ in range(data.draw(st.integers(0, 3))):   # a few bytes overwritten, cut or doubled
        at = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        pieces = [b"", b"[", b"}", b'"', b"\xff", b"1e999", b"NaN", raw[at:at + 1] * 2]
        raw[at:at + 1] = data.draw(st.sampled_from(pieces))
    try:
        record = checked(parse_json(bytes(raw), "the stage record 'x'"), StageRecord, "the stage record 'x'")
        assert isinstance(record.key, str) and isinstance(record.report.outputs, dict)
    except InputError as error:
        one_sentence(error, "'x'")
