"""An ASCII FBX is text from elsewhere: whatever it holds is read into typed nodes or refused in one
sentence before Blender's writer sees it (blender_io/fbx_ascii.read_text_fbx). The known-good corpus file
still reads; random and mutated text gives a tree or that sentence, never another exception."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.blender_io.fbx_ascii import binary_copy, read_text_fbx
from scenefit.core.base.errors import InputError

CORPUS = Path("/work/shared/corpus/assets/kenney_furniture_ascii_fbx/loungeSofa.fbx")
SMALL = """; FBX 7.3.0 project file
FBXHeaderExtension:  {
\tFBXVersion: 7300
}
Objects:  {
\tGeometry: 4455667788990, "Geometry::Sofa", "Mesh" {
\t\tVertices: *6 {
\t\t\ta: 0,0,0,1.5,-2e-3,3
\t\t}
\t\tPolygonVertexIndex: *3 {
\t\t\ta: 0,1,-2
\t\t}
\t\tProperties70:  {
\t\t\tP: "Lcl Scaling", "Lcl Scaling", "", "A",1,1,1
\t\t\tP: "Visibility", "bool", "", "",1
\t\t}
\t}
}
Connections:  {
\tC: "OO",4455667788990,0
}
"""


def one_sentence(error: InputError, *words: str) -> None:
    text = str(error)
    assert "\n" not in text and text.endswith(".") and text.count(". ") == 0, text
    for word in words:
        assert word in text, (word, text)


def test_a_good_text_reads_with_its_types(tmp_path):
    path = tmp_path / "sofa.fbx"
    path.write_text(SMALL)
    version, nodes = read_text_fbx(path)
    geometry = nodes[1][2][0]
    assert version == 7300 and geometry[1][0] == ("add_int64", 4455667788990)
    vertices, indices, _ = geometry[2]
    assert vertices[1][0][0] == "add_float64_array" and np.array_equal(vertices[1][0][1], [0, 0, 0, 1.5, -2e-3, 3])
    assert indices[1][0][0] == "add_int32_array" and indices[1][0][1].dtype == np.int32


@pytest.mark.parametrize("old, new, words", [
    ("0,0,0,1.5", "0,0,zero,1.5", ("Vertices holds 'zero' among its numbers",)),   # a word in a number array
    ("a: 0,1,-2", "a: 0,1,9e99", ("PolygonVertexIndex",)),
    ("a: 0,1,-2", "a: 0,99998,-2", ("PolygonVertexIndex names vertex 99998 of 2",)),   # a corner past the vertices
    ("a: 0,1,-2", "a: 0,1,-99999", ("PolygonVertexIndex names vertex 99998 of 2",)),
    ('"bool", "", "",1', '"bool", "", "",1e999', ("Visibility", "1e999")),
    ("Geometry: 4455667788990", "Geometry: 99999999999999999999999", ("Geometry",)),
    ("FBXVersion: 7300", 'FBXVersion: "seven"', ("cannot be read",)),
    ("Vertices: *6 {", "Vertices: *6 { b: 1 } Other: *1 {", ("cannot be read",)),
])
def test_a_value_its_field_cannot_take_is_one_sentence(tmp_path, old, new, words):
    path = tmp_path / "sofa.fbx"
    path.write_text(SMALL.replace(old, new))
    with pytest.raises(InputError) as caught:
        read_text_fbx(path)
    one_sentence(caught.value, str(path), *words)


def test_a_word_in_a_number_array_is_one_sentence_before_anything_is_written(tmp_path):
    source = tmp_path / "sofa.fbx"
    source.write_text(SMALL.replace("1.5,-2e-3", "1.5,oops"))
    with pytest.raises(InputError) as caught:
        binary_copy(source, tmp_path / "binary.fbx")
    one_sentence(caught.value, "Vertices holds 'oops' among its numbers")
    assert not (tmp_path / "binary.fbx").exists()


def test_braces_thousands_deep_are_one_sentence(tmp_path):
    path = tmp_path / "deep.fbx"
    path.write_text("A: {" * 5000 + "}" * 5000)
    with pytest.raises(InputError) as caught:
        read_text_fbx(path)
    one_sentence(caught.value, "nest more than")


@pytest.mark.skipif(not CORPUS.is_file(), reason="the shared corpus is not on this machine")
def test_the_corpus_text_fbx_still_reads():
    version, nodes = read_text_fbx(CORPUS)
    assert version >= 7000 and any(name == "Objects" for name, _, _ in nodes)


PIECES = ["{", "}", ",", "*3 {a: 1,2,3}", "*2 {a: x,1}", '"S::n"', "1e999", "-", "nan", "P:", "C:", ";", "\n",
          "A:", "99999999999999999999", '"int"', '"KTime"', "\x00", "*9999999999999999999999 {a: }"]
FUZZ = settings(derandomize=True, max_examples=250, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@FUZZ
@given(st.data())
def test_fuzz_mutated_text_gives_a_tree_or_one_sentence(tmp_path, data):
    text = SMALL
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text)))
        cut = data.draw(st.integers(0, 12))
        text = text[:at] + data.draw(st.sampled_from(PIECES) | st.text(max_size=6)) + text[at + cut:]
    path = tmp_path / "fuzz.fbx"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        version, nodes = read_text_fbx(path)
        assert version >= 7000 and isinstance(nodes, list)
    except InputError as error:
        assert "\n" not in str(error) and str(path) in str(error)


@FUZZ
@given(st.binary(max_size=200))
def test_fuzz_random_bytes_give_a_tree_or_one_sentence(tmp_path, raw):
    path = tmp_path / "fuzz.fbx"
    path.write_bytes(b"; FBX 7.3.0 project file\nFBXHeaderExtension: {\nFBXVersion: 7300\n}\n" + raw)
    try:
        read_text_fbx(path)
    except InputError as error:
        assert "\n" not in str(error)
