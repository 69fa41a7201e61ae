"""An asset folder, or an OBJ's material library, from elsewhere may hold a FIFO (reading it waits for
ever), a socket or a link to nothing: a job, a batch's payload and the readers refuse it in one sentence
naming it, before anything is packed or read; a map that simply is missing stays a missing map."""
from __future__ import annotations

import os
import socket

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.asset_files import asset_files
from scenefit.core.data.imageio import write_image
from scenefit.workers.payload import make_payload
from scenefit.workers.jobs import Job

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")


def folder_asset(tmp_path):
    folder = tmp_path / "chair"
    folder.mkdir()
    write_image(folder / "base_color.png", np.full((4, 4, 3), 0.5, np.float32))
    return folder


def obj_asset(tmp_path, map_name: str):
    folder = tmp_path / "asset"
    folder.mkdir()
    (folder / "thing.obj").write_text("mtllib thing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "thing.mtl").write_text(f"newmtl Paint\nmap_Kd {map_name}\n")
    return folder / "thing.obj"


def one_sentence(error, *words):
    text = str(error)
    assert "\n" not in text and text.endswith("."), text
    for word in words:
        assert word in text, (word, text)


@pytest.mark.parametrize("plant, kind", [
    (lambda p: os.mkfifo(p), "a FIFO"),
    (lambda p: os.symlink(p.parent / "gone.png", p), "a link to nothing"),
    (lambda p: socket.socket(socket.AF_UNIX).bind(str(p)), "a socket"),
])
def test_a_special_file_in_an_asset_folder_is_one_sentence_before_packing(tmp_path, plant, kind):
    folder = folder_asset(tmp_path)
    plant(folder / "extra.png")
    with pytest.raises(InputError) as caught:
        make_payload(Job(name="j", asset=folder, stages=("convert",)))
    one_sentence(caught.value, "Job 'j'", "extra.png", kind)
    with pytest.raises(InputError):
        asset_files(folder)


def test_a_fifo_named_as_a_map_is_one_sentence_and_a_missing_map_stays_missing(tmp_path):
    obj = obj_asset(tmp_path, "pipe.png")
    os.mkfifo(obj.parent / "pipe.png")
    with pytest.raises(InputError) as caught:
        make_payload(Job(name="j", asset=obj, stages=("convert",)))
    one_sentence(caught.value, "pipe.png", "a FIFO")
    (obj.parent / "pipe.png").unlink()
    os.symlink(obj.parent / "gone.png", obj.parent / "pipe.png")
    assert [p.name for p in asset_files(obj)] == ["thing.mtl", "thing.obj"]   # as a map that is not there
