"""Bad input and interruptions: one sentence and exit 2, nothing lost, a run's folder is one unit."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.data.asset_io import load_asset_folder, save_asset_folder
from scenefit.core.base.atomic import TEMP_MARK
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import read_image, write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.base.output_folder import MARKER, _FolderLock, output_folder, staging_path, write_marker


def files(folder: Path) -> list[str]:
    """What a folder holds, without SceneFit's marker."""
    return sorted(p.name for p in folder.iterdir() if p.name != MARKER)
from scenefit.core.base.report import write_report
from scenefit.core.data.primitives import uv_sphere


def small_maps(size: int = 16, metallic=0.0) -> PBRMaps:
    yy, xx = np.mgrid[0:size, 0:size] / size
    base = np.stack([0.2 + 0.6 * xx, 0.3 + 0 * xx, 0.2 + 0.6 * yy], -1).astype(np.float32)
    return PBRMaps(base, (0.3 + 0.5 * xx).astype(np.float32), metallic)


@pytest.fixture
def asset(tmp_path) -> Path:
    return save_asset_folder(uv_sphere(segments=12, rings=6), small_maps(), tmp_path / "asset")


def cli(*args: str) -> int:
    """The command line in this process (argparse's refusals are returned as exit code 2 too)."""
    return main(list(args))


CONVERT_FAST = ("--preset", "draft", "--iterations", "2", "--resolution", "16", "--quiet")


# -- a run's output folder is one unit ---------------------------------------------------------------
def test_a_rerun_is_refused_then_replaces_the_folder_whole(tmp_path, asset, capsys):
    metallic_asset = save_asset_folder(uv_sphere(segments=12, rings=6),
                                       small_maps(metallic=np.full((16, 16), 0.7, np.float32)), tmp_path / "metal")
    out = tmp_path / "out"
    assert cli("convert", str(metallic_asset), "--out", str(out), *CONVERT_FAST) == 0
    assert (out / "asset" / "metallic.png").is_file()
    capsys.readouterr()
    # The same folder again: refused before any work, the first run's files untouched.
    assert cli("convert", str(asset), "--out", str(out), *CONVERT_FAST) == 2
    assert "--replace" in capsys.readouterr().err
    assert (out / "asset" / "metallic.png").is_file()
    # Asked to replace: the folder holds this run's files only (no leftover metallic map to load as metal).
    assert cli("convert", str(asset), "--out", str(out), "--replace", *CONVERT_FAST) == 0
    assert not (out / "asset" / "metallic.png").exists()
    assert load_asset_folder(out / "asset")[1].metallic == 0.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["asset", "metal", "out"]  # no lock or partial left


