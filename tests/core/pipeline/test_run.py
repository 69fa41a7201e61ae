"""`scenefit run`: every stage in one go, one report, and a second run reuses what is done."""
from __future__ import annotations

import json
from dataclasses import replace
import shutil
import subprocess
import sys

import numpy as np
import pytest

from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere

from asset_builder import write_obj
from conftest import scenefit_here


def scenefit(*args: str) -> subprocess.CompletedProcess:
    """A process of its own: the asset file is read (and the game asset baked) by bpy."""
    return subprocess.run([sys.executable, "-m", "scenefit.cli", *args], capture_output=True, text=True, timeout=900)


def test_run_composes_and_a_second_run_reuses_every_stage(tmp_path):
    yy, xx = np.mgrid[0:16, 0:16] / 16
    # Glossy (roughness 0.15 asks for a 256-row map): the draft preset caps the map at its 64 rows.
    maps = PBRMaps(np.stack([0.3 + 0.5 * xx, 0.4 + 0 * xx, 0.7 - 0.4 * yy], -1).astype(np.float32), 0.15, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 16, 8), maps, tmp_path / "asset")
    rng = np.random.default_rng(0)
    photo = np.clip(np.linspace(0.9, 0.3, 72)[:, None, None] + rng.normal(0, 0.05, (72, 96, 3)), 0, 1)
    photo_path = write_image(tmp_path / "photo.png", photo)
    out = tmp_path / "run"
    args = (str(asset), "--photo", str(photo_path), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
            "--guidance", "none", "--spp", "4", "--quiet")
    first = scenefit_here("run", *args)
    assert first.returncode == 0, first.stderr
    report = json.loads((out / "report.json").read_text())
    status = {name: stage["status"] for name, stage in report["stages"].items()}
    assert status == {"convert": "ran", "light": "ran", "adapt": "skipped", "compose": "ran", "bake": "skipped"}
    assert "asset folder" in report["stages"]["bake"]["why"]
    assert read_image(out / "compose" / "composite.png").shape == (72, 96, 3)
    assert report["stages"]["compose"]["report"]["spp"] == 4
    light = report["stages"]["light"]["report"]
    assert light["map_size"] == [128, 64] and "capped at the draft preset" in light["decisions"]["envmap_height"]["why"]

    second = scenefit_here("run", *args[:-1])   # (not --quiet: what the terminal says)
    assert second.returncode == 0, second.stderr
    again = json.loads((out / "report.json").read_text())
    assert again["reused"] == ["convert", "light", "compose"]
    # A skipped stage is said with its reason, on the line and in report.json's stage_status (demo's and batch's too).
    line = second.stdout.splitlines()[0]
    assert "adapt skipped: guidance none" in line and "bake skipped: " in line and "compose reused" in line
    assert again["stage_status"]["adapt"] == {"status": "skipped", "why": "guidance none"}
    assert {name: s["status"] for name, s in again["stage_status"].items()} == \
        {name: s["status"] for name, s in again["stages"].items()}

    # A compose setting changes only the compose stage.
    third = scenefit_here("run", *args[:-3], "--spp", "2", "--quiet")
    assert third.returncode == 0, third.stderr
    last = json.loads((out / "report.json").read_text())
    assert last["reused"] == ["convert", "light"] and last["stages"]["compose"]["status"] == "ran"

    # --replace starts over (it took up the earlier run's stages all the same)
    fourth = scenefit_here("run", *args, "--replace")
    assert fourth.returncode == 0, fourth.stderr
    assert json.loads((out / "report.json").read_text())["reused"] == []


def test_run_on_an_asset_file_bakes_a_game_asset_and_reuses_it(tmp_path):
    yy, xx = np.mgrid[0:32, 0:32] / 32
    obj = write_obj(tmp_path / "obj", uv_sphere(0.5, 16, 8),
                     np.stack([0.2 + 0.6 * xx, 0.5 + 0 * xx, 0.8 - 0.5 * yy], -1).astype(np.float32))
    photo_path = write_image(tmp_path / "photo.png", np.clip(np.linspace(0.9, 0.3, 48)[:, None, None]
                                                               + np.zeros((48, 64, 3)), 0, 1))
    out = tmp_path / "run"
    args = (obj, "--photo", str(photo_path), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
            "--guidance", "none", "--spp", "2", "--quiet")
    first = scenefit("run", *args)
    assert first.returncode == 0, first.stderr
    report = json.loads((out / "report.json").read_text())
    bake = report["stages"]["bake"]
    assert bake["status"] == "ran", bake
    glb = out / "bake" / "ball.glb"
    assert glb.read_bytes()[:4] == b"glTF"            # the binary glTF magic
    assert [m["name"] for m in bake["report"]["materials"]] == ["Ball"]

    assert report["asset_read"]["source"] == "asset"

    second = scenefit("run", *args)
    assert second.returncode == 0, second.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["convert", "light", "compose", "bake"]
    assert report["asset_read"]["source"] == "copy"   # the same files: Blender's read kept from the first run
    # A texture of the asset changed: read again, and the stages that depend on it run again.
    write_image(tmp_path / "obj" / "albedo.png", np.full((32, 32, 3), 0.5, np.float32))
    third = scenefit("run", *args)
    assert third.returncode == 0, third.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["asset_read"]["source"] == "asset" and "convert" not in report["reused"]


