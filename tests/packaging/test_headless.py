"""The docs' headless batch recipe (docs/technical/headless.md), run as written: the extension installed
from its zip, a .blend holding two objects, a jobs file naming them (`asset = "props.blend"`, `object = ...`); run twice, the
second run does no work. (`blender -b --python-expr X` is bpy imported, then X.)"""
import json
import os
import re
import subprocess
import sys

import pytest

pytestmark = pytest.mark.blender

from conftest import ROOT  # noqa: E402

JOBS = """
[defaults]
asset = "props.blend"
photo = "room.png"
at = [0.5, 0.7]
preset = "draft"
stages = ["convert", "light"]
overrides = { convert = { iterations = 20 }, light = { map_height = 16 } }
[[job]]
name = "sofa-room"
object = "Sofa"
[[job]]
name = "table-room"
object = "Table"
"""

SETUP = r"""
import sys
from pathlib import Path
import numpy as np
import bpy

tmp, zip_path = Path(sys.argv[1]), sys.argv[2]
bpy.ops.extensions.package_install_files(repo="user_default", filepath=zip_path, enable_on_install=True)
bpy.ops.wm.save_userpref()
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
sofa = bpy.context.active_object
sofa.name = "Sofa"
image = bpy.data.images.new("sofa_color", 16, 16)
pixels = np.ones((16, 16, 4), np.float32)
pixels[..., :3] = np.random.default_rng(0).uniform(0.1, 0.9, (16, 16, 3))
image.pixels.foreach_set(pixels.ravel())
image.pack()
mat = bpy.data.materials.new("Leather")
tex = mat.node_tree.nodes.new("ShaderNodeTexImage"); tex.image = image
mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
sofa.data.materials.append(mat)
bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
table = bpy.context.active_object
table.name = "Table"
wood = bpy.data.materials.new("Wood")
wood.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.4, 0.25, 0.1, 1.0)
table.data.materials.append(wood)
bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "props.blend"))
photo = bpy.data.images.new("room", 64, 48)
photo.pixels.foreach_set(np.random.default_rng(1).uniform(0.2, 0.8, 64 * 48 * 4).astype(np.float32))
photo.filepath_raw, photo.file_format = str(tmp / "room.png"), "PNG"
photo.save()
"""


def readme_batch_recipe() -> str:
    """The Python expression of the docs' `blender -b --python-expr "..."` batch line."""
    text = (ROOT / "docs" / "technical" / "headless.md").read_text()
    match = re.search(r'^blender -b --python-expr "(.*?)"$', text, re.MULTILINE)
    assert match, "docs/technical/headless.md has no one-line headless batch recipe"
    return match.group(1)


def test_readme_batch_recipe_runs_blend_objects_and_skips_finished_jobs(tmp_path):
    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension

    zip_path = build_extension.build_without_wheels(tmp_path / "scenefit.zip")
    (tmp_path / "user").mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    made = subprocess.run([sys.executable, "-c", SETUP, str(tmp_path), str(zip_path)], capture_output=True, text=True,
                          env=env, timeout=300)
    assert made.returncode == 0, made.stderr[-3000:]
    (tmp_path / "jobs.toml").write_text(JOBS)
    recipe = "import bpy\n" + readme_batch_recipe()   # what `blender -b --python-expr` runs

    def run() -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", recipe], capture_output=True, text=True, env=env,
                              cwd=tmp_path, timeout=600)

    first = run()
    assert first.returncode == 0, first.stdout[-2000:] + first.stderr[-3000:]
    assert "batch: 2 done, 0 skipped" in first.stdout
    runs = tmp_path / "runs"
    for name, obj in (("sofa-room", "Sofa"), ("table-room", "Table")):
        report = json.loads((runs / name / "report.json").read_text())
        assert report["status"] == "done" and report["job"]["object"] == obj
        assert report["job"]["asset"] == str(tmp_path / "props.blend")
        assert (runs / name / "convert" / "maps" / "base_color.png").is_file()
        assert (runs / name / "light" / "light.exr").is_file()
        # Above what one flat colour scores on the sofa's random 0.1-0.9 texture (about 12.7 dB).
        assert report["quality"]["convert_psnr_db"] > 13.0
    # The two objects are different assets: their fitted colour maps differ.
    sofa, table = ((runs / n / "convert" / "maps" / "base_color.png").read_bytes() for n in ("sofa-room", "table-room"))
    assert sofa != table
    assert "| sofa-room | done |" in (runs / "summary.md").read_text()

    before = {p: p.stat().st_mtime_ns for p in runs.rglob("*") if p.is_file() and p.parent != runs}
    second = run()
    assert second.returncode == 0, second.stderr[-3000:]
    assert "batch: 0 done, 2 skipped" in second.stdout
    assert {p: p.stat().st_mtime_ns for p in runs.rglob("*") if p.is_file() and p.parent != runs} == before


def operator_recipe() -> str:
    """The Python expression of the docs' `blender -b scene.blend --python-expr "..."` operator recipe."""
    text = (ROOT / "docs" / "technical" / "headless.md").read_text()
    match = re.search(r'^blender -b scene\.blend --python-expr "\n(.*?)\n"$', text, re.MULTILINE | re.DOTALL)
    assert match, "docs/technical/headless.md has no operator recipe"
    return match.group(1)


def test_the_operator_recipe_runs_as_written_without_the_weights(tmp_path):
    """The docs' operator recipe in a session like `blender -b scene.blend` with the extension installed, on a
    machine without Stable Diffusion 2's weights (an empty Hugging Face cache): Adapt stops at once with the
    sentence that says how to get them, everything else finishes and the file is saved."""
    import shutil

    import cv2

    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension

    zip_path = build_extension.build_without_wheels(tmp_path / "scenefit.zip")
    (tmp_path / "user").mkdir()
    (tmp_path / "hub").mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), HF_HUB_CACHE=str(tmp_path / "hub"))
    made = subprocess.run([sys.executable, "-c", SETUP, str(tmp_path), str(zip_path)], capture_output=True, text=True,
                          env=env, timeout=300)
    assert made.returncode == 0, made.stderr[-3000:]
    shutil.copy(tmp_path / "props.blend", tmp_path / "scene.blend")
    cv2.imwrite(str(tmp_path / "swamp.jpg"), cv2.imread(str(tmp_path / "room.png")))
    before = (tmp_path / "scene.blend").stat().st_mtime_ns
    # What `blender -b scene.blend` does before the expression: the enabled extensions, then the file.
    recipe = ("import bpy, addon_utils\naddon_utils.enable('bl_ext.user_default.scenefit', default_set=True)\n"
              "bpy.ops.wm.open_mainfile(filepath='scene.blend')\n" + operator_recipe())
    proc = subprocess.run([sys.executable, "-c", recipe], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=1200)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "scenefit models download" in proc.stdout and "Stable Diffusion 2" in proc.stdout
    assert (tmp_path / "scene.blend").stat().st_mtime_ns != before
