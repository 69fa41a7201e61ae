"""The light bench's held-out maps (benchmarks/heldout_hdri.py) come from a JavaScript package: only a plain
EXR data URL is taken from each module (it is never run), the tarball must match its pinned SHA-256, and the
lossy files' negative ringing is clamped. No network here: the package is built by the test."""
from __future__ import annotations

import base64
import io
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
import heldout_hdri  # noqa: E402

from scenefit.core.data.imageio import read_image, write_image


def exr_bytes(tmp_path: Path, pixels: np.ndarray) -> bytes:
    path = tmp_path / "map.exr"
    write_image(path, pixels)
    return path.read_bytes()


def module_text(data: bytes) -> str:
    return f"export default 'data:application/exr;base64,{base64.b64encode(data).decode()}'\n"


def test_a_data_url_module_gives_back_the_exr_it_holds(tmp_path):
    pixels = np.linspace(-2.0, 50.0, 8 * 16 * 3, dtype=np.float32).reshape(8, 16, 3)
    data = exr_bytes(tmp_path, pixels)
    assert heldout_hdri.decode_exr_module(module_text(data)) == data


@pytest.mark.parametrize("text", [
    "export default 'data:application/exr;base64,AAAA'; fetch('http://example.com')\n",   # code after the URL
    "import x from 'y'\nexport default 'data:application/exr;base64,AAAA'\n",                # code before it
    "export default 'data:image/png;base64,AAAA'\n",                                        # not an EXR URL
    "export default 'data:application/exr;base64,QUJDRA=='\n",                              # not EXR bytes
])
def test_anything_but_a_plain_exr_data_url_is_refused(text):
    with pytest.raises(ValueError):
        heldout_hdri.decode_exr_module(text)


def test_the_tarball_is_checked_and_each_map_decoded_with_its_ringing_clamped(tmp_path):
    pixels = np.full((8, 16, 3), 0.5, np.float32)
    pixels[2, 3] = (-4.0, 7.0, 100.0)   # a lossy codec's negative lobe beside a sun
    data = exr_bytes(tmp_path, pixels)
    tarball = tmp_path / "assets.tgz"
    with tarfile.open(tarball, "w:gz") as tar:
        for name in heldout_hdri.HELD_OUT_MAPS:
            body = module_text(data).encode()
            info = tarfile.TarInfo(f"package/hdri/{name}.exr.js")
            info.size = len(body)
            tar.addfile(info, io.BytesIO(body))
    with pytest.raises(ValueError, match="SHA-256"):
        heldout_hdri.check_sha256(tarball)            # not the pinned package
    written = heldout_hdri.maps_from_tarball(tarball, tmp_path / "maps")
    assert sorted(p.stem for p in written) == sorted(heldout_hdri.HELD_OUT_MAPS)
    assert np.array_equal(read_image(written[0])[..., :3], pixels)
    clamped = heldout_hdri.read_heldout(written[0])
    assert clamped.min() == 0.0 and np.allclose(clamped[2, 3], (0.0, 7.0, 100.0))
    assert np.allclose(np.delete(clamped.reshape(-1, 3), 2 * 16 + 3, axis=0), 0.5)
