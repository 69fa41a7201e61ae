"""The convert stage, the command line and the demo, on the bundled example and on small synthetic assets."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from scenefit.core.data.asset_io import load_asset_folder, save_asset_folder
from scenefit.core.stages.convert import ConvertConfig, choose_resolution, convert_asset
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import read_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.texture.bake import load_neural_texture
from scenefit.core.texture.fit_direct import encode_for_metric
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.data.mesh import normalize_to_unit_sphere

from conftest import scenefit_here


def smooth_maps(size: int = 64) -> PBRMaps:
    yy, xx = np.mgrid[0:size, 0:size] / size
    base = np.stack([0.5 + 0.4 * np.sin(4 * np.pi * xx), 0.5 + 0.4 * np.cos(2 * np.pi * yy), 0.3 + 0 * xx], -1)
    return PBRMaps(base.astype(np.float32), (0.3 + 0.5 * xx).astype(np.float32), 0.0)


def scenefit(*args: str, cwd: Path | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory, example_asset):
    """`scenefit demo --preset draft`, with the example asset the session already made."""
    out = tmp_path_factory.mktemp("demo")
    shutil.copytree(example_asset, out / "input" / "asset")
    # Every stage runs (about 2 minutes on a quiet 2-core machine); room for a machine shared with others.
    proc = scenefit("demo", "--out", str(out), "--preset", "draft", timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads((out / "report.json").read_text()), proc.stdout


def test_demo_runs_the_pipeline_and_writes_the_sheet(demo_run):
    out, report, said = demo_run
    assert report["inputs"]["asset"] == "reused"
    assert report["convert"]["psnr_covered_texels_db"] >= 30.0
    assert report["environment"]["mitsuba_variant"] in ("llvm_ad_rgb", "cuda_ad_rgb")
    # Lit by the HDR map estimated from the photo; without a critic the prior sets the scales, and says so.
    assert report["lighting"]["stage"] == "light" and report["lighting"]["decisions"]["critic"]["used"] is False
    assert (out / "light" / "light.exr").is_file() and (out / "input" / "photo.png").is_file()
    # A skipped stage is said where every run says it: report.json's stage_status, and the terminal.
    adapt = report["stage_status"]["adapt"]
    assert adapt["status"] == "skipped" and adapt["why"].startswith("no weights: ") and "not on this machine" in adapt["why"]
    assert "adapt skipped: no weights" in said.splitlines()[0] and "scenefit models download" in said
    for name in ("base_color.png", "roughness.png"):
        assert (out / "convert" / "maps" / name).is_file()
    photo = read_image(out / "input" / "photo.png")
    composite = read_image(out / "compose" / "composite.png")
    assert composite.shape == photo.shape and 0 < report["compose"]["changed_pixels"] < photo.shape[0] * photo.shape[1]
    sheet = read_image(out / "sheet.png")
    assert sheet.shape[1] == 3 * photo.shape[1] and sheet.shape[0] > 2 * photo.shape[0]   # a row for the prior
    # The test prior's edit ("make it blue", its known answer) turns the asset bluer where it shows.
    prior = report["test_prior_adapt"]
    assert prior["status"] == "ran" and prior["instruction"] == "make it blue"
    adapted = read_image(out / prior["composite"] if not Path(prior["composite"]).is_absolute() else
                         Path(prior["composite"]))[..., :3]
    shows = np.abs(adapted - composite[..., :3]).sum(axis=-1) > 0.03
    blueness = lambda image: float((image[..., 2] - image[..., 0])[shows].mean())   # noqa: E731
    assert shows.sum() > 100 and blueness(adapted) > blueness(composite[..., :3]) + 0.05, \
        (int(shows.sum()), blueness(adapted), blueness(composite[..., :3]))
    bake = report["stage_status"]["bake"]
    assert bake["status"] == "skipped" and "asset folder" in bake["why"]


def test_baked_maps_read_back_match_the_network_within_one_level(demo_run, example_asset):
    out, _, _ = demo_run
    texture = load_neural_texture(out / "convert" / "maps" / "texture.pt")
    mesh, _ = load_asset_folder(example_asset)
    normalized, _ = normalize_to_unit_sphere(mesh)
    raster = rasterize_uv(normalized, texture.config.resolution)
    with torch.no_grad():
        stack = texture.texture(raster.position, raster.border, raster.fill_index)
    expected = encode_for_metric(stack).numpy()       # sRGB base colour, linear roughness/metallic
    base = read_image(out / "convert" / "maps" / "base_color.png")[..., :3]
    rough = read_image(out / "convert" / "maps" / "roughness.png")[..., 0]
    covered = raster.border
    assert np.abs(base[covered] - expected[covered][:, :3]).max() <= 1 / 255 + 1e-6
    assert np.abs(rough[covered] - expected[covered][:, 3]).max() <= 1 / 255 + 1e-6


def test_direct_and_inverse_fits_both_learn_the_maps():
    maps = smooth_maps()
    direct = convert_asset(uv_sphere(), maps, stage_config("convert", "draft", init_type="fit", iterations=60))
    inverse = convert_asset(uv_sphere(), maps, stage_config("convert", "draft", init_type="fit", method_type="inverse", iterations=40,
                                                                render_size=96, spp=4))
    untrained = convert_asset(uv_sphere(), maps, stage_config("convert", "draft", init_type="fit", iterations=1, lr_start=1e-9,
                                                                  lr_end=1e-9))
    assert direct.psnr > 30.0
    # Inverse rendering learns far more slowly per iteration (bench: conversion_psnr.png), but it learns.
    assert inverse.psnr > untrained.psnr + 1.5
    assert np.mean(inverse.history[-5:]) < 0.5 * np.mean(inverse.history[:5])


def test_conversion_leaves_the_users_data_untouched():
    mesh, maps = uv_sphere(segments=16, rings=8), smooth_maps(32)
    before = (mesh.positions.copy(), maps.base_color.copy(), maps.roughness.copy())
    convert_asset(mesh, maps, stage_config("convert", "draft", iterations=2))
    assert np.array_equal(before[0], mesh.positions)
    assert np.array_equal(before[1], maps.base_color) and np.array_equal(before[2], maps.roughness)


def test_resolution_follows_the_asset_and_the_preset_cap():
    small, big = smooth_maps(64), PBRMaps(np.zeros((2048, 2048, 3), np.float32))
    assert choose_resolution(small, ConvertConfig())[0] == 64
    assert choose_resolution(big, stage_config("convert", "draft"))[0] == 512
    assert choose_resolution(big, ConvertConfig(resolution=256))[0] == 256
    with pytest.raises(InputError):
        ConvertConfig(method_type="magic")


def test_cli_convert_render_export_on_an_asset_folder(tmp_path):
    asset = save_asset_folder(uv_sphere(segments=16, rings=8), smooth_maps(32), tmp_path / "asset")
    proc = scenefit_here("convert", str(asset), "--out", str(tmp_path / "c"), "--preset", "draft", "--iterations", "20",
                    "--quiet")
    assert proc.returncode == 0, proc.stderr
    report = json.loads((tmp_path / "c" / "report.json").read_text())
    assert report["decisions"]["method"] == "direct" and report["iterations"] == 20
    assert (tmp_path / "c" / "maps" / "texture.pt").is_file()

    proc = scenefit_here("render", str(asset), "--texture", str(tmp_path / "c" / "maps" / "texture.pt"), "--out",
                    str(tmp_path / "r"), "--views", "2", "--size", "32", "--spp", "4", "--quiet")
    assert proc.returncode == 0, proc.stderr
    views = sorted((tmp_path / "r").glob("view_*.png"))
    assert len(views) == 2 and read_image(views[0]).shape == (32, 32, 3)

    proc = scenefit_here("export", str(asset), "--out", str(tmp_path / "x"), "--size", "32", "--spp", "4")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "x" / "scene.xml").is_file() and (tmp_path / "x" / "mesh.ply").is_file()


def test_cli_bad_input_is_a_sentence_not_a_traceback(tmp_path):
    # In this process: an asset path is checked before any command loads Blender (scenefit_here fails
    # the test if bpy is imported), so a mistyped path is refused at once, not after seconds of loading.
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "empty.glb").write_bytes(b"")
    (tmp_path / "fox.obj").write_text("mtllib fox.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")   # its .mtl left behind
    for command in ("convert", "run", "bake", "render", "export"):
        for asset, words in (("missing.glb", "does not exist"), ("notes.txt", "cannot read '.txt'"),
                             ("empty.glb", "is empty"), ("fox.obj", "names the material library 'fox.mtl', "
                                                                    "which is not in")):
            extra = {"run": ["--photo", tmp_path / "p.png", "--at", "0.5,0.6"], "bake": ["--texture", "t.pt"]}
            proc = scenefit_here(command, tmp_path / asset, "--out", tmp_path / "o.glb", *extra.get(command, []))
            assert proc.returncode == 2 and words in proc.stderr, (command, asset, proc.stderr)
            assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.glb", "fox.obj", "notes.txt"]
