"""EXT_meshopt_compression data is from elsewhere: a count or stride the view cannot hold (a count of
10^12 would have the decoder allocate terabytes), bytes outside the buffer, fields of the wrong type or a
document of another shape are one sentence before anything is decoded; mutated files decode or give it."""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.core.base.errors import InputError
from scenefit.core.data.glb import read_gltf, write_glb
from scenefit.core.data.gltf_meshopt import EXTENSION, encoded_glb, importable



def plain_glb(path):
    """A strip of 38 triangles: float positions (vec3), UVs (vec2), uint16 indices, as an exporter writes them."""
    rng = np.random.default_rng(3)
    parts = [rng.normal(size=(40, 3)).astype(np.float32).tobytes(), rng.uniform(size=(40, 2)).astype(np.float32)
             .tobytes(), np.array([[i, i + 1, i + 2] for i in range(38)], np.uint16).tobytes()]
    offsets = np.cumsum([0] + [len(p) for p in parts]).tolist()
    write_glb(path, {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 40, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5126, "count": 40, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 114, "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteOffset": offsets[i], "byteLength": len(p),
                         "target": 34963 if i == 2 else 34962} for i, p in enumerate(parts)],
        "buffers": [{"byteLength": offsets[-1]}]}, b"".join(parts))
    return path


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshopt")
    path = encoded_glb(plain_glb(folder / "plain.glb"), folder / "packed.glb")
    return read_gltf(path)


def rewritten(tmp_path, packed, change) -> object:
    document, chunk = copy.deepcopy(packed[0]), packed[1]
    change(document)
    path = tmp_path / "asset.glb"
    write_glb(path, document, chunk)
    return path


def sentence_of(path) -> str:
    with pytest.raises(InputError) as caught:
        with importable(path):
            pass
    text = str(caught.value)
    assert "\n" not in text and text.endswith(".") and ("'asset.glb'" in text or f"'{path}'" in text), text
    return text


def meshopt(document, index=0) -> dict:
    return document["bufferViews"][index]["extensions"][EXTENSION]


@pytest.mark.parametrize("field, value, words", [
    ("count", 10**12, ("decodes to 1000000000000 x 12 bytes",)),
    ("count", -1, ("bufferView 0's EXT_meshopt_compression", "'count'")),
    ("count", "40", ("count",)),
    ("byteStride", 6, ("mode ATTRIBUTES cannot hold",)),
    ("byteStride", 0, ("byteStride",)),
    ("mode", "QUADS", ("mode",)),
    ("byteOffset", 2**40, ("which holds",)),
    ("buffer", 7, ("which holds 0",)),
])
def test_a_count_or_field_the_view_cannot_hold_is_one_sentence(tmp_path, packed, field, value, words):
    text = sentence_of(rewritten(tmp_path, packed, lambda d: meshopt(d).update({field: value})))
    for word in words:
        assert word in text, (word, text)


def test_a_huge_view_is_refused_before_the_decoder_allocates(tmp_path, packed):
    def huge(document):
        meshopt(document).update(count=2**30)
        document["bufferViews"][0]["byteLength"] = 2**30 * 12
    assert "past 2 GiB" in sentence_of(rewritten(tmp_path, packed, huge))


@pytest.mark.parametrize("change", [
    lambda d: d.update(bufferViews={"0": 1}), lambda d: d.update(images=[{"uri": 5}]),
    lambda d: d["bufferViews"][0].update(extensions=[EXTENSION]), lambda d: d.update(buffers=[7]),
])
def test_a_document_of_another_shape_is_one_sentence(tmp_path, packed, change):
    sentence_of(rewritten(tmp_path, packed, change))


VALUES = st.one_of(st.integers(-2**40, 2**40), st.sampled_from(["ATTRIBUTES", "TRIANGLES", "INDICES", "NONE",
                                                                 "OCTAHEDRAL", "x", ""]),
                   st.none(), st.floats(allow_nan=False), st.lists(st.integers(0, 3), max_size=2))


@settings(derandomize=True, max_examples=150, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.data())
def test_fuzz_mutated_meshopt_fields_decode_or_give_one_sentence(tmp_path, packed, data):
    document = copy.deepcopy(packed[0])
    for _ in range(data.draw(st.integers(1, 3))):
        view = data.draw(st.integers(0, len(document["bufferViews"]) - 1))
        target = document["bufferViews"][view]
        target = target["extensions"][EXTENSION] if EXTENSION in target.get("extensions", {}) and \
            data.draw(st.booleans()) else target
        target[data.draw(st.sampled_from(["count", "byteStride", "byteLength", "byteOffset", "buffer", "mode",
                                          "filter"]))] = data.draw(VALUES)
    path = tmp_path / "fuzz.glb"
    write_glb(path, json.loads(json.dumps(document)), packed[1] if data.draw(st.booleans()) else
              data.draw(st.binary(max_size=64)) + packed[1][data.draw(st.integers(0, 64)):])
    try:
        with importable(path) as readable:
            assert read_gltf(readable)[0]["buffers"]
    except InputError as error:
        assert "\n" not in str(error)
