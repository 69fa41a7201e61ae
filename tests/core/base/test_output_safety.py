"""The user's files are never deleted, overwritten or run, on decoy folders: `--replace`
only replaces a SceneFit run folder, outputs never overwrite inputs, checkpoints and textures are
data, and `run` and `batch` follow every command's output-folder contract."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from scenefit.cli import main
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.base.output_folder import MARKER, _FolderLock, is_run_folder, output_folder, staging_path
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.glb import write_glb

CONVERT_FAST = ("--preset", "draft", "--iterations", "2", "--resolution", "16", "--quiet")
RUN_FAST = ("--preset", "draft", "--guidance", "none", "--spp", "2", "--quiet")


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` with its bytes: what must be exactly the same after a refusal."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def project(tmp_path) -> Path:
    """A user's project folder: an asset folder, a photo, notes of their own."""
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    save_asset_folder(uv_sphere(0.5, 12, 6), maps, tmp_path / "project" / "asset")
    write_image(tmp_path / "project" / "photos" / "room.png",
                np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None], (48, 64, 3)).astype(np.float32))
    (tmp_path / "project" / "notes.txt").write_text("my notes")
    (tmp_path / "project" / "photos" / "shot-list.txt").write_text("my list")
    return tmp_path / "project"


def refused(capsys, *args: str) -> str:
    """Run the command line in this process; it must refuse (exit 2) in one sentence."""
    assert main(list(args)) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scenefit: error: ") and "\n" not in err and "Traceback" not in err, err
    return err


# -- --replace deletes nothing but SceneFit's own run folders ---------------------------------------------
@pytest.mark.parametrize("where", ["asset", "project", "photos"])
def test_replace_never_deletes_a_folder_that_holds_an_input(tmp_path, project, capsys, where):
    before = snapshot(tmp_path)
    out = project / where if where != "project" else project
    if where == "photos":
        err = refused(capsys, "light", "--photo", str(project / "photos" / "room.png"), "--at", "0.5,0.8",
                      "--out", str(out), "--replace", "--preset", "draft", "--quiet")
    else:
        err = refused(capsys, "convert", str(project / "asset"), "--out", str(out), "--replace", *CONVERT_FAST)
    assert "holds the input" in err
    assert snapshot(tmp_path) == before


def test_replace_never_deletes_home_the_working_folder_or_their_ancestors(tmp_path, project, capsys, monkeypatch):
    home = tmp_path / "home"
    (home / ".ssh").mkdir(parents=True)
    (home / ".ssh" / "config").write_text("Host decoy")
    work = home / "work"
    work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    before = snapshot(tmp_path)
    for out in (str(home), "~", ".", "..", "/"):
        err = refused(capsys, "convert", str(project / "asset"), "--out", out, "--replace", *CONVERT_FAST)
        assert "never replaces" in err, err
    assert snapshot(tmp_path) == before


def test_replace_never_deletes_a_folder_sceneFit_did_not_write(tmp_path, project, capsys):
    mine = tmp_path / "results"
    mine.mkdir()
    (mine / "thesis.tex").write_text("chapter 1")
    err = refused(capsys, "convert", str(project / "asset"), "--out", str(mine), "--replace", *CONVERT_FAST)
    assert "did not write" in err and MARKER in err
    assert (mine / "thesis.tex").read_text() == "chapter 1"


def test_replace_replaces_its_own_run_folder_and_leaves_lookalike_names_alone(tmp_path, project, capsys):
    out = tmp_path / "out"
    assert main(["convert", str(project / "asset"), "--out", str(out), *CONVERT_FAST]) == 0
    assert is_run_folder(out)
    # The user's own folders named like SceneFit's leftovers: not SceneFit's, so never deleted.
    for name in (".out.old", ".out.old-abc", ".out.partial-x"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "keep.txt").write_text(name)
    assert main(["convert", str(project / "asset"), "--out", str(out), "--replace", *CONVERT_FAST]) == 0
    for name in (".out.old", ".out.old-abc", ".out.partial-x"):
        assert (tmp_path / name / "keep.txt").read_text() == name
    # A folder of the user's exactly where the staging folder goes is in the way: refused, kept.
    (tmp_path / ".out.partial").mkdir()
    (tmp_path / ".out.partial" / "keep.txt").write_text("mine")
    err = refused(capsys, "convert", str(project / "asset"), "--out", str(out), "--replace", *CONVERT_FAST)
    assert "was not made by SceneFit" in err and (tmp_path / ".out.partial" / "keep.txt").read_text() == "mine"


