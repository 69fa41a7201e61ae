"""The glTF JSON reader (core/data/glb.read_gltf, which the bake's engine targets, the asset's file list and
the meshopt decoder read through) against hostile documents: `images` an object or null, primitives a
number, buffers a number, JSON nested 100,000 deep. Each is one sentence naming the file, through
`scenefit bake --target godot` as a user meets it; fuzzed documents give a document or one sentence."""
from __future__ import annotations

import json
import struct

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from conftest import scenefit_process
from scenefit.core.base.errors import InputError
from scenefit.core.data.glb import read_gltf, write_glb

FUZZ = settings(derandomize=True, max_examples=80, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
GOOD = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "images": [{"uri": "a.png"}], "buffers": [{"uri": "a.bin", "byteLength": 4}]}


def _glb(path, document_text: bytes):
    text = document_text + b" " * (-len(document_text) % 4)
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 20 + len(text)) + struct.pack("<I", len(text)) + b"JSON" + text)
    return path


@pytest.mark.parametrize("name, text", [
    ("images_object.glb", json.dumps({**GOOD, "images": {"0": {"uri": "a.png"}}}).encode()),
    ("primitives_number.glb", json.dumps({**GOOD, "meshes": [{"primitives": 3}]}).encode()),
    ("deep.glb", b"[" * 100_000 + b"]" * 100_000),
    ("images_null.gltf", json.dumps({**GOOD, "images": None, "buffers": 7}).encode()),
])
def test_a_hostile_gltf_is_one_sentence_for_an_engine_bake(tmp_path, name, text):
    asset = tmp_path / name
    if name.endswith(".glb"):
        _glb(asset, text)
    else:
        asset.write_bytes(text)
    texture = tmp_path / "texture.pt"
    texture.write_bytes(b"not read")
    proc = scenefit_process("bake", asset, "--texture", texture, "--out", tmp_path / "out.glb", "--target", "godot",
                            "--quiet")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert str(asset) in proc.stderr and not (tmp_path / "out.glb").exists()


ODD = st.one_of(st.none(), st.integers(-5, 2**64), st.floats(), st.text(max_size=5), st.booleans(),
                st.lists(st.integers(-2, 5), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
KEYS = ["images", "buffers", "meshes", "nodes", "scenes", "extensionsUsed", "extensionsRequired", "materials"]


@FUZZ
@given(st.data())
def test_fuzz_gltf_json_gives_a_document_or_one_sentence(tmp_path_factory, data):
    from scenefit.core.stages.bake.gltf_output import output_like_input

    document = json.loads(json.dumps(GOOD))
    for _ in range(data.draw(st.integers(1, 3))):
        where = data.draw(st.sampled_from(["top", "mesh", "primitive", "node", "image"]))
        value = data.draw(ODD)
        key = data.draw(st.sampled_from(KEYS + ["primitives", "attributes", "children", "uri", "mesh"]))
        target = {"top": document, "mesh": document["meshes"][0] if isinstance(document.get("meshes"), list)
                  and document["meshes"] and isinstance(document["meshes"][0], dict) else document,
                  "primitive": document, "node": document, "image": document}[where]
        target[key] = value
    text = json.dumps(document, allow_nan=True).encode()
    folder = tmp_path_factory.mktemp("gltf")
    path = folder / "a.glb"
    _glb(path, text) if data.draw(st.booleans()) else (path := folder / "a.gltf").write_bytes(text)
    try:
        read_gltf(path)
        output_like_input(path, target=data.draw(st.sampled_from(["godot", "unity", "web", "as-imported"])))
        write_glb(folder / "b.glb", *read_gltf(path)[:1], b"")
    except InputError as error:
        assert "\n" not in str(error)