def test_an_interrupted_run_keeps_its_finished_stages_and_says_so(tmp_path, monkeypatch, capsys):
    import scenefit.core.pipeline.steps.compose as compose_step
    from scenefit.cli import main
    from scenefit.core.base.output_folder import staging_path

    maps = PBRMaps(np.full((64, 64, 3), 0.5, np.float32), 0.5, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 12, 6), maps, tmp_path / "asset")
    photo_path = write_image(tmp_path / "photo.png", np.full((48, 64, 3), 0.5))
    out = tmp_path / "run"
    args = ["run", str(asset), "--photo", str(photo_path), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
            "--guidance", "none", "--spp", "2", "--quiet"]

    monkeypatch.setattr(compose_step, "compose_to_folder", _interrupted)   # Ctrl-C during the compose stage
    assert main(args) == 130
    message = capsys.readouterr().err
    assert "stages finished so far (convert, camera, light) are kept beside it" in message
    # Nothing is swapped in until the run is whole; the finished stages wait beside the folder.
    staging = staging_path(out)
    assert not out.exists()
    assert (staging / "convert" / "stage.json").is_file() and (staging / "light" / "stage.json").is_file()
    assert not (staging / "compose" / "stage.json").exists()
    monkeypatch.undo()
    assert main(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["convert", "light"]
    # Only what the scene needs: the asset spans 0.3 x 48 = 14 px of the composite, so 32 texels, not its 64.
    decisions = report["stages"]["convert"]["report"]["decisions"]
    assert decisions["resolution"] == 32 and "14 px tall in the composite" in decisions["resolution_reason"]

    # A moved run folder (Blender swaps it into place, a batch worker sends it home) is still reused.
    moved = tmp_path / "moved"
    out.rename(moved)
    assert main([str(moved) if a == str(out) else a for a in args]) == 0
    assert json.loads((moved / "report.json").read_text())["reused"] == ["convert", "light", "compose"]


def _grey_sphere_run(tmp_path) -> tuple:
    """(asset folder, --out, the `scenefit run` arguments) of a grey sphere in a grey photo, at draft."""
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 12, 6), maps, tmp_path / "asset")
    photo_path = write_image(tmp_path / "photo.png", np.full((48, 64, 3), 0.5))
    out = tmp_path / "run"
    return asset, out, ["run", str(asset), "--photo", str(photo_path), "--at", "0.5,0.8", "--out", str(out),
                        "--preset", "draft", "--guidance", "none", "--spp", "2", "--no-bake", "--quiet"]


def _interrupted(*_, **__):
    raise KeyboardInterrupt


def test_a_run_stopped_before_any_stage_finished_says_nothing_was_kept(tmp_path, monkeypatch, capsys):
    import scenefit.core.pipeline.steps.convert as convert_step
    from scenefit.cli import main
    from scenefit.core.base.output_folder import staging_path

    _, out, args = _grey_sphere_run(tmp_path)
    monkeypatch.setattr(convert_step, "convert_and_bake", _interrupted)   # Ctrl-C in the first stage
    assert main(args) == 130
    message = capsys.readouterr().err
    assert "no stage had finished, so nothing of this run was kept" in message and "kept beside" not in message
    assert not out.exists() and not staging_path(out).exists()


