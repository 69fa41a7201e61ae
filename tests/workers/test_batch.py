"""`scenefit batch`: the jobs file and the in-process runner: folders, summary, retries, resume, what each
job's inputs take along."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from scenefit.cli import main
from scenefit.workers.batch import InProcessDispatcher, run_batch
from scenefit.workers.job_worker import JOB_FOLDER_PREFIX, JobWorker
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import read_image, write_image
from scenefit.workers.jobs import load_jobs
from scenefit.core.data.glb import write_glb
from scenefit.core.data.primitives import uv_sphere
from batch_inputs import AlwaysFailingWorker, make_inputs


def test_jobs_file_paths_defaults_and_order(tmp_path):
    jobs = load_jobs(make_inputs(tmp_path))
    assert [j.name for j in jobs.jobs] == ["a", "b", "c"]
    a, b, c = jobs.jobs
    assert a.asset == (tmp_path / "ball").resolve() and a.photo == (tmp_path / "room.png").resolve()
    assert a.stages == ("convert", "light")          # pipeline order, whatever the file's order
    assert c.stages == ("light",) and b.run.seed == 1 and a.run.preset == "draft" and a.at == (0.5, 0.7)
    assert jobs.settings.retries == 1 and jobs.settings.num_gpus == "auto"


def test_a_job_may_name_the_folder_a_gltf_came_in(tmp_path):
    path = make_inputs(tmp_path)
    (tmp_path / "Fox").mkdir()
    write_glb(tmp_path / "Fox" / "Fox.glb", {"asset": {"version": "2.0"}}, b"")   # (read when the jobs file is)
    (tmp_path / "Fox" / "LICENSE.md").write_text("CC-BY")
    path.write_text(path.read_text().replace('asset = "ball"\nseed', 'asset = "Fox"\nseed'))
    assert load_jobs(path).jobs[1].asset == (tmp_path / "Fox" / "Fox.glb").resolve()
    (tmp_path / "Fox" / "Fox.gltf").write_text("{}")
    with pytest.raises(InputError, match="holds 2 asset files"):
        load_jobs(path)


@pytest.mark.parametrize("change, message", [
    (lambda t: t.replace('asset = "ball"\nseed', 'asset = "nothing"\nseed'), "the asset"),
    (lambda t: t.replace('name = "b"', 'name = "a"'), "two jobs are named 'a'"),
    (lambda t: t.replace('name = "c"', 'name = "../c"'), "needs a name"),
    (lambda t: t.replace('stages = ["light"]', 'stages = ["light", "paint"]'), "unknown stage 'paint'"),
    (lambda t: t.replace("at = [0.5, 0.7]", "at = [0.5, 1.7]"), r"at must be \[x, y\]"),
    (lambda t: t.replace('preset = "draft"', 'preset = "fast"'), "preset must be one of"),
    (lambda t: t.replace("seed = 1", "sed = 1"), "unknown key 'sed'"),
    (lambda t: t.replace("retries = 1", "retries = -1"), "retries must be"),
    (lambda t: t.replace('photo = "room.png"\n', ''), "needs a photo"),
    (lambda t: t.replace("[[job]]", "[[jobs]]"), "unknown table 'jobs'"),
    (lambda t: t + "[[job\n", "not valid TOML"),
    (lambda t: t + "[models]\nbase = 'x'\n", r"\[models\]: unknown key 'base'"),
    (lambda t: t + "[models]\ndevice_type = 'tpu'\n", "device_type must be one of"),
    (lambda t: t + "[models]\nbase_model = './models/sd2-base'\n", r"base_model './models/sd2-base' names the "
                                                                  r"folder .* which does not exist"),
    (lambda t: t + "[models]\ncache_dir = 'hub-cache'\n", r"cache_dir 'hub-cache' names the folder"),
    (lambda t: t.replace("seed = 1", "overrides = { paint = { iterations = 2 } }"), "unknown stage 'paint'"),
])
def test_jobs_file_errors_are_one_sentence(tmp_path, change, message):
    path = make_inputs(tmp_path)
    path.write_text(change(path.read_text()))
    with pytest.raises(InputError, match=message) as error:
        load_jobs(path)
    assert "\n" not in str(error.value).strip()


def test_models_given_as_folders_are_folders_and_hub_ids_stay_ids(tmp_path):
    """The docs' example `base_model = "models/sd2-base"`: with models/ beside the jobs file it is that folder,
    refused while it is missing; without models/ it is a hub id (owner/name), as the run looks it up."""
    path = make_inputs(tmp_path)
    path.write_text(path.read_text() + '[models]\nbase_model = "models/sd2-base"\n')
    assert load_jobs(path).jobs[0].models.base_model == "models/sd2-base"          # a hub id
    (tmp_path / "models").mkdir()
    with pytest.raises(InputError, match="names the folder .*sd2-base', which does not exist"):
        load_jobs(path)
    (tmp_path / "models" / "sd2-base").mkdir()
    assert load_jobs(path).jobs[0].models.base_model == str((tmp_path / "models" / "sd2-base").resolve())


def test_in_process_batch_writes_folders_summary_and_resumes(in_process, capsys):
    jobs_path, out, outcomes = in_process
    assert [(o.name, o.status, o.attempts) for o in outcomes] == [("a", "done", 1), ("b", "done", 1), ("c", "done", 1)]
    for name in "abc":
        report = json.loads((out / name / "report.json").read_text())
        assert report["status"] == "done" and report["job"]["name"] == name
        assert (out / name / "light" / "light.exr").is_file()
        # Paths in the report are inside the job's folder, relative to it.
        assert (out / name / report["stages"]["run"]["stages"]["light"]["report"]["outputs"]["hdr_exr"]).is_file()
    assert (out / "a" / "convert" / "maps" / "base_color.png").is_file() and not (out / "c" / "convert").exists()
    assert outcomes[0].quality["convert_psnr_db"] > 30.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"done": 3, "skipped": 0, "failed": 0}
    assert "| a | done | 1 |" in (out / "summary.md").read_text()
    sheet = read_image(out / "contact_sheet.png")
    assert sheet.shape[0] > 0 and sheet.shape[1] == 3 * 192      # three cells in one row
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".scenefit-run"]  # no staging folders left
    # No record or report names the worker's temporary copies of the inputs, gone once the job ended.
    assert not [p for p in out.rglob("*.json") if JOB_FOLDER_PREFIX in p.read_text()]

    # A second run does nothing: every job is skipped and no job folder is touched.
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.parent != out}
    assert main(["batch", str(jobs_path), "--out", str(out)]) == 0
    assert "0 done, 3 skipped" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.parent != out} == before


def test_failed_job_is_reported_and_retried_by_the_next_run(tmp_path, capsys):
    jobs = load_jobs(make_inputs(tmp_path / "in", retries=2))
    outcomes = run_batch(jobs, tmp_path / "out", InProcessDispatcher(jobs.settings, AlwaysFailingWorker))
    by_name = {o.name: o for o in outcomes}
    assert by_name["b"].status == "failed" and by_name["b"].attempts == 3
    assert "injected failure" in by_name["b"].error
    assert by_name["a"].status == by_name["c"].status == "done"
    report = json.loads((tmp_path / "out" / "b" / "report.json").read_text())
    assert report["status"] == "failed" and report["attempts"] == 3 and "injected failure" in report["error"]
    assert "| b | failed | 3 |" in (tmp_path / "out" / "summary.md").read_text()
    # The command line says so and exits 1; the next run retries only the failed job.
    assert main(["batch", str(jobs.path), "--out", str(tmp_path / "out")]) == 0
    assert "1 done, 2 skipped" in capsys.readouterr().out
    assert json.loads((tmp_path / "out" / "b" / "report.json").read_text())["status"] == "done"


def test_cli_bad_jobs_file_exits_2(tmp_path, capsys):
    (tmp_path / "jobs.toml").write_text("[[job]]\nname = 'x'\n")
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out")]) == 2
    assert "asset is missing" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_changed_job_runs_again_reusing_its_unchanged_stages(tmp_path, capsys):
    """A job edited since an earlier batch (or whose input files changed) used to be skipped as done, its
    folder then holding another job's results. It runs again, and its earlier stages whose inputs and
    settings are the same travel with it and are reused; an input file touched but not changed is the same."""
    make_inputs(tmp_path)
    jobs_path = tmp_path / "jobs.toml"
    text = ('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
            'stages = ["convert", "light", "compose"]\n[[job]]\nname = "a"\nasset = "ball"\n'
            'overrides = { compose = { shadow_type = "ratio" } }\n')
    jobs_path.write_text(text)
    out = tmp_path / "out"
    args = ["batch", str(jobs_path), "--out", str(out)]

    def statuses() -> dict:
        stages = json.loads((out / "a" / "report.json").read_text())["stages"]["run"]["stages"]
        return {name: stage["status"] for name, stage in stages.items() if name in ("convert", "light", "compose")}

    assert main(args) == 0 and statuses() == {"convert": "ran", "light": "ran", "compose": "ran"}
    capsys.readouterr()
    first = (out / "a" / "compose" / "composite.png").read_bytes()
    photo = tmp_path / "room.png"
    photo.write_bytes(photo.read_bytes())   # touched, not changed: still done
    assert main(args) == 0 and "0 done, 1 skipped" in capsys.readouterr().out

    jobs_path.write_text(text.replace('"ratio"', '"none"'))   # compose's setting only
    assert main(args) == 0
    said = capsys.readouterr()
    assert "1 done, 0 skipped" in said.out and "[a] changed since the earlier run" in said.err
    assert statuses() == {"convert": "reused", "light": "reused", "compose": "ran"}
    assert "; convert, light reused" in said.err   # said, and in the summary
    assert "| a | done | 1 |" in (out / "summary.md").read_text() and "| convert, light |" in (out / "summary.md").read_text()
    assert json.loads((out / "summary.json").read_text())["jobs"][0]["reused"] == ["convert", "light"]
    assert (out / "a" / "compose" / "composite.png").read_bytes() != first   # no shadow now, not the old one
    assert main(args) == 0 and "0 done, 1 skipped" in capsys.readouterr().out

    write_image(photo, np.full((48, 64, 3), 0.4, np.float32))   # another photo under the same name
    assert main(args) == 0 and "1 done, 0 skipped" in capsys.readouterr().out
    assert statuses() == {"convert": "reused", "light": "ran", "compose": "ran"}
    assert main(args + ["--replace"]) == 0   # --replace runs the job again from scratch
    assert statuses() == {"convert": "ran", "light": "ran", "compose": "ran"}


def test_a_job_of_an_obj_takes_its_material_library_and_maps_along(tmp_path, capsys):
    """A job's .obj travelled alone (a .gltf took its whole folder): the worker read it without its .mtl
    and maps, and the batch fitted a flat white where `scenefit convert` fits the texture. Its files now
    travel as the file names them (a map in a subfolder, a link by its own name); one it names outside
    its folder is refused in one sentence before any job (a downloaded asset could name any file)."""
    from asset_builder import write_obj

    from scenefit.core.data.imageio import read_image

    make_inputs(tmp_path)
    rng = np.random.default_rng(3)
    obj = Path(write_obj(tmp_path / "model", uv_sphere(0.5, 16, 8), rng.uniform(0.1, 0.9, (32, 32, 3)).astype(np.float32)))
    (tmp_path / "model" / "lib").mkdir()
    (tmp_path / "model" / "albedo.png").rename(tmp_path / "model" / "lib" / "albedo.png")
    (tmp_path / "model" / "Textures").mkdir()
    (tmp_path / "model" / "Textures" / "albedo.png").symlink_to(Path("..") / "lib" / "albedo.png")
    mtl = tmp_path / "model" / "ball.mtl"
    mtl.write_text(mtl.read_text().replace("map_Kd albedo.png", "map_Kd Textures/albedo.png"))
    (tmp_path / "jobs.toml").write_text('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
                                        'stages = ["convert"]\n[[job]]\nname = "obj"\nasset = "model/ball.obj"\n')
    out = tmp_path / "model" / "runs"   # the batch's folder inside the asset's: not an input of the job
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out), "--quiet"]) == 0
    assert main(["convert", str(obj), "--out", str(tmp_path / "convert"), "--preset", "draft", "--quiet"]) == 0
    batch = read_image(out / "obj" / "convert" / "maps" / "base_color.png")
    alone = read_image(tmp_path / "convert" / "maps" / "base_color.png")
    assert batch.std() > 0.1 and batch.shape == alone.shape and np.abs(batch - alone).max() < 1e-6
    capsys.readouterr()
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]) == 0   # its own results are no input
    assert "0 done, 1 skipped" in capsys.readouterr().out

    secret = tmp_path / "secret.png"
    secret.write_bytes(b"not for the cluster")
    (tmp_path / "model" / "lib" / "leak.png").symlink_to(secret)
    # the asset the jobs file names may itself be a link (its files are what it names, beside the link)
    (tmp_path / "library").mkdir()
    (tmp_path / "library" / "chair.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "model" / "chair.obj").symlink_to(tmp_path / "library" / "chair.obj")
    from scenefit.workers.job_inputs import job_files
    from scenefit.workers.jobs import Job

    assert list(job_files(Job(name="l", asset=tmp_path / "model" / "chair.obj", stages=("convert",)))) == \
        ["asset/chair.obj"]
    for named, shown in (("../secret.png", f"'{secret}'"), (str(secret), f"'{secret}'"),
                         ("lib/leak.png", f"'{tmp_path / 'model' / 'lib' / 'leak.png'}', a link to '{secret}'")):
        mtl.write_text(f"newmtl Ball\nmap_Kd {named}\n")
        assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "elsewhere")]) == 2
        said = capsys.readouterr().err.strip()
        assert f"'ball.obj' reads {shown}, outside its folder" in said and len(said.splitlines()) == 1
        assert not (tmp_path / "elsewhere").exists()


def test_a_blend_job_sends_the_images_it_reads_and_no_others(tmp_path):
    """A .blend's external images (not packed) travel, found by linking its images for a look (the open
    file keeps what it had); other images beside it (photos, renders) do not, so they neither travel nor
    change its digest. An .fbx sends the images beside it whose names it holds."""
    import bpy

    from scenefit.core.data.imageio import write_image
    from scenefit.workers.job_inputs import job_digest, job_files
    from scenefit.workers.jobs import Job

    for name in ("textures/wood.png", "textures/unused.png", "photos/room.png"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        write_image(tmp_path / name, np.full((4, 4, 3), 0.5, np.float32))
    script = (f"import bpy\nbpy.ops.wm.read_factory_settings(use_empty=True)\n"
              f"image = bpy.data.images.load({str(tmp_path / 'textures' / 'wood.png')!r})\nimage.use_fake_user = True\n"
              f"bpy.ops.wm.save_as_mainfile(filepath={str(tmp_path / 'props.blend')!r}, relative_remap=True)\n")
    import subprocess
    subprocess.run([sys.executable, "-c", script], check=True, capture_output=True)
    before = (len(bpy.data.images), len(bpy.data.libraries))
    job = Job(name="a", asset=tmp_path / "props.blend", stages=("convert",))
    files = job_files(job)
    assert sorted(files) == ["asset/props.blend", "asset/textures/wood.png"]
    assert (len(bpy.data.images), len(bpy.data.libraries)) == before   # nothing of the look stays
    digest = job_digest(job, files)
    write_image(tmp_path / "photos" / "room.png", np.full((4, 4, 3), 0.9, np.float32))   # another job's photo
    assert job_digest(job, job_files(job)) == digest
    write_image(tmp_path / "textures" / "wood.png", np.full((4, 4, 3), 0.1, np.float32))  # its own texture
    assert job_digest(job, job_files(job)) != digest

    # a headless batch run in Blender with that .blend open (Blender cannot link from the open file)
    opened = subprocess.run([sys.executable, "-c", f"import bpy\nbpy.ops.wm.open_mainfile(filepath={str(tmp_path / 'props.blend')!r})\n"
                             "from scenefit.workers.job_inputs import job_files\nfrom scenefit.workers.jobs import Job\n"
                             f"print('FILES', sorted(job_files(Job(name='a', asset=__import__('pathlib').Path({str(tmp_path / 'props.blend')!r}), "
                             "stages=('convert',)))))\n"], capture_output=True, text=True)
    assert "FILES ['asset/props.blend', 'asset/textures/wood.png']" in opened.stdout, opened.stderr[-2000:]

    # an .fbx: the images whose whole names it holds ("wood.png", not "unused.png" inside "not_unused.png"),
    # never its own batch's outputs beside it
    (tmp_path / "sofa.fbx").write_bytes(b"Kaydara FBX Binary\x00 Texture::Wood RelativeFilename textures\\wood.png"
                                        b"\x00S\x0e\x00\x00\x00not_unused.png")
    from scenefit.core.base.output_folder import MARKER

    (tmp_path / "runs" / "sofa" / "textures").mkdir(parents=True)
    (tmp_path / "runs" / MARKER).write_text("{}")
    write_image(tmp_path / "runs" / "sofa" / "textures" / "wood.png", np.zeros((4, 4, 3), np.float32))
    files = job_files(Job(name="b", asset=tmp_path / "sofa.fbx", stages=("convert",)))
    assert sorted(files) == ["asset/sofa.fbx", "asset/textures/wood.png"]


def test_blend_tiles_and_frames_and_an_unreadable_blend(tmp_path):
    """A UDIM image's tiles and a sequence's frames travel (the .blend names one file for all); a .blend
    Blender cannot read is one sentence."""
    from scenefit.blender_io.asset_file import _tiles_or_frames, blend_external_files

    for name in ("wall.1001.png", "wall.1002.png", "wall.png", "walls.1003.png", "fire_0001.png", "fire_0002.png"):
        (tmp_path / name).write_bytes(b"x")
    tiles = _tiles_or_frames(tmp_path / "wall.<UDIM>.png", "TILED")
    assert sorted(p.name for p in tiles) == ["wall.1001.png", "wall.1002.png"]
    for name in ("rock_1001_4k.png", "rock_1002_4k.png", "rock_1001_2k.png"):   # digits after the tile's own
        (tmp_path / name).write_bytes(b"x")
    assert sorted(p.name for p in _tiles_or_frames(tmp_path / "rock_<UDIM>_4k.png", "TILED")) == \
        ["rock_1001_4k.png", "rock_1002_4k.png"]
    assert sorted(p.name for p in _tiles_or_frames(tmp_path / "fire_0001.png", "SEQUENCE")) == \
        ["fire_0001.png", "fire_0002.png"]
    (tmp_path / "broken.blend").write_bytes(b"BLENDER-v400 not really")
    with pytest.raises(InputError, match=r"^Blender cannot read '.*broken\.blend' \(.*\); open it in Blender and save "
                                         r"it again\.$"):
        blend_external_files(tmp_path / "broken.blend")


def test_an_earlier_stage_holding_a_link_is_not_sent(tmp_path):
    """Earlier stages travel as files: one holding a link (to anything) would send what it points at, so
    it runs again instead."""
    from scenefit.workers.payload import finished_stage_folders

    for stage in ("convert", "light"):
        (tmp_path / "run" / stage).mkdir(parents=True)
        (tmp_path / "run" / stage / "stage.json").write_text("{}")
    (tmp_path / "secret.txt").write_text("x")
    assert [p.name for p in finished_stage_folders(tmp_path / "run")] == ["convert", "light"]
    (tmp_path / "run" / "light" / "light.exr").symlink_to(tmp_path / "secret.txt")
    assert [p.name for p in finished_stage_folders(tmp_path / "run")] == ["convert"]


def test_a_changed_job_that_fails_keeps_its_earlier_stages_for_the_next_try(tmp_path):
    """A job changed since a done run, failing this time, was written down as failed with nothing else: the
    earlier run's finished stages were lost and the next try ran all of them again."""
    make_inputs(tmp_path)
    text = ('[batch]\nretries = 0\n[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
            'stages = ["convert", "light", "compose"]\n[[job]]\nname = "b"\nasset = "ball"\n'
            'overrides = { compose = { shadow_type = "ratio" } }\n')
    (tmp_path / "jobs.toml").write_text(text)
    out = tmp_path / "out"
    assert [o.status for o in run_batch(load_jobs(tmp_path / "jobs.toml"), out)] == ["done"]
    (tmp_path / "jobs.toml").write_text(text.replace('"ratio"', '"none"'))
    jobs = load_jobs(tmp_path / "jobs.toml")
    assert [o.status for o in run_batch(jobs, out, InProcessDispatcher(jobs.settings, AlwaysFailingWorker))] == ["failed"]
    report = json.loads((out / "b" / "report.json").read_text())
    assert report["status"] == "failed" and report["kept"]["stages"] == ["convert", "camera", "light", "compose"]
    assert [o.status for o in run_batch(jobs, out)] == ["done"]
    stages = json.loads((out / "b" / "report.json").read_text())["stages"]["run"]["stages"]
    assert {name: stages[name]["status"] for name in ("convert", "light", "compose")} == \
        {"convert": "reused", "light": "reused", "compose": "ran"}


