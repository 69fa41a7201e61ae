"""Damaged inputs, resource limits and OS errors: each is refused in one sentence that
names the user's file, exit 2, before it can be used half-read or exhaust the machine."""
from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.core.data.asset_io import load_asset_folder, save_asset_folder
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import check_decodes, read_image, write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.primitives import uv_sphere

from conftest import printed_json

CONVERT_FAST = ("--preset", "draft", "--iterations", "2", "--resolution", "16", "--quiet")
LIGHT_FAST = ("--at", "0.5,0.8", "--critic", "none", "--depth", "geometric", "--outpaint", "prior", "--quiet")


def cli(*args: str) -> int:
    return main(list(args))


def one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def small_asset(folder: Path, size: tuple[int, int] = (16, 16)) -> Path:
    base = np.random.default_rng(0).uniform(0.1, 0.9, (*size, 3)).astype(np.float32)
    return save_asset_folder(uv_sphere(segments=12, rings=6), PBRMaps(base, 0.5, 0.0), folder)


def truncated_image(path: Path, fraction: float = 1 / 3) -> Path:
    """A real JPEG or PNG of noise (nothing compresses it away), cut to `fraction` of its bytes."""
    write_image(path, np.random.default_rng(1).uniform(0, 1, (96, 128, 3)).astype(np.float32))
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


# -- decoders that fail loudly -------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".jpg", ".png"])
@pytest.mark.parametrize("max_side", [None, 32])        # whole, and reduced band by band as photos are
def test_a_truncated_image_is_refused_not_used_half_grey(tmp_path, suffix, max_side):
    whole = tmp_path / f"whole{suffix}"
    write_image(whole, np.random.default_rng(1).uniform(0, 1, (96, 128, 3)).astype(np.float32))
    assert read_image(whole, max_side=max_side).shape[:2] == ((96, 128) if max_side is None else (24, 32))
    cut = truncated_image(tmp_path / f"cut{suffix}")
    with pytest.raises(InputError, match=r"cut\.(jpg|png)' cannot be decoded \(.*(end of|Premature)") as caught:
        read_image(cut, max_side=max_side)
    assert str(caught.value).count(str(cut)) == 1          # libjpeg's own copy of the path is dropped


def test_light_refuses_a_truncated_photo_in_one_line(tmp_path, capsys):
    photo = truncated_image(tmp_path / "truncated.jpg")
    out = tmp_path / "light"
    assert cli("light", "--photo", str(photo), "--out", str(out), *LIGHT_FAST) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith("scenefit: error: ") and str(photo) in line and "cannot be decoded" in line
    assert not out.exists()


def test_a_truncated_texture_in_an_asset_folder_is_refused(tmp_path, capsys):
    asset = small_asset(tmp_path / "asset")
    truncated_image(asset / "base_color.png")
    out = tmp_path / "out"
    assert cli("render", str(asset), "--out", str(out), "--size", "16", "--views", "1", "--quiet") == 2
    assert str(asset / "base_color.png") in one_line(capsys.readouterr().err)
    assert not out.exists()


def test_packed_image_bytes_are_checked_under_the_users_name(tmp_path):
    """What Blender holds packed (a .glb's textures): checked from its bytes, named as Blender names it."""
    cut = truncated_image(tmp_path / "albedo.jpg").read_bytes()
    with pytest.raises(InputError, match=r"Image 'albedo\.jpg' cannot be decoded") as caught:
        check_decodes(cut, "albedo.jpg")
    assert "tmp" not in str(caught.value).replace(str(tmp_path), "")
    write_image(tmp_path / "ok.png", np.full((4, 4, 3), 0.5, np.float32))
    check_decodes((tmp_path / "ok.png").read_bytes(), "ok.png")
    check_decodes(b"not an image format SceneFit checks", "other")   # other formats are Blender's to read


@pytest.mark.blender
def test_a_truncated_jpeg_texture_blender_would_show_grey_is_refused(tmp_path):
    """An OBJ whose map_Kd is a truncated JPEG: Blender decodes it (grey rows, no error); SceneFit refuses."""
    folder = tmp_path / "obj"
    folder.mkdir()
    mesh = uv_sphere(0.5, 12, 6)
    truncated_image(folder / "albedo.jpg")
    (folder / "ball.mtl").write_text("newmtl Ball\nKd 1 1 1\nmap_Kd albedo.jpg\n")
    lines = ["mtllib ball.mtl", "o Ball"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    lines += ["usemtl Ball"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in mesh.faces]
    (folder / "ball.obj").write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "scenefit.cli", "convert", str(folder / "ball.obj"), "--out",
                           str(out), *CONVERT_FAST], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    line = one_line(proc.stdout + proc.stderr)
    assert str(folder / "albedo.jpg") in line and "cannot be decoded" in line
    assert not out.exists()


