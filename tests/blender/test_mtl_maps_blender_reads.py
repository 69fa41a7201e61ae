"""What a job sends of an OBJ, and the asset-read cache's key, are the files Blender's OBJ importer reads:
an MTL naming a map by every keyword (refl, as older exporters write metallic, among them) is imported by
Blender itself, and every image it loaded must be among core.data.asset_files' list (which job_files and
read_key both take)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from conftest import printed_json, run_python
from scenefit.core.data.asset_files import asset_files
from scenefit.core.data.asset_read_cache import read_key
from scenefit.core.data.imageio import write_image
from scenefit.workers.job_inputs import job_files
from scenefit.workers.jobs import Job

KEYWORDS = ["map_Kd", "map_Ka", "map_Ks", "map_Ns", "map_d", "refl", "map_refl", "map_Ke", "map_Bump", "map_bump",
            "bump", "map_Pr", "map_Pm", "map_Ps", "map_Pc", "map_Pcr", "map_Pa", "norm", "disp", "decal"]


def obj_asset(folder: Path, lines: list[str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "thing.obj").write_text("mtllib thing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                      "usemtl Paint\nf 1/1 2/2 3/3\n")
    (folder / "thing.mtl").write_text("newmtl Paint\nKd 0.8 0.8 0.8\n" + "".join(f"{line}\n" for line in lines))
    return folder / "thing.obj"


def test_a_refl_metallic_map_travels_with_the_job_and_keys_the_read(tmp_path):
    obj = obj_asset(tmp_path / "asset", ["map_Kd base.png", "refl -type sphere metal.png"])
    for name in ("base.png", "metal.png"):
        write_image(obj.parent / name, np.full((4, 4, 3), 0.5, np.float32))
    files = job_files(Job(name="j", asset=obj, stages=("convert",)))
    assert "asset/metal.png" in files and "asset/base.png" in files
    key = read_key(obj, None)
    write_image(obj.parent / "metal.png", np.full((4, 4, 3), 0.9, np.float32))
    assert read_key(obj, None) != key   # the metallic map changed: Blender's read is not reused


def test_every_image_blenders_importer_reads_is_in_the_assets_files(tmp_path):
    objs = {}
    for word in KEYWORDS:   # an asset per keyword: two keywords of one slot would hide one another
        objs[word] = obj_asset(tmp_path / word, [f"{word} -s 1 1 1 {word.lower()}.png"])
        write_image(objs[word].parent / f"{word.lower()}.png", np.full((4, 4, 3), 0.5, np.float32))
    proc = run_python(f"""
import json, bpy
read = {{}}
for word, obj in {json.dumps({w: str(o) for w, o in objs.items()})}.items():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.obj_import(filepath=obj)
    read[word] = sorted(bpy.path.abspath(i.filepath) for i in bpy.data.images if i.filepath)
print("JSON", json.dumps(read))
""")
    read_by_blender = printed_json(proc)
    assert read_by_blender["refl"] and read_by_blender["map_Kd"] and not read_by_blender["decal"], read_by_blender
    for word, images in read_by_blender.items():
        listed = set(asset_files(objs[word]))
        assert {Path(p).resolve() for p in images} <= listed, (word, images)