@pytest.mark.parametrize("links", [True, False], ids=["hard links", "copies"])
def test_a_stopped_rerun_never_counts_the_earlier_runs_stages_as_kept(tmp_path, monkeypatch, capsys, links):
    """A rerun starts from the earlier run's files (hard-linked, or copied where links fail): stopped before
    a stage of its own finished, it keeps nothing and says so (it named the earlier run's stages as kept),
    and the earlier folder stays whole."""
    import scenefit.core.base.output_folder as output_folder
    import scenefit.core.pipeline.steps.convert as convert_step
    from scenefit.cli import main
    from scenefit.core.base.output_folder import staging_path

    asset, out, args = _grey_sphere_run(tmp_path)
    assert main(args) == 0
    if not links:   # a file system without hard links
        def no_links(*_):
            raise OSError("no hard links here")
        monkeypatch.setattr(output_folder.os, "link", no_links)
    before = (out / "report.json").read_bytes()
    save_asset_folder(uv_sphere(0.5, 12, 6), PBRMaps(np.full((16, 16, 3), 0.3, np.float32), 0.5, 0.0), asset)
    monkeypatch.setattr(convert_step, "convert_and_bake", _interrupted)   # the changed asset's convert, stopped
    capsys.readouterr()
    assert main(args) == 130
    message = capsys.readouterr().err
    assert "no stage had finished, so nothing of this run was kept" in message, message
    assert not staging_path(out).exists() and (out / "report.json").read_bytes() == before


def test_a_run_refused_mid_way_says_which_finished_stages_it_kept(tmp_path, monkeypatch, capsys):
    """A refusal once stages have finished (here compose's, after convert and light) names what was kept for
    the next run, and the next run reuses it."""
    import scenefit.core.pipeline.steps.compose as compose_step
    from scenefit.cli import main
    from scenefit.core.base.errors import InputError

    _, out, args = _grey_sphere_run(tmp_path)

    def refused(*_, **__):
        raise InputError("Compose refused this.")

    monkeypatch.setattr(compose_step, "compose_to_folder", refused)
    assert main(args) == 2
    message = capsys.readouterr().err.strip()
    assert message == (f"scenefit: error: Compose refused this. The finished stages (convert, camera, light) are kept beside "
                       f"'{out}' in '.run.partial'; the next run into it reuses each whose inputs and settings are "
                       "the same.")
    assert not out.exists()
    monkeypatch.undo()
    assert main(args) == 0
    assert json.loads((out / "report.json").read_text())["reused"] == ["convert", "light"]
    # A refusal before any stage ran keeps nothing and says nothing of it.
    assert main([*args, "--at", "0.5,1.5"]) == 2
    assert "kept beside" not in capsys.readouterr().err


def test_what_only_the_camera_shows_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    """A shadow tip in the sky and an asset too flat to stand in view were found by the light stage and
    compose, after convert had run (the corpus's palm tree on its ground plane: convert and light first)."""
    import scenefit.core.pipeline.steps.convert as convert_step
    from scenefit.cli import main

    monkeypatch.setattr(convert_step, "convert_and_bake", _interrupted)   # any work would stop the test with 130
    _, out, args = _grey_sphere_run(tmp_path)
    assert main([*args, "--sun-from-shadow", "0.5,0.9", "0.5,0.8", "0.3,0.02"]) == 2   # the tip in the sky
    said = capsys.readouterr().err.strip()
    assert len(said.splitlines()) == 1 and "above the horizon" in said and "kept" not in said
    sphere = uv_sphere(0.5, 12, 6)
    plane = replace(sphere, positions=sphere.positions * np.float32([1.0, 1.0, 0.01]))   # 100 times as wide as tall
    save_asset_folder(plane, PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0), tmp_path / "flat")
    assert main([str(tmp_path / "flat") if a == str(tmp_path / "asset") else a for a in args]) == 2
    said = capsys.readouterr().err.strip()
    assert "times as wide as it is tall (a ground plane?)" in said and len(said.splitlines()) == 1
    assert not out.exists() and not (tmp_path / ".run.partial").exists()


def test_a_run_that_reuses_every_stage_does_not_estimate_the_camera_again(tmp_path, monkeypatch):
    """The check runs before the first stage that works; a rerun that reuses them all passed it before
    (estimating the camera again cost 1-3 s per rerun)."""
    import scenefit.core.pipeline.run as run_module
    from scenefit.cli import main

    _, out, args = _grey_sphere_run(tmp_path)
    assert main(args) == 0

    def estimated(*_, **__):
        raise AssertionError("the camera was estimated again")

    monkeypatch.setattr(run_module, "photo_camera_estimate", estimated)
    assert main(args) == 0
    assert json.loads((out / "report.json").read_text())["reused"] == ["convert", "light", "compose"]