# -- face indices ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("index, dtype", [(2**32 + 7, np.int64), (2**32 + 7, np.uint64), (-(2**32) + 7, np.int64)])
def test_face_indices_beyond_32_bits_are_refused_not_wrapped(tmp_path, index, dtype):
    """2^32 + 7 cast to int32 is 7, a valid vertex: the range is checked on the stored integers."""
    asset = small_asset(tmp_path / "asset")
    sphere = uv_sphere(segments=12, rings=6)
    faces = sphere.faces.astype(dtype)
    faces[3, 1] = index
    assert faces.astype(np.int32)[3, 1] == 7          # the cast alone would have hidden it
    np.savez(asset / "mesh.npz", positions=sphere.positions, faces=faces, uvs=sphere.uvs)
    with pytest.raises(InputError, match=r"mesh\.npz' has face indices .* outside its vertex list \(0\.\.\d+\)"):
        load_asset_folder(asset)
    with pytest.raises(InputError, match="outside its vertex list"):
        Mesh.from_arrays(sphere.positions, faces, sphere.uvs)


def test_face_indices_past_the_vertex_count_are_one_sentence_on_the_command_line(tmp_path, capsys):
    asset = small_asset(tmp_path / "asset")
    sphere = uv_sphere(segments=12, rings=6)
    faces = sphere.faces.astype(np.int64)
    faces[0, 0] = len(sphere.positions)
    np.savez(asset / "mesh.npz", positions=sphere.positions, faces=faces, uvs=sphere.uvs)
    assert cli("convert", str(asset), "--out", str(tmp_path / "out"), *CONVERT_FAST) == 2
    assert str(asset / "mesh.npz") in one_line(capsys.readouterr().err)


# -- sizes said as stored ----------------------------------------------------------------------------------
@pytest.mark.parametrize("shape, said, not_said", [((10000, 1, 3), "1x10000", "1x1000;"),
                                                    ((10, 10000, 3), "10000x10", "is 1000x1")])
def test_photo_sizes_in_messages_are_the_stored_sizes(tmp_path, capsys, shape, said, not_said):
    photo = write_image(tmp_path / "thin.png", np.full(shape, 0.5, np.float32))
    assert cli("light", "--photo", str(photo), "--out", str(tmp_path / "o"), *LIGHT_FAST) == 2
    line = one_line(capsys.readouterr().err)
    assert f"is {said}" in line and not_said not in line


