"""`scenefit bake --target`: a corpus asset (ToyCar: clearcoat, sheen, transmission, texture transforms)
baked for each engine validates clean and carries only what that engine's importer reads."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from scenefit.core.data.glb import gltf_json
from scenefit.core.stages.bake.engine_targets import COMPRESSION_EXTENSION, TARGETS
from scenefit.core.stages.bake.gltf_output import MIME_OF_FORMAT

from conftest import ROOT, scenefit_process, scenefit_side_by_side

CORPUS = Path(os.environ.get("SCENEFIT_CORPUS", ROOT.parent / "shared" / "corpus")) / "assets"
TOY_CAR = CORPUS / "khronos_ToyCar" / "ToyCar.gltf"
ENGINES = ("web", "godot", "unity", "unreal")


@pytest.fixture(scope="module")
def toy_car_bakes(tmp_path_factory) -> dict[str, Path]:
    if not TOY_CAR.is_file():
        pytest.skip(f"the development corpus is not at {CORPUS.parent} (set SCENEFIT_CORPUS)")
    folder = tmp_path_factory.mktemp("targets")
    # What each engine's file holds does not depend on how well the texture fits: a short fit.
    proc = scenefit_process("convert", TOY_CAR, "--out", folder / "convert", "--preset", "draft",
                            "--resolution", "64", "--iterations", "20", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    texture = folder / "convert" / "maps" / "texture.pt"
    outs = {engine: folder / f"car_{engine}.glb" for engine in ENGINES}
    results = scenefit_side_by_side(*[("bake", TOY_CAR, "--texture", texture, "--out", out, "--target", engine,
                                       "--max-texture", "256", "--quiet") for engine, out in outs.items()])
    for (code, err), engine in zip(results, ENGINES):
        assert code == 0, f"{engine}: {err[-2000:]}"
    return outs


def test_each_engines_bake_validates_and_uses_only_what_that_engine_reads(toy_car_bakes, validator):
    source = set(gltf_json(TOY_CAR)["extensionsUsed"])
    assert {"KHR_materials_sheen", "KHR_materials_clearcoat", "KHR_materials_transmission"} <= source
    seen = {}
    for engine, path in toy_car_bakes.items():
        target = TARGETS[engine]
        report = validator(str(path))
        assert report["issues"]["numErrors"] == 0, (engine, report["issues"]["messages"][:5])
        document = gltf_json(path)
        used = set(document.get("extensionsUsed", []))
        assert used <= target.extensions, (engine, used - target.extensions)
        assert set(document.get("extensionsRequired", [])) <= used
        mimes = {image.get("mimeType") for image in document.get("images", [])}
        assert mimes <= {MIME_OF_FORMAT[f] for f in target.textures}, (engine, mimes)
        compressions = {c for c, name in COMPRESSION_EXTENSION.items() if name in used}
        assert compressions <= set(target.compressions) and len(compressions) <= 1, (engine, compressions)
        seen[engine] = used
    # What each engine reads of the car's materials stays; what it does not goes.
    assert "EXT_meshopt_compression" in seen["web"] and source <= seen["web"]
    assert seen["godot"] & source == {"KHR_texture_transform"}
    assert "KHR_materials_sheen" not in seen["unity"] and "KHR_materials_clearcoat" in seen["unity"]
    assert source <= seen["unreal"]


@pytest.mark.parametrize("layout", ["glb", "gltf"])
def test_a_report_naming_the_bakes_own_output_is_refused_before_work(tmp_path, layout):
    """`--report x.glb --out x.glb` left the report in the GLB, `--report y.bin` with `--format gltf` replaced the
    buffer, both exit 0; and `--report missing/r.json` exited 2 only after the GLB was written."""
    asset = tmp_path / "a.gltf"
    asset.write_text('{"asset": {"version": "2.0"}}')
    texture = tmp_path / "texture.pt"
    texture.write_bytes(b"not read")
    out = tmp_path / f"baked.{layout}"
    reports = [out] + ([out.with_suffix(".bin")] if layout == "gltf" else []) + [tmp_path / "missing" / "r.json"]
    for report in reports:
        proc = scenefit_process("bake", asset, "--texture", texture, "--out", out, "--report", report, "--quiet")
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr[-2000:]
        assert str(report) in proc.stderr and ("the bake itself writes" in proc.stderr or
                                              "does not exist" in proc.stderr), proc.stderr
        assert not out.exists() and not report.exists()


TRUCK = CORPUS / "khronos_CesiumMilkTruck_draco" / "CesiumMilkTruck.gltf"
INGENUITY = CORPUS / "nasa_ingenuity_meshopt" / "Ingenuity.glb"
# (input, the targets it is baked for): every target sees a Draco, a meshopt and a WebP input; WebP and AVIF
# (required extensions, written by glTF-Transform) are formats the Unity and Unreal importers do not read.
INPUTS = {"draco": ("unity", "godot"), "meshopt": ("unreal", "web"), "webp": ENGINES, "avif": ("unity",)}


def test_every_target_from_draco_meshopt_webp_and_avif_inputs(tmp_path, validator, gltf_transform):
    """An engine's bake of any valid input: a geometry compression or texture format the engine does not read
    becomes one it does (the input's WebP images re-encoded as PNG after Blender's exporter, its AVIF ones
    before Blender's importer), and the file validates with 0 errors."""
    if not (TRUCK.is_file() and INGENUITY.is_file()):
        pytest.skip(f"the development corpus is not at {CORPUS.parent} (set SCENEFIT_CORPUS)")
    files = {"draco": TRUCK, "meshopt": INGENUITY}
    for fmt in ("webp", "avif"):
        files[fmt] = tmp_path / f"truck_{fmt}.glb"
        gltf_transform(fmt, TRUCK, files[fmt])
        assert gltf_json(files[fmt])["extensionsRequired"] == [f"EXT_texture_{fmt}"]
    # The file's validity does not depend on the texture's fit (nor on whose fit it is): one short fit for all.
    proc = scenefit_process("convert", TRUCK, "--out", tmp_path / "convert", "--preset", "draft", "--resolution",
                            "32", "--iterations", "10", "--quiet")
    assert proc.returncode == 0, proc.stderr[-2000:]
    texture = tmp_path / "convert" / "maps" / "texture.pt"
    bakes = [(fmt, engine, tmp_path / f"{fmt}_{engine}.glb") for fmt, engines in INPUTS.items() for engine in engines]
    results = scenefit_side_by_side(*[("bake", files[fmt], "--texture", texture, "--out", out, "--target", engine,
                                       "--max-texture", "64", "--quiet") for fmt, engine, out in bakes])
    for (code, err), (fmt, engine, out) in zip(results, bakes):
        assert code == 0, f"{fmt} for {engine}: {err[-2000:]}"
        report = validator(str(out))
        assert report["issues"]["numErrors"] == 0, (fmt, engine, report["issues"]["messages"][:5])
        document, target = gltf_json(out), TARGETS[engine]
        used = set(document.get("extensionsUsed", []))
        assert used <= target.extensions, (fmt, engine, used - target.extensions)
        mimes = {image.get("mimeType") for image in document.get("images", [])}
        assert mimes and mimes <= {MIME_OF_FORMAT[f] for f in target.textures}, (fmt, engine, mimes)
    assert {i.get("mimeType") for i in gltf_json(tmp_path / "webp_godot.glb")["images"]} == {"image/webp"}