def _sphere_and_photo(tmp_path):
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    photo = write_image(tmp_path / "photo.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                                (48, 64, 3)).astype(np.float32))
    return uv_sphere(0.5, 12, 6), maps, photo


def _bake_running(script: str, started: list):
    """A GameBake whose process is `script` (python), so the test sees when it starts and whether it lives."""
    from scenefit.core.stages.bake.process import BakeProcess

    def bake(texture, folder, cancel=None):
        folder.mkdir(parents=True, exist_ok=True)
        process = BakeProcess([sys.executable, "-c", script.format(folder=str(folder))], "asset.glb",
                              folder / "asset.glb", folder / "bake.json", cancel)
        started.append((process, texture))
        return process

    return bake


def test_the_game_bake_runs_beside_light_and_compose_and_a_cancel_stops_it(tmp_path):
    """Without adaptation the bake starts once convert is done and runs while light and compose do; a
    cancel during compose stops it: no bake process outlives the run."""
    import threading

    import pytest

    from scenefit.core.base.errors import Cancelled
    from scenefit.core.pipeline.run import RunConfig, run_pipeline

    mesh, maps, photo = _sphere_and_photo(tmp_path)
    started, cancel, seen = [], threading.Event(), []

    def progress(event) -> None:
        seen.append((event.message, bool(started)))
        if event.message == "compose: running":
            cancel.set()

    bake = _bake_running("import time; time.sleep(120)", started)
    with pytest.raises(Cancelled):
        run_pipeline(mesh, maps, photo, (0.5, 0.8), tmp_path / "run", RunConfig(preset="draft", guidance_type="none"),
                     progress=progress, cancel=cancel, bake=bake)
    assert ("light: running", True) in seen      # the bake was already running when light began
    process, texture = started[0]
    assert texture.name == "texture.pt" and texture.is_file()
    assert process.process.poll() is not None     # stopped, not left running for two minutes


def test_a_failed_game_bake_fails_the_run_in_one_sentence(tmp_path):
    from scenefit.core.base.errors import SceneFitError
    from scenefit.core.pipeline.run import RunConfig, run_pipeline

    import pytest

    mesh, maps, photo = _sphere_and_photo(tmp_path)
    script = "import sys; print('scenefit: error: The asset has no mesh.', file=sys.stderr); sys.exit(2)"
    with pytest.raises(SceneFitError, match="game bake of 'asset.glb' failed: The asset has no mesh.$"):
        run_pipeline(mesh, maps, photo, (0.5, 0.8), tmp_path / "run", RunConfig(preset="draft", guidance_type="none"),
                     bake=_bake_running(script, []))
    # the stages that finished are recorded; the bake is not
    assert (tmp_path / "run" / "compose" / "stage.json").is_file()
    assert not (tmp_path / "run" / "bake" / "stage.json").exists()


def test_run_gives_the_light_stage_the_scene_type_and_the_models_cache(tmp_path, capsys):
    """`scenefit run` once had no --scene (Run All dropped the panel's Scene type) and looked for the depth
    model outside --cache-dir / --offline, which `scenefit light` follows."""
    from scenefit.cli import main

    maps = PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.6, 0.0)
    asset = save_asset_folder(uv_sphere(0.5, 12, 6), maps, tmp_path / "asset")
    photo = write_image(tmp_path / "photo.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                                (48, 64, 3)).astype(np.float32))
    cache = tmp_path / "hub"
    cache.mkdir()
    for scene in ("indoor", "outdoor"):
        out = tmp_path / scene
        assert main(["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(out), "--preset",
                     "draft", "--guidance", "none", "--spp", "2", "--no-bake", "--quiet", "--scene", scene,
                     "--cache-dir", str(cache), "--offline"]) == 0
        light = json.loads((out / "report.json").read_text())["stages"]["light"]["report"]
        assert light["decisions"]["scene_type"]["chosen"] == scene
        depth = light["config"]["depth"]
        assert depth["cache_dir"] == str(cache) and depth["local_files_only"] is True
    # Again into the same folder, every stage reused: the summary says the light's direction was guessed.
    capsys.readouterr()
    assert main(["run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(tmp_path / "outdoor"),
                 "--preset", "draft", "--guidance", "none", "--spp", "2", "--no-bake", "--scene", "outdoor",
                 "--cache-dir", str(cache), "--offline"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "light reused" in line and "light direction guessed (--sun AZ,EL or --sun-from-shadow sets it)" in line


def test_a_new_run_folder_reuses_an_earlier_runs_stages_by_copy_and_leaves_that_run_as_it_was(tmp_path):
    """Blender's Run All makes a new folder per run: run_pipeline(reuse_from=the last run) copies in each of
    its stages whose key this run shares (it once redid every stage), and the earlier run is not touched."""
    from scenefit.core.pipeline.run import RunConfig, run_pipeline

    yy, xx = np.mgrid[0:16, 0:16] / 16
    maps = PBRMaps(np.stack([0.3 + 0.5 * xx, 0.4 + 0 * xx, 0.7 - 0.4 * yy], -1).astype(np.float32), 0.5, 0.0)
    mesh = uv_sphere(0.5, 16, 8)
    photo = write_image(tmp_path / "photo.png", np.clip(np.linspace(0.9, 0.3, 48)[:, None, None]
                                                        + np.zeros((48, 64, 3)), 0, 1))
    config = RunConfig(preset="draft", guidance_type="none", compose_spp=2)
    first = run_pipeline(mesh, maps, photo, (0.5, 0.8), tmp_path / "run-1", config)
    assert first.reused == ()
    files = lambda folder: {p: p.stat().st_mtime_ns for p in sorted(folder.rglob("*")) if p.is_file()}
    before = files(tmp_path / "run-1")

    second = run_pipeline(mesh, maps, photo, (0.5, 0.8), tmp_path / "run-2", config, reuse_from=tmp_path / "run-1")
    assert second.reused == ("convert", "light", "compose")
    for name in ("convert", "light", "compose"):
        assert (tmp_path / "run-2" / name / "stage.json").is_file()
        assert second.stages[name].source == str((tmp_path / "run-1").resolve())
    assert np.array_equal(read_image(tmp_path / "run-2" / "compose" / "composite.png"),
                          read_image(tmp_path / "run-1" / "compose" / "composite.png"))
    # copies, not links: Blender opens these images and may save an edit into one in place
    copied = [p for p in (tmp_path / "run-2").rglob("*") if p.is_file() and p.parent.name != "run-2"]
    assert copied and not any(p.samefile(tmp_path / "run-1" / p.relative_to(tmp_path / "run-2")) for p in copied)
    written = json.loads((tmp_path / "run-2" / "report.json").read_text())
    for stage in written["stages"].values():   # its outputs are its own files (copies of the earlier run's)
        assert "run-1" not in json.dumps(stage.get("report", {}).get("outputs", {}))

    # Another placement: the light and what follows it run again; the texture is still the earlier one's
    third = run_pipeline(mesh, maps, photo, (0.3, 0.8), tmp_path / "run-3", config, reuse_from=tmp_path / "run-2")
    assert third.reused == ("convert",)
    assert [third.stages[n].status for n in ("light", "compose")] == ["ran", "ran"]
    assert files(tmp_path / "run-1") == before   # nothing of the first run was changed


@pytest.mark.parametrize("lead_out", ["parent", "absolute", "link", "folder link"])
def test_a_stage_whose_outputs_lead_out_of_its_folder_is_run_again(tmp_path, capsys, lead_out):
    """stage.json is data from wherever the run folder came from: an output naming a file outside the
    stage's folder ('..', an absolute path, a link out) is not taken as the finished stage's, which runs
    again and writes its own."""
    from scenefit.cli import main

    _, out, args = _grey_sphere_run(tmp_path)
    assert main(args) == 0
    outside = tmp_path / "elsewhere.exr"
    shutil.copy(out / "light" / "light.exr", outside)
    before = outside.read_bytes()
    record = out / "light" / "stage.json"
    saved = json.loads(record.read_text())
    if lead_out == "link":
        (out / "light" / "light.exr").unlink()
        (out / "light" / "light.exr").symlink_to(outside)
    elif lead_out == "folder link":   # the whole stage folder a link to a copy elsewhere
        shutil.copytree(out / "light", tmp_path / "elsewhere")
        shutil.rmtree(out / "light")
        (out / "light").symlink_to(tmp_path / "elsewhere")
        outside = tmp_path / "elsewhere" / "light.exr"
        record = tmp_path / "elsewhere" / "stage.json"
        before = outside.read_bytes()
    else:
        saved["report"]["outputs"]["hdr_exr"] = "../../elsewhere.exr" if lead_out == "parent" else str(outside)
        record.write_text(json.dumps(saved))
    assert main(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["convert"] and report["stages"]["light"]["status"] == "ran"
    light = out / "light" / "light.exr"
    assert light.is_file() and not light.is_symlink() and not (out / "light").is_symlink()
    assert json.loads((out / "light" / "stage.json").read_text())["report"]["outputs"]["hdr_exr"] == "light.exr"
    assert outside.read_bytes() == before   # the file outside is neither read as the stage's nor written
    assert record.is_file()   # nor the stage.json outside removed