def test_a_lock_file_name_of_the_users_is_neither_used_nor_deleted(tmp_path):
    (tmp_path / ".out.lock").write_text("my lock notes")
    with pytest.raises(InputError, match="was not made by SceneFit"):
        with output_folder(tmp_path / "out"):
            pass
    assert (tmp_path / ".out.lock").read_text() == "my lock notes"


def test_an_out_that_is_a_symbolic_link_is_refused(tmp_path, project, capsys):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (target / "precious.txt").write_text("x")
    (tmp_path / "link").symlink_to(target)
    err = refused(capsys, "convert", str(project / "asset"), "--out", str(tmp_path / "link"), "--replace",
                  *CONVERT_FAST)
    assert "symbolic link" in err and (target / "precious.txt").read_text() == "x"


# -- outputs never overwrite an input -------------------------------------------------------------------
def _glb(path: Path) -> Path:
    """A minimal valid GLB (one triangle), as any exporter writes it."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()
    document = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
                "nodes": [{"mesh": 0, "name": "Tri"}],
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                               "min": [0, 0, 0], "max": [1, 1, 0]}],
                "bufferViews": [{"buffer": 0, "byteLength": len(positions)}],
                "buffers": [{"byteLength": len(positions)}]}
    write_glb(path, document, positions)
    return path


def test_bake_refuses_to_write_over_the_asset_or_the_texture(tmp_path, capsys):
    model = _glb(tmp_path / "model.glb")
    texture = tmp_path / "texture.pt"
    texture.write_bytes(b"weights")
    before = snapshot(tmp_path)
    for out in (model, tmp_path / "." / "model.glb"):
        err = refused(capsys, "bake", str(model), "--texture", str(texture), "--out", str(out))
        assert "one of the inputs" in err
    (tmp_path / "link.glb").symlink_to(model)       # the same file under another name
    assert "one of the inputs" in refused(capsys, "bake", str(model), "--texture", str(texture), "--out",
                                          str(tmp_path / "link.glb"))
    os.link(model, tmp_path / "hard.glb")           # and a hard link to it
    assert "one of the inputs" in refused(capsys, "bake", str(model), "--texture", str(texture), "--out",
                                          str(tmp_path / "hard.glb"))
    assert "one of the inputs" in refused(capsys, "bake", str(model), "--texture", str(texture), "--out",
                                          str(tmp_path / "baked.glb"), "--report", str(texture))
    (tmp_path / "link.glb").unlink()
    (tmp_path / "hard.glb").unlink()
    assert snapshot(tmp_path) == before


def test_bake_refuses_to_replace_an_earlier_bake_unless_asked(tmp_path, capsys):
    model = _glb(tmp_path / "model.glb")
    texture = tmp_path / "texture.pt"
    texture.write_bytes(b"weights")
    (tmp_path / "baked.glb").write_bytes(b"an earlier bake")
    (tmp_path / "notes.json").write_text("the user's notes")
    before = snapshot(tmp_path)
    err = refused(capsys, "bake", str(model), "--texture", str(texture), "--out", str(tmp_path / "baked.glb"))
    assert "'" + str(tmp_path / "baked.glb") + "' already exists" in err and "--replace" in err
    err = refused(capsys, "bake", str(model), "--texture", str(texture), "--out", str(tmp_path / "new.gltf"),
                  "--report", str(tmp_path / "notes.json"))
    assert "notes.json' already exists" in err
    assert snapshot(tmp_path) == before
    # --replace passes that check; this texture file is then refused for what it is, and nothing is written
    err = refused(capsys, "bake", str(model), "--texture", str(texture), "--out", str(tmp_path / "baked.glb"),
                  "--replace")
    assert "already exists" not in err
    assert snapshot(tmp_path) == before


def test_the_files_a_gltf_asset_is_made_of_are_known(tmp_path):
    from scenefit.core.data.asset_files import asset_files

    (tmp_path / "tex").mkdir()
    for name in ("mesh.bin", "tex/Material_base_color.png", "unrelated.png"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "chair.gltf").write_text(json.dumps({
        "asset": {"version": "2.0"}, "buffers": [{"uri": "mesh.bin", "byteLength": 1}],
        "images": [{"uri": "tex/Material%5Fbase_color.png"}, {"uri": "data:image/png;base64,AAAA"}]}))
    names = [p.relative_to(tmp_path.resolve()).as_posix() for p in asset_files(tmp_path / "chair.gltf")]
    assert names == ["chair.gltf", "mesh.bin", "tex/Material_base_color.png"]
    (tmp_path / "ball.obj").write_text("mtllib ball.mtl\nv 0 0 0\n")
    (tmp_path / "ball.mtl").write_text("newmtl Ball\nmap_Kd tex/Material_base_color.png\n")
    names = [p.relative_to(tmp_path.resolve()).as_posix() for p in asset_files(tmp_path / "ball.obj")]
    assert names == ["ball.mtl", "ball.obj", "tex/Material_base_color.png"]


@pytest.mark.parametrize("mtllib, library", [
    ("mtllib my fox.mtl", "my fox.mtl"),          # the line's rest is one name, spaces and all
    ('mtllib "quoted.mtl"', "quoted.mtl"),        # quotes stripped
    ("mtllib gone.mtl", "fox.mtl"),               # a missing one: Blender reads the same-named .mtl
    ("", "fox.mtl"),                              # none named: the same-named .mtl all the same
])
def test_an_objs_libraries_and_maps_are_read_as_blender_reads_them(tmp_path, mtllib, library):
    """The OBJ's material library as Blender's importer finds it, and a map whose name has spaces after
    its options: what the refusal of a missing library and what a batch job sends rest on (a library
    named with a space, quotes or missing beside a same-named .mtl was refused, though Blender reads it)."""
    from scenefit.core.data.asset_files import asset_files
    from scenefit.core.data.asset_io import check_asset_path

    (tmp_path / "fox.obj").write_text(f"{mtllib}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / library).write_text("newmtl Fox\nmap_Kd -s 2 2 1 -clamp on my wood.png\n"
                                    'map_Ks "quoted name.png"\nmap_Ns C:\\Users\\me\\tex\\beside.png\n')
    for name in ("my wood.png", "quoted name.png", "beside.png"):
        (tmp_path / name).write_bytes(b"x")
    check_asset_path(tmp_path / "fox.obj")   # not refused
    names = [p.name for p in asset_files(tmp_path / "fox.obj")]   # (a path from elsewhere: its base name beside)
    assert names == sorted(["fox.obj", library, "my wood.png", "quoted name.png", "beside.png"])
    (tmp_path / library).unlink()
    if mtllib:   # named, and neither it nor the same-named .mtl there: one sentence
        with pytest.raises(InputError, match="names the material library"):
            check_asset_path(tmp_path / "fox.obj")
    else:
        check_asset_path(tmp_path / "fox.obj")


def test_one_missing_library_of_two_is_refused(tmp_path):
    """Two libraries named, one missing and no same-named .mtl to stand in: Blender would import that
    one's materials grey without a word."""
    from scenefit.core.data.asset_io import check_asset_path

    (tmp_path / "fox.obj").write_text("mtllib a.mtl\nmtllib b.mtl\nv 0 0 0\n")
    (tmp_path / "a.mtl").write_text("newmtl A\n")
    with pytest.raises(InputError, match="names the material library 'b.mtl', which is not in"):
        check_asset_path(tmp_path / "fox.obj")
    (tmp_path / "fox.mtl").write_text("newmtl B\n")   # the same-named .mtl, which Blender reads as well
    check_asset_path(tmp_path / "fox.obj")