def test_an_install_without_reuse_from_is_not_given_it(tmp_path):
    """A worker install from before `scenefit batch --reuse-from` would refuse the whole job over the flag:
    it is asked first, and only one that has it is given it."""
    from scenefit.workers.remote import install_takes_reuse_from

    older = tmp_path / "python"
    older.write_text("#!/bin/sh\necho 'usage: scenefit batch [-h] [--out OUT] [--replace] jobs'\n")
    older.chmod(0o755)
    assert install_takes_reuse_from(sys.executable) and not install_takes_reuse_from(str(older))
    assert not install_takes_reuse_from(str(tmp_path / "missing-python"))


def test_a_convert_job_of_several_materials_fits_them_as_scenefit_convert_does(tmp_path):
    """A batch convert job read the asset as one atlas texture and capped it whole (half the detail per
    material of `scenefit convert`'s: the corpus's ToyCar at a 512² atlas against 1024²); it now fits each
    material in its own cell, and its maps are the command line's."""
    from scenefit.core.data.imageio import read_image, write_image

    make_inputs(tmp_path)
    mesh, rng = uv_sphere(0.5, 16, 8), np.random.default_rng(5)
    folder = tmp_path / "two"
    folder.mkdir()
    for name in ("red", "blue"):
        write_image(folder / f"{name}.png", rng.uniform(0.1, 0.9, (512, 512, 3)).astype(np.float32))   # draft's cap
    (folder / "two.mtl").write_text("newmtl Red\nmap_Kd red.png\nnewmtl Blue\nmap_Kd blue.png\n")
    lines = ["mtllib two.mtl"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    half = len(mesh.faces) // 2
    for material, faces in (("Red", mesh.faces[:half]), ("Blue", mesh.faces[half:])):
        lines += [f"usemtl {material}"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    (folder / "two.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "jobs.toml").write_text('[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
                                        'stages = ["convert"]\n[[job]]\nname = "two"\nasset = "two/two.obj"\n')
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert main(["convert", str(folder / "two.obj"), "--out", str(tmp_path / "convert"), "--preset", "draft",
                 "--quiet"]) == 0
    batch = read_image(tmp_path / "out" / "two" / "convert" / "maps" / "base_color.png")
    alone = read_image(tmp_path / "convert" / "maps" / "base_color.png")
    assert batch.shape == alone.shape == (1024, 1024, 3) and np.abs(batch - alone).max() < 1e-6


def test_a_batch_stopped_half_way_says_which_jobs_it_finished_and_its_summary_matches(tmp_path, monkeypatch, capsys):
    """Ctrl-C half-way through a batch said "'DIR' is unchanged (nothing of this run was written to it)" though
    the jobs finished before it were in DIR, and its summary.md still described the earlier batch."""
    make_inputs(tmp_path)
    out = tmp_path / "out"
    args = ["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]
    assert main(args) == 0
    before = (out / "c" / "report.json").read_text()
    run = JobWorker.run

    def stopped_at_b(self, payload, progress_sink=None):
        if payload.job.name == "b":
            raise KeyboardInterrupt
        return run(self, payload, progress_sink)

    monkeypatch.setattr(JobWorker, "run", stopped_at_b)
    capsys.readouterr()
    assert main(args + ["--replace"]) == 130
    said = capsys.readouterr().err.strip().splitlines()[-1]
    assert said == (f"scenefit: interrupted; the jobs finished before it (a) are in '{out}', each folder whole, the "
                    "others as they were (summary.md says which): run the same command again to run them.")
    summary = json.loads((out / "summary.json").read_text())
    assert [job["status"] for job in summary["jobs"]] == ["done", "interrupted", "interrupted"]
    assert "1 done, 0 skipped (done before), 0 failed, 2 not run (the batch was interrupted)" in \
        (out / "summary.md").read_text()
    assert (out / "c" / "report.json").read_text() == before   # a job not reached is as it was
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]   # nothing half-written beside it


def test_a_job_whose_adapt_was_skipped_says_so_everywhere(tmp_path, capsys):
    """A job that lists adapt on a machine without the weights is done, and its skip is said: the command's
    line for the job, report.json's stage_status (the place a run's report has it), summary.md and .json."""
    make_inputs(tmp_path)
    (tmp_path / "empty-cache").mkdir()   # no weights, whatever this machine holds
    (tmp_path / "jobs.toml").write_text(
        '[models]\ncache_dir = "empty-cache"\n[defaults]\npreset = "draft"\nphoto = "room.png"\nat = [0.5, 0.7]\n'
        'stages = ["convert", "light", "adapt", "compose"]\n[[job]]\nname = "a"\nasset = "ball"\n'
        'overrides = { convert = { iterations = 20 } }\n')
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]) == 0
    said = capsys.readouterr()
    assert "[a] done in" in said.err and "; adapt skipped: no weights" in said.err
    assert "a skipped stages (summary.md says which and why)" in said.out
    report = json.loads((out / "a" / "report.json").read_text())
    assert report["status"] == "done" and report["stage_status"]["adapt"]["status"] == "skipped"
    assert report["stage_status"] == report["stages"]["run"]["stage_status"]   # one shape, as `scenefit run` writes it
    assert "scenefit models download" in report["stage_status"]["adapt"]["why"]
    assert "| a | done, adapt skipped: no weights | 1 |" in (out / "summary.md").read_text()
    assert json.loads((out / "summary.json").read_text())["jobs"][0]["skipped_stages"] == {"adapt": "no weights"}
    # Run again: the job is skipped as done before, and what it skipped is still said.
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(out)]) == 0
    assert "| a | skipped, adapt skipped: no weights |" in (out / "summary.md").read_text()
