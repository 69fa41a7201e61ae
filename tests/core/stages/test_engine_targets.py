"""What a bake for each engine may write (core.stages.bake.engine_targets, gltf_output.output_like_input)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.glb import write_glb
from scenefit.core.stages.bake.engine_targets import TARGETS, keep_only_extensions
from scenefit.core.stages.bake.gltf_output import output_like_input

from conftest import ROOT

CORPUS = Path(os.environ.get("SCENEFIT_CORPUS", ROOT.parent / "shared" / "corpus")) / "assets"


def _document() -> dict:
    return {"asset": {"version": "2.0"},
            "extensionsUsed": ["KHR_materials_sheen", "KHR_texture_transform", "KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point"}]}},
            "nodes": [{"extensions": {"KHR_lights_punctual": {"light": 0}}}, {"name": "plain"}],
            "materials": [{"extensions": {"KHR_materials_sheen": {"sheenRoughnessFactor": 0.5}},
                           "pbrMetallicRoughness": {"baseColorTexture": {
                               "index": 0, "extensions": {"KHR_texture_transform": {"scale": [2, 2]}}}}}]}


def test_extensions_an_engine_does_not_read_leave_every_object_and_the_used_list():
    document = _document()
    removed = keep_only_extensions(document, frozenset({"KHR_texture_transform"}))
    assert removed == ["KHR_lights_punctual", "KHR_materials_sheen"]
    assert document["extensionsUsed"] == ["KHR_texture_transform"]
    assert "extensions" not in document and "extensions" not in document["nodes"][0]
    assert "extensions" not in document["materials"][0]
    texture = document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    assert texture["extensions"] == {"KHR_texture_transform": {"scale": [2, 2]}}   # what it reads stays
    everything = _document()
    assert keep_only_extensions(everything, TARGETS["web"].extensions) == [] and everything == _document()


def test_an_extension_the_file_requires_is_never_taken_out():
    document = dict(_document(), extensionsRequired=["KHR_materials_sheen"])
    with pytest.raises(InputError, match="requires KHR_materials_sheen"):
        keep_only_extensions(document, frozenset())


@pytest.mark.parametrize("asset, as_imported", [("khronos_CesiumMilkTruck_draco/CesiumMilkTruck.gltf", "draco"),
                                                ("nasa_ingenuity_meshopt/Ingenuity.glb", "meshopt")])
def test_each_engine_gets_a_compression_it_reads(asset, as_imported):
    path = CORPUS / asset
    if not path.is_file():
        pytest.skip("the development corpus is not on this machine")
    assert output_like_input(path).compress == as_imported
    for engine in ("godot", "unity", "unreal"):
        output = output_like_input(path, target=engine)
        assert output.compress == "none" and output.target == engine
        assert "KHR_draco_mesh_compression" not in output.extensions
        assert "EXT_meshopt_compression" not in output.extensions
    assert output_like_input(path, target="web").compress == "meshopt"
    assert output_like_input(path, target="web", file_format="gltf").compress == "draco"   # meshopt: .glb only
    assert "EXT_meshopt_compression" in output_like_input(path, target="web").extensions


def test_each_engine_gets_a_texture_format_it_reads_and_says_what_changed(tmp_path):
    path = tmp_path / "in.glb"
    write_glb(path, {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_texture_basisu"],
                     "images": [{"mimeType": "image/ktx2"}, {"mimeType": "image/ktx2"}]}, b"")
    assert output_like_input(path, target="web").textures == "ktx2"
    for engine in ("godot", "unity", "unreal"):
        output = output_like_input(path, target=engine)
        assert output.textures == "png" and "KHR_texture_basisu" not in output.extensions
        assert any("ktx2" in why for why in output.unlike_input)
    write_glb(path, {"asset": {"version": "2.0"}, "images": [{"mimeType": "image/webp"}]}, b"")
    assert output_like_input(path, target="godot").textures == "webp"
    assert "EXT_texture_webp" in output_like_input(path, target="godot").extensions
    assert output_like_input(path, target="unity").textures == "png"
    assert output_like_input(path).extensions is None   # as imported: every extension as the input has it


def test_a_setting_an_engine_does_not_read_is_one_sentence(tmp_path):
    with pytest.raises(InputError, match="Godot 4 does not read draco compression"):
        output_like_input(None, compress="draco", target="godot")
    with pytest.raises(InputError, match="Unity .glTFast. does not read webp textures"):
        output_like_input(None, textures="webp", target="unity")
    with pytest.raises(InputError, match="--target must be one of"):
        output_like_input(None, target="playstation")
    assert output_like_input(None, compress="draco", target="web").compress == "draco"