# -- nothing from a folder runs code ------------------------------------------------------------------
class _Payload:
    """A pickle that, if unpickled by an unrestricted loader, creates a file: the proof that code ran."""

    def __init__(self, proof: Path) -> None:
        self.proof = proof

    def __reduce__(self):
        return (exec, (f"open({str(self.proof)!r}, 'w').write('ran')",))


def test_a_planted_checkpoint_or_texture_runs_nothing(tmp_path):
    from scenefit.core.stages.adapt.checkpoint import load_checkpoint
    from scenefit.core.stages.adapt.config import AdaptConfig
    from scenefit.core.texture.bake import load_neural_texture

    proof = tmp_path / "code_ran"
    planted = tmp_path / "adapt_checkpoint.pt"
    torch.save({"format": "scenefit.adapt_checkpoint", "settings": _Payload(proof)}, planted)
    with pytest.raises(InputError, match="cannot be read"):
        load_checkpoint(planted, AdaptConfig(prompt="x"))
    texture = tmp_path / "texture.pt"
    torch.save({"format": "scenefit.neural_texture", "config": _Payload(proof)}, texture)
    with pytest.raises(InputError, match="not a readable neural texture"):
        load_neural_texture(texture)
    assert not proof.exists()


def test_a_real_checkpoint_still_loads_as_data(tmp_path):
    """weights_only loading keeps what a checkpoint holds: tensors, optimiser state, history."""
    from scenefit.core.stages.adapt.checkpoint import load_checkpoint, save_checkpoint
    from scenefit.core.stages.adapt.config import AdaptConfig
    from scenefit.core.texture.neural_texture import NeuralTexture, NeuralTextureConfig

    config = AdaptConfig(prompt="x")
    texture = NeuralTexture(NeuralTextureConfig(resolution=16, n_levels=2, log2_table=8, finest_resolution=32, hidden=8), seed=0)
    optimizer = torch.optim.Adam(texture.parameters(), lr=1e-3)
    texture(torch.rand(4, 3) - 0.5).sum().backward()
    optimizer.step()
    path = save_checkpoint(tmp_path / "c.pt", 7, config, texture, optimizer, None, [{"iteration": 7, "loss": 0.5}])
    payload = load_checkpoint(path, config)
    assert payload["iteration"] == 7 and payload["history"] == [{"iteration": 7, "loss": 0.5}]
    assert set(payload["optimizer"]["state"]) == set(optimizer.state_dict()["state"])


