"""`basisu` is an external tool: however it fails (an error exit, a crash by signal, no file, a file that
is not KTX2, a file that is no program), --textures ktx2 ends in one sentence naming it and the way round
(--textures png). The stand-ins are real executables that fail as a broken install does."""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.stages.bake.gltf_ktx2 import encode_ktx2


def png_bytes(tmp_path) -> bytes:
    from scenefit.core.data.imageio import write_image

    return write_image(tmp_path / "src.png", np.full((6, 6, 3), 0.5, np.float32)).read_bytes()


def executable(tmp_path, body: str):
    path = tmp_path / "basisu"
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


@pytest.mark.skipif(os.name != "posix", reason="shell-script stand-ins")
@pytest.mark.parametrize("body, words", [
    ("echo 'Error: Failed loading image file' >&2; exit 1", ("exit status 1", "Failed loading image file")),
    ("kill -SEGV $$", ("exit status -11",)),
    ("exit 0", ("wrote no file",)),
    ('for a; do last="$a"; done; echo "<html>" > "$last"', ("not a KTX2 file",)),
    (None, ("cannot be started",)),
])
def test_basisu_failing_is_one_sentence(tmp_path, monkeypatch, body, words):
    if body is None:
        path = tmp_path / "basisu"
        path.write_bytes(b"\x7fELF not really a program")
        path.chmod(0o755)
    else:
        path = executable(tmp_path, body)
    monkeypatch.setenv("SCENEFIT_BASISU", str(path))
    work = tmp_path / "work"
    work.mkdir()
    with pytest.raises(InputError) as caught:
        encode_ktx2(png_bytes(tmp_path), ".png", "colour", work)
    text = str(caught.value)
    assert "\n" not in text and "--textures png" in text and str(path) in text, text
    for word in words:
        assert word in text, (word, text)