@pytest.mark.blender
def test_a_refused_compose_or_pick_leaves_no_datablock_behind(run_py, tmp_path):
    truncated_image(tmp_path / "cut.jpg")       # Blender itself would load this one, grey rows and all
    truncated_image(tmp_path / "cut.png")
    (tmp_path / "noise.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 8)
    write_image(tmp_path / "good.png", np.full((24, 32, 3), 0.5, np.float32))
    proc = run_py(f"""
        import json
        from pathlib import Path
        import bpy, addon_utils

        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        bpy.ops.mesh.primitive_uv_sphere_add()
        settings = bpy.context.scene.scenefit
        out = {{}}
        def images():
            return sorted(i.name for i in bpy.data.images)
        def refused(op, **kw):   # a reported error is raised in background Blender
            try:
                return list(op(**kw))
            except RuntimeError as error:
                return ["refused", str(error).splitlines()[0]]
        for name in ("cut.jpg", "cut.png", "noise.png"):
            settings.photo_path = str(Path({str(tmp_path)!r}) / name)
            before = images()
            out[name] = {{"compose": refused(bpy.ops.scenefit.compose, render=False),
                          "pick": refused(bpy.ops.scenefit.pick_placement, x=0.5, y=0.8),
                          "new": sorted(set(images()) - set(before))}}
        settings.photo_path = str(Path({str(tmp_path)!r}) / "good.png")
        out["good"] = {{"compose": list(bpy.ops.scenefit.compose(render=False)), "images": images()}}
        print("JSON" + json.dumps(out))
    """)
    out = printed_json(proc)
    for name in ("cut.jpg", "cut.png", "noise.png"):
        result = out[name]
        assert result["new"] == [], (name, result)
        for op in ("compose", "pick"):
            assert result[op][0] == "refused" and f"{name}' cannot be" in result[op][1], (name, result)
    assert out["good"]["compose"] == ["FINISHED"] and "good.png" in out["good"]["images"]


# -- resource limits before work ---------------------------------------------------------------------------
def test_render_size_has_an_upper_bound_said_in_one_sentence(tmp_path, capsys):
    asset = small_asset(tmp_path / "asset")
    out = tmp_path / "out"
    assert cli("render", str(asset), "--out", str(out), "--size", "100000") == 2
    line = one_line(capsys.readouterr().err)
    assert "--size 100000" in line and "8192" in line and "memory" in line
    assert not out.exists()


def test_a_long_thin_texture_is_rendered_at_its_own_size_not_squared(tmp_path, monkeypatch, capsys):
    """A 16384x16 base colour (1 MB) squared to 16384² made a 5 GB stack (21 GB peak for 16 pixels)."""
    import scenefit.core.texture.views as views

    asset = small_asset(tmp_path / "asset", size=(16, 16384))
    seen = {}

    def render_views(mesh, stacks, envmap, cameras, spp, **_):
        seen.update({name: tuple(stack.shape) for name, stack in stacks.items()})
        return {name: [np.zeros((c.height, c.width, 3), np.float32) for c in cameras] for name in stacks}

    monkeypatch.setattr(views, "render_views", render_views)
    assert cli("render", str(asset), "--out", str(tmp_path / "out"), "--size", "16", "--views", "1",
               "--quiet") == 0, capsys.readouterr().err
    assert seen == {"asset maps": (16, 16384, 5)}


def test_a_texture_too_large_for_memory_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    import scenefit.core.base.limits as limits

    asset = small_asset(tmp_path / "asset", size=(256, 256))
    monkeypatch.setattr(limits, "physical_memory", lambda: 8 * 2**20)   # a machine of 8 MB
    out = tmp_path / "out"
    assert cli("render", str(asset), "--out", str(out), "--size", "16", "--views", "1", "--quiet") == 2
    line = one_line(capsys.readouterr().err)
    assert str(asset) in line and "256x256 texels" in line and "memory" in line
    assert not out.exists()


# -- every OSError a sentence -----------------------------------------------------------------------------
def failing(monkeypatch, name: str, code: int, inside: str) -> None:
    """os.<name> raises OSError(code) for paths under `inside` (as the full disk or read-only mount would)."""
    real = getattr(os, name)

    def fail(src, *args, **kwargs):
        dst = args[0] if args and name in ("replace", "rename") else src
        if inside in str(src) or inside in str(dst):
            raise OSError(code, os.strerror(code), str(src), *([str(dst)] if dst is not src else []))
        return real(src, *args, **kwargs)

    monkeypatch.setattr(os, name, fail)


@pytest.mark.parametrize("code, said", [(errno.ENOSPC, "(the disk is full); free space on it or choose another "
                                                       "--out folder."),
                                        (errno.EROFS, "(the file system is read-only)"),
                                        (errno.EACCES, "(permission denied)")])
def test_a_failed_write_during_convert_is_one_sentence_and_the_earlier_run_stays(tmp_path, monkeypatch, capsys,
                                                                                 code, said):
    asset = small_asset(tmp_path / "asset")
    out = tmp_path / "out"
    assert cli("convert", str(asset), "--out", str(out), *CONVERT_FAST) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    failing(monkeypatch, "replace", code, inside=".out.partial")     # every file this run writes
    assert cli("convert", str(asset), "--out", str(out), "--replace", *CONVERT_FAST) == 2
    line = one_line(capsys.readouterr().err)
    # Named as the file it was to become in --out, never the hidden staging folder or a temp name.
    assert line.startswith(f"scenefit: error: Cannot write '{out}{os.sep}") and said in line, line
    assert ".partial" not in line and "scenefit-tmp" not in line
    monkeypatch.undo()
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_read_only_output_parent_is_one_sentence(tmp_path, monkeypatch, capsys):
    """Tests run as root, which chmod cannot stop: the mount's refusal is simulated at mkdir."""
    asset = small_asset(tmp_path / "asset")
    parent = tmp_path / "mounted"
    parent.mkdir()
    failing(monkeypatch, "mkdir", errno.EROFS, inside=str(parent))
    assert cli("convert", str(asset), "--out", str(parent / "out"), *CONVERT_FAST) == 2
    line = one_line(capsys.readouterr().err)
    assert "read-only" in line and "--out" in line and str(parent / "out") in line


def test_a_busy_rename_is_one_sentence(tmp_path, monkeypatch, capsys):
    asset = small_asset(tmp_path / "asset")
    out = tmp_path / "out"
    failing(monkeypatch, "rename", errno.EBUSY, inside=str(out))
    assert cli("convert", str(asset), "--out", str(out), *CONVERT_FAST) == 2
    line = one_line(capsys.readouterr().err)
    assert f"'{out}' is busy" in line and "try again" in line


def test_a_full_disk_during_run_is_one_sentence(tmp_path, monkeypatch, capsys):
    asset = small_asset(tmp_path / "asset")
    photo = write_image(tmp_path / "photo.png", np.full((48, 64, 3), 0.5, np.float32))
    out = tmp_path / "run"
    failing(monkeypatch, "replace", errno.ENOSPC, inside=str(tmp_path / "run"))
    failing(monkeypatch, "rename", errno.ENOSPC, inside=str(tmp_path / "run"))
    assert cli("run", str(asset), "--photo", str(photo), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
               "--guidance", "none", "--spp", "2", "--quiet") == 2
    line = one_line(capsys.readouterr().err)
    assert "(the disk is full)" in line and str(out) in line


def test_os_error_sentences_name_the_users_path_and_what_to_do(tmp_path):
    from scenefit.core.base.os_errors import os_error_sentence, with_out_paths

    out = tmp_path / "out"
    temp = tmp_path / ".out.partial" / "maps" / ".roughness.png.k3j2.scenefit-tmp.png"
    said = os_error_sentence(OSError(errno.ENOSPC, "No space left on device", str(temp)), out)
    assert said == f"Cannot write '{out / 'maps' / 'roughness.png'}' (the disk is full); free space on it or " \
                   "choose another --out folder."
    in_the_way = tmp_path / "a_file"
    said = os_error_sentence(NotADirectoryError(errno.ENOTDIR, "Not a directory", str(in_the_way / "x")), out)
    assert "a file of that name is in the way" in said and "give another path" in said
    said = os_error_sentence(OSError(errno.ENOTEMPTY, "Directory not empty", str(tmp_path / ".out.partial"),
                                     str(out)), out)
    assert said.startswith(f"'{out}' already exists") and "choose another --out folder" in said
    # A write() to an open file names no path: the run's folder is named.
    said = os_error_sentence(OSError(errno.ENOSPC, "No space left on device"), out)
    assert said.startswith(f"Cannot write '{out}' (the disk is full)")
    assert with_out_paths(f"Cannot write '{tmp_path / '.out.partial' / 'light.exr'}': no", out) == \
        f"Cannot write '{out / 'light.exr'}': no"
    said = os_error_sentence(OSError(errno.EIO, "Input/output error"), out)
    assert said.startswith("A file operation failed (Input/output error)") and said.endswith("try again.")
    for code in (errno.EISDIR, errno.EXDEV, errno.ENAMETOOLONG, errno.EMFILE, errno.ENOENT, errno.EPERM, errno.EIO):
        said = os_error_sentence(OSError(code, os.strerror(code), str(out / "f.png")), out)
        assert f"'{out / 'f.png'}'" in said and said.endswith(".") and said.count(". ") == 0, said


# -- a batch job's error names the user's file ----------------------------------------------------------------
def test_an_unpacked_copys_paths_become_the_users(tmp_path):
    from scenefit.workers.jobs import Job, with_user_paths

    job = Job("j", tmp_path / "assets" / "ball", ("light",), photo=tmp_path / "photos" / "broken.png")
    copy = Job("j", Path("/tmp/scenefit-job-x/in/asset/ball"), ("light",),
               photo=Path("/tmp/scenefit-job-x/in/photo/broken.png"))
    text = ("Image '/tmp/scenefit-job-x/in/photo/broken.png' cannot be decoded; and "
            "'/tmp/scenefit-job-x/in/asset/ball/base_color.png' too.")
    assert with_user_paths(text, copy, job) == (f"Image '{job.photo}' cannot be decoded; and "
                                                f"'{job.asset / 'base_color.png'}' too.")


def test_a_failed_batch_jobs_error_names_the_users_photo(tmp_path, capsys):
    small_asset(tmp_path / "ball")
    photo = truncated_image(tmp_path / "broken.png")
    (tmp_path / "jobs.toml").write_text('[batch]\nretries = 0\n[[job]]\nname = "j"\nasset = "ball"\n'
                                        'photo = "broken.png"\nat = [0.5, 0.7]\nstages = ["light"]\npreset = "draft"\n')
    assert cli("batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out"), "--quiet") == 1
    error = json.loads((tmp_path / "out" / "j" / "report.json").read_text())["error"]
    assert str(photo) in error and "scenefit-job-" not in error, error