# -- run: the same contract --------------------------------------------------------------------------
def test_run_refuses_a_folder_of_the_users_and_a_second_writer(tmp_path, project, capsys):
    photo = str(project / "photos" / "room.png")
    before = snapshot(tmp_path)
    err = refused(capsys, "run", str(project / "asset"), "--photo", photo, "--at", "0.5,0.8",
                  "--out", str(project / "asset"), *RUN_FAST)
    assert "holds the input" in err
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "a.txt").write_text("a")
    before = snapshot(tmp_path)
    assert "did not write" in refused(capsys, "run", str(project / "asset"), "--photo", photo, "--at", "0.5,0.8",
                                      "--out", str(mine), *RUN_FAST)
    out = tmp_path / "run"
    holder = _FolderLock(tmp_path / ".run.lock")
    holder.acquire(out)
    try:
        assert "Another SceneFit run" in refused(capsys, "run", str(project / "asset"), "--photo", photo, "--at",
                                                 "0.5,0.8", "--out", str(out), *RUN_FAST)
    finally:
        holder.release()
    assert snapshot(tmp_path) == before and not out.exists()


KILLED_RUN = """
import os, signal, sys
import scenefit.core.stages.compose as compose
from scenefit.cli import main

def killed(*_, **__):
    os.kill(os.getpid(), signal.SIGKILL)   # kill -9 in the middle of the compose stage

compose.compose_to_folder = killed
sys.exit(main(sys.argv[1:]))
"""