def test_an_interrupted_run_leaves_the_previous_results_whole(tmp_path):
    out = tmp_path / "out"
    with output_folder(out) as staging:
        (staging / "a.txt").write_text("first")
        (staging / "b.txt").write_text("first")
    with pytest.raises(KeyboardInterrupt):
        with output_folder(out, replace=True) as staging:
            (staging / "a.txt").write_text("second")
            raise KeyboardInterrupt
    assert {p.name: p.read_text() for p in out.iterdir() if p.name != MARKER} == {"a.txt": "first", "b.txt": "first"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # Replaced: fewer files than before leaves no stale ones (render --views 4 then --views 2).
    with output_folder(out, replace=True) as staging:
        (staging / "a.txt").write_text("third")
    assert files(out) == ["a.txt"]


def test_a_resumable_run_keeps_its_progress_when_interrupted(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with output_folder(out, resume=True) as staging:
            (staging / "checkpoint.pt").write_text("iteration 100")
            raise KeyboardInterrupt
    assert not out.exists()
    with output_folder(out, resume=True) as staging:
        assert (staging / "checkpoint.pt").read_text() == "iteration 100"
    assert (out / "checkpoint.pt").is_file()


def test_leftovers_of_a_killed_run_are_cleaned_up(tmp_path):
    out = tmp_path / "out"
    staging = staging_path(out)
    staging.mkdir(parents=True)
    write_marker(staging)                                          # a killed run's partial folder
    (staging / "half.png").write_bytes(b"")
    aside = tmp_path / ".out.old-x1y2"                             # killed between the two renames of a swap
    (aside / "out").mkdir(parents=True)
    write_marker(aside, role="aside")
    write_marker(aside / "out")
    (aside / "out" / "report.json").write_text("{}")
    with output_folder(out, replace=True) as fresh:
        (fresh / f".base_color.png.x1y2{TEMP_MARK}.png").write_bytes(b"")  # a killed write's dot-temp file
        (fresh / "base_color.png").write_bytes(b"png")
        assert not (fresh / "half.png").exists()
    assert files(out) == ["base_color.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_two_runs_into_one_folder_are_refused(tmp_path):
    out = tmp_path / "out"
    holder = _FolderLock(tmp_path / ".out.lock")
    holder.acquire(out)
    try:
        with pytest.raises(InputError, match="Another SceneFit run"):
            with output_folder(out):
                pass
    finally:
        holder.release()
    with output_folder(out):
        pass


def test_out_that_is_a_file_is_refused_before_any_work(tmp_path, asset, capsys):
    target = tmp_path / "taken.txt"
    target.write_text("mine")
    assert cli("convert", str(asset), "--out", str(target), *CONVERT_FAST) == 2
    assert "is a file" in capsys.readouterr().err and target.read_text() == "mine"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_out_is_refused_before_any_work(tmp_path, asset, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert cli("convert", str(asset), "--out", str(locked / "out"), *CONVERT_FAST) == 2
        assert "permission" in capsys.readouterr().err
    finally:
        locked.chmod(0o700)


# -- images ------------------------------------------------------------------------------------------
def test_rgba_colour_is_read_as_stored_not_multiplied_by_alpha(tmp_path):
    rgba = np.zeros((4, 4, 4), np.float32)
    rgba[..., 0], rgba[..., 1], rgba[..., 3] = 1.0, 0.6, 0.5
    rgba[0, 0, 3] = 0.0
    write_image(tmp_path / "rgba.png", rgba)
    read = read_image(tmp_path / "rgba.png")
    assert np.allclose(read[..., :3], rgba[..., :3], atol=1 / 255)
    assert np.allclose(read[..., 3], rgba[..., 3], atol=1 / 255)


def test_image_errors_say_what_and_why(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        read_image(tmp_path)
    (tmp_path / "cut.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(InputError, match=r"cannot be (read|decoded) \(\S.*\)"):
        read_image(tmp_path / "cut.png")


# -- asset folders -----------------------------------------------------------------------------------
def broken_asset(tmp_path: Path, asset: Path, **arrays) -> Path:
    with np.load(asset / "mesh.npz") as data:
        content = {k: data[k] for k in data.files}
    content.update(arrays)
    for key in [k for k, v in content.items() if v is None]:
        del content[key]
    np.savez(asset / "mesh.npz", **content)
    return asset


@pytest.mark.parametrize("change, message", [
    ({"uvs": None}, "no uvs"),
    ({"faces": None}, "no faces"),
    ({"faces": "float"}, "integers"),
    ({"normals": "nan"}, "NaN or infinite normals"),
    ({"normals": "zero"}, "all-zero normals"),
])
def test_a_broken_mesh_npz_is_one_sentence(tmp_path, asset, change, message):
    key, value = next(iter(change.items()))
    with np.load(asset / "mesh.npz") as data:
        if value == "float":
            value = data["faces"].astype(np.float64)
        elif value == "nan":
            value = np.full_like(data["positions"], np.nan)
        elif value == "zero":
            value = np.zeros_like(data["positions"])
    broken_asset(tmp_path, asset, **{key: value})
    with pytest.raises(InputError, match=message):
        load_asset_folder(asset)


def test_truncated_npz_invalid_material_and_a_folder_as_a_map(tmp_path, asset):
    good = (asset / "mesh.npz").read_bytes()
    (asset / "mesh.npz").write_bytes(good[: len(good) // 2])
    with pytest.raises(InputError, match="cannot be read"):
        load_asset_folder(asset)
    (asset / "mesh.npz").write_bytes(good)
    (asset / "material.json").write_text('{"roughness": 0.5,')
    with pytest.raises(InputError, match="not valid JSON"):
        load_asset_folder(asset)
    (asset / "material.json").write_text('{"metallic": "shiny"}')
    with pytest.raises(InputError, match="must be a number"):
        load_asset_folder(asset)
    (asset / "material.json").write_text("{}")
    (asset / "roughness.png").unlink()
    (asset / "roughness.png").mkdir()
    with pytest.raises(InputError, match="is a folder"):
        load_asset_folder(asset)


# -- options and environment maps ----------------------------------------------------------------------
@pytest.mark.parametrize("args", [
    ("render", "--spp", "-4"), ("render", "--spp", "0"), ("render", "--exposure", "nan"),
    ("render", "--exposure", "-1"), ("render", "--size", "0"), ("export", "--azimuth", "nan"),
    ("export", "--spp", "-3"), ("adapt", "--at", "abc"), ("adapt", "--render-size", "0"),
    ("adapt", "--at", "1.5,0.5"),
])
def test_bad_options_are_refused_before_any_work(tmp_path, asset, capsys, args):
    out = tmp_path / "out"
    assert cli(args[0], str(asset), "--out", str(out), *args[1:]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and args[1] in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["light", "adapt", "compose", "run"])
def test_at_and_object_size_mean_one_thing_in_every_command(command):
    from scenefit.cli import build_parser
    from scenefit.core.scene.placement import Placement

    parser = build_parser()
    action = {a.dest: a for a in parser._subparsers._group_actions[0].choices[command]._actions}
    assert action["at"].type("0.5,0.7") == (0.5, 0.7) and action["at"].type("640,480") == (640.0, 480.0)
    assert ("object_size" in action) == (command != "light")      # light has no use for the object's size
    assert "size" not in action or command not in ("compose", "run")
    # Pixels are pixels of the photo as stored: 640,480 in a 1280x960 photo is its centre.
    assert Placement.parse((640.0, 480.0), (1280, 960)).center == (0.5, 0.5)
    with pytest.raises(InputError, match="mixes a fraction and a pixel"):
        Placement.parse("1.5,0.5", (1280, 960))


def test_light_takes_fractions_like_adapt(tmp_path, capsys):
    photo = tmp_path / "photo.png"
    write_image(photo, np.full((8, 8, 3), 0.5, np.float32))
    assert cli("light", "--photo", str(photo), "--at", "1.5,0.5", "--out", str(tmp_path / "o")) == 2
    assert "fractions" in capsys.readouterr().err


def test_light_messages_name_options_not_fields_and_offline_never_touches_the_network(tmp_path, capsys,
                                                                                     monkeypatch):
    import socket

    photo = tmp_path / "photo.png"
    write_image(photo, np.full((8, 8, 3), 0.5, np.float32))
    assert cli("light", "--photo", str(photo), "--at", "0.5,0.8", "--elevation", "100", "--out",
               str(tmp_path / "a"), "--quiet") == 2
    err = capsys.readouterr().err
    assert "pitch" in err and "-100" in err and "camera_pitch_deg" not in err   # the old --elevation is -pitch
    # --depth model --offline: a missing model is reported at once, without one connection attempt
    # (it used to retry the network for 98 s).
    attempts = []

    def no_network(self, address):
        attempts.append(address)
        raise OSError("network disabled by the test")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    assert cli("light", "--photo", str(photo), "--at", "0.5,0.8", "--depth", "model", "--offline", "--out",
               str(tmp_path / "b"), "--quiet") == 2
    assert attempts == []
    err = capsys.readouterr().err   # (a run never downloads: it says how to, offline or not)
    assert "was not found" in err and "scenefit models download depth" in err and not (tmp_path / "b").exists()


@pytest.mark.parametrize("value", [np.nan, np.inf, -1.0])
def test_export_refuses_a_broken_environment_map(tmp_path, asset, capsys, value):
    env = np.ones((8, 16, 3), np.float32)
    env[2, 3, 1] = value
    write_image(tmp_path / "env.exr", env)
    out = tmp_path / "out"
    assert cli("export", str(asset), "--out", str(out), "--envmap", str(tmp_path / "env.exr")) == 2
    assert "environment map" in capsys.readouterr().err.lower() and not out.exists()


def test_reports_are_strict_json(tmp_path):
    write_report(tmp_path / "report.json", {"psnr": float("inf"), "loss": float("nan"), "a": np.float32(2.5),
                                            "file": str(tmp_path / "maps" / "x.png")})

    def refuse(constant):
        raise ValueError(f"non-standard JSON constant {constant}")

    report = json.loads((tmp_path / "report.json").read_text(), parse_constant=refuse)
    assert report["psnr"] is None and report["loss"] is None and report["a"] == 2.5
    assert report["file"] == "maps/x.png"  # relative to the report, so it survives the folder's swap


def test_a_foreign_texture_file_gets_no_torch_advice(tmp_path, asset, capsys):
    (tmp_path / "texture.pt").write_bytes(b"not a torch file at all")
    assert cli("render", str(asset), "--texture", str(tmp_path / "texture.pt"), "--out", str(tmp_path / "o"),
               "--quiet") == 2
    err = capsys.readouterr().err
    assert "texture.pt" in err and "weights_only" not in err and len(err.strip().splitlines()) == 1


# -- files Blender reads (bpy in a child process) --------------------------------------------------------
def test_broken_asset_files_are_one_sentence(tmp_path):
    (tmp_path / "empty.glb").write_bytes(b"")
    (tmp_path / "cut.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    (tmp_path / "noise.fbx").write_bytes(bytes(range(256)) * 4)
    for name in ("empty.glb", "cut.glb", "noise.fbx"):
        out = tmp_path / f"out_{name}"
        proc = subprocess.run([sys.executable, "-m", "scenefit.cli", "convert", str(tmp_path / name), "--out",
                               str(out)], capture_output=True, text=True, timeout=300)
        lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
        assert proc.returncode == 2, proc.stderr[-2000:]
        assert len(lines) == 1 and name in lines[0] and "Traceback" not in lines[0], lines
        assert not out.exists()


def test_a_phone_photo_stored_sideways_is_read_upright(tmp_path):
    """EXIF Orientation 6 (stored sideways, shown turned 90 degrees clockwise): the light stage, the
    placement and the composite all see the photo as viewers show it, and the metadata's field of view
    is the upright photo's horizontal one."""
    import OpenImageIO as oiio

    from scenefit.core.data.photo import load_photo

    stored = np.full((40, 60, 3), 0.2, np.float32)
    stored[:8, :8] = 1.0                                # a white block in the stored top-left corner
    spec = oiio.ImageSpec(60, 40, 3, oiio.UINT8)
    spec.attribute("Orientation", 6)
    spec.attribute("Exif:FocalLengthIn35mmFilm", 26)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), stored)
    path = tmp_path / "portrait.jpg"
    assert buf.write(str(path))

    photo, info = load_photo(path)
    assert photo.shape == (60, 40, 3) and info["size"] == [40, 60] and "working_size" not in info
    assert photo[:8, -8:].mean() > 0.9 and photo[:8, :8].mean() < 0.5     # the block is now top-right
    # 35 mm equivalent 26 mm: 69.4 degrees across a landscape 3:2 frame, 49.6 across the portrait's width.
    assert abs(info["fov_from_metadata_deg"] - np.degrees(2 * np.arctan(24.0 / 52.0))) < 0.1


def test_a_ctrl_c_inside_a_render_is_an_interrupt_not_a_traceback(tmp_path, capsys, monkeypatch):
    """Dr.Jit wraps a KeyboardInterrupt raised during mi.render in a RuntimeError."""
    import scenefit.cli.render as render_command
    from scenefit.cli import main

    def render_interrupted(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise RuntimeError("drjit.custom(<_RenderOp>): error while performing a custom operation") from interrupt

    monkeypatch.setattr(render_command, "run", render_interrupted)
    parser_out, asset = tmp_path / "out", tmp_path / "asset"
    asset.mkdir()
    (asset / "mesh.npz").write_bytes(b"")   # an asset folder to the path check that runs before the command
    assert main(["render", str(asset), "--out", str(parser_out)]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err


def test_a_ctrl_c_inside_cycles_python_is_raised_once_the_bake_returns(run_py):
    """Cycles' bake runs its engine's Python inside the operator; a KeyboardInterrupt raised there is
    printed and dropped by Blender, and the bake finished as if nothing had happened (exit 0). Under
    interrupt_held the Ctrl-C is noted and raised after the operator; the handler is Python's again."""
    done = run_py("""
        import os, signal, time
        from scenefit.blender_io.interrupts import interrupt_held

        # A shell's background job starts with SIGINT ignored, and Python then keeps it ignored.
        signal.signal(signal.SIGINT, signal.default_int_handler)

        def operator_that_drops_exceptions():   # what Blender does with an engine callback's exception
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.2)
            except KeyboardInterrupt:
                print("dropped")

        operator_that_drops_exceptions()          # without: the interrupt is lost
        try:
            with interrupt_held():
                operator_that_drops_exceptions()
            print("lost")
        except KeyboardInterrupt:
            print("raised after the operator")
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    """)
    assert done.stdout.split() == ["dropped", "raised", "after", "the", "operator"], done.stdout