def test_a_killed_changed_rerun_leaves_the_finished_folder_whole(tmp_path, project):
    out = tmp_path / "run"
    args = [str(project / "asset"), "--photo", str(project / "photos" / "room.png"), "--at", "0.5,0.8",
            "--out", str(out), "--preset", "draft", "--guidance", "none", "--quiet"]
    assert main(["run", *args, "--spp", "2"]) == 0
    before = snapshot(out)
    killed = subprocess.run([sys.executable, "-c", textwrap.dedent(KILLED_RUN), "run", *args, "--spp", "3"],
                            capture_output=True, text=True, timeout=600)
    assert killed.returncode == -9, killed.stderr
    assert snapshot(out) == before              # report, composite, every stage.json: the first run's
    # The next run takes up where the killed one stopped (its finished stages kept beside the folder).
    assert (staging_path(out) / "light" / "stage.json").is_file()
    assert main(["run", *args, "--spp", "3"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["convert", "light"] and report["composite"] == "compose/composite.png"
    assert not staging_path(out).exists()


# -- batch: the same contract ------------------------------------------------------------------------
def _jobs(folder: Path, project: Path, name: str) -> Path:
    path = folder / "jobs.toml"
    path.write_text(f'[[job]]\nname = "{name}"\nasset = "{project / "asset"}"\nphoto = "{project / "photos" / "room.png"}"'
                    f'\nat = [0.5, 0.8]\npreset = "draft"\nstages = ["light"]\n')
    return path


def test_batch_never_replaces_a_users_folder_or_writes_over_its_own_files(tmp_path, project, capsys):
    jobs = _jobs(tmp_path, project, "sofa")
    (project / "sofa").mkdir()
    (project / "sofa" / "notes.txt").write_text("the user's sofa notes")
    before = snapshot(tmp_path)
    assert "holds the input" in refused(capsys, "batch", str(jobs), "--out", str(project))
    other = tmp_path / "other"
    (other / "sofa").mkdir(parents=True)
    (other / "sofa" / "notes.txt").write_text("mine")
    assert "did not write" in refused(capsys, "batch", str(jobs), "--out", str(other))
    (tmp_path / "file.txt").write_text("a file")
    assert "is a file" in refused(capsys, "batch", str(jobs), "--out", str(tmp_path / "file.txt"))
    assert "named like a file the batch writes" in refused(capsys, "batch", str(_jobs(tmp_path, project, "summary.json")),
                                                           "--out", str(tmp_path / "new"))
    _jobs(tmp_path, project, "sofa")
    assert snapshot(tmp_path) == {**before, "file.txt": b"a file", "other/sofa/notes.txt": b"mine"}
    assert not (tmp_path / "new").exists()


def test_batch_folder_is_marked_and_a_job_folder_of_the_users_inside_it_is_refused(tmp_path, project, capsys):
    jobs = _jobs(tmp_path, project, "sofa")
    out = tmp_path / "out"
    assert main(["batch", str(jobs), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert is_run_folder(out) and is_run_folder(out / "sofa")
    _jobs(tmp_path, project, "chair")
    (out / "chair").mkdir()
    (out / "chair" / "mine.txt").write_text("mine")
    assert "not replaced" in refused(capsys, "batch", str(jobs), "--out", str(out))
    assert (out / "chair" / "mine.txt").read_text() == "mine"


def test_an_out_inside_a_file_is_named_as_such(tmp_path, project, capsys):
    (tmp_path / "afile").write_text("x")
    err = refused(capsys, "convert", str(project / "asset"), "--out", str(tmp_path / "afile" / "sub"), *CONVERT_FAST)
    assert "is a file" in err and (tmp_path / "afile").read_text() == "x"


GLTF_WITH_LOOKALIKE = r"""
from pathlib import Path
import sys
import bpy, addon_utils
sys.path.insert(0, "tests")
from asset_builder import _image, _pattern, _rgba

folder = Path(FOLDER)
addon_utils.enable("io_scene_gltf2", default_set=False)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
ball = bpy.context.active_object
mat = bpy.data.materials.new("Ball")
tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
# The asset's own texture is named exactly as bake names the baked base colour of material 'Ball'.
tex.image = _image(bpy, folder, "Ball_base_color", _rgba(_pattern(16, 1)), "sRGB")
mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
ball.data.materials.append(mat)
bpy.ops.export_scene.gltf(filepath=str(folder / "ball.gltf"), export_format="GLTF_SEPARATE")
bpy.ops.wm.read_factory_settings(use_empty=True)
from scenefit.cli import main   # convert it in this Blender process
assert main(["convert", str(folder / "ball.gltf"), "--out", str(folder / "conv"), *CONVERT_FAST]) == 0
"""


@pytest.mark.blender
def test_a_gltf_bake_beside_the_asset_never_writes_over_its_own_images(tmp_path, run_py):
    run_py(GLTF_WITH_LOOKALIKE.replace("FOLDER", repr(str(tmp_path))).replace("CONVERT_FAST", repr(CONVERT_FAST)),
           timeout=600)
    asset = tmp_path / "ball.gltf"
    from scenefit.core.data.asset_files import asset_files

    assert tmp_path.resolve() / "Ball_base_color.png" in asset_files(asset)
    before = snapshot(tmp_path / "conv") | {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    done = subprocess.run([sys.executable, "-m", "scenefit.cli", "bake", str(asset), "--texture",
                           str(tmp_path / "conv" / "maps" / "texture.pt"), "--format", "gltf", "--out",
                           str(tmp_path / "baked.gltf"), "--quiet"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and "one of the inputs" in done.stderr and "Ball_base_color.png" in done.stderr
    after = snapshot(tmp_path / "conv") | {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    assert after == before and not (tmp_path / "baked.gltf").exists()


def test_files_that_appear_in_the_output_while_writing_are_left_and_this_run_waits_beside_them(tmp_path):
    """Someone saves into the (empty) output folder while a run writes: neither is lost. Their file stays,
    and this run's files stay in the staging folder the sentence names (it named it, then deleted it)."""
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(InputError) as refused:
        with output_folder(out) as staging:
            (staging / "result.txt").write_text("this run")
            (out / "mine.txt").write_text("theirs")
    assert str(refused.value) == (f"Files appeared in '{out}' while SceneFit was writing; this run is kept beside it "
                                  f"in '.out.partial' and '{out}' is untouched: move them away and run again.")
    assert (out / "mine.txt").read_text() == "theirs" and not (out / "result.txt").exists()
    assert (staging_path(out) / "result.txt").read_text() == "this run"
