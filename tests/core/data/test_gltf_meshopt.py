"""EXT_meshopt_compression files are decoded before Blender imports them (its importer has no decoder)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenefit.core.data.glb import read_gltf, write_glb
from scenefit.core.data.gltf_meshopt import decoded_glb, encoded_glb, importable, uses_meshopt
from conftest import ROOT


def plain_glb(path: Path) -> Path:
    """A quad strip: float positions (vec3), UVs (vec2), uint16 triangles, as an exporter writes them."""
    rng = np.random.default_rng(3)
    positions = rng.normal(size=(40, 3)).astype(np.float32)
    uvs = rng.uniform(size=(40, 2)).astype(np.float32)
    indices = np.array([[i, i + 1, i + 2] for i in range(38)], np.uint16).ravel()
    parts = [positions.tobytes(), uvs.tobytes(), indices.tobytes()]
    offsets = np.cumsum([0] + [len(p) for p in parts])
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 40, "type": "VEC3",
             "min": positions.min(0).tolist(), "max": positions.max(0).tolist()},
            {"bufferView": 1, "componentType": 5126, "count": 40, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": len(indices), "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteOffset": int(offsets[i]), "byteLength": len(p),
                         "target": 34963 if i == 2 else 34962} for i, p in enumerate(parts)],
        "buffers": [{"byteLength": int(offsets[-1])}]}
    write_glb(path, document, b"".join(parts))
    return path


def view_bytes(path: Path) -> list[bytes]:
    document, chunk = read_gltf(path)
    return [chunk[v.get("byteOffset", 0):][:v["byteLength"]] for v in document["bufferViews"]]


def canonical(indices: bytes) -> list[tuple[int, ...]]:
    """Each uint16 triangle with its smallest corner first (the winding kept)."""
    triangles = np.frombuffer(indices, np.uint16).reshape(-1, 3)
    return [tuple(np.roll(t, -int(np.argmin(t)))) for t in triangles.tolist()]


def test_meshopt_views_decode_to_the_bytes_they_were_made_from(tmp_path):
    plain = plain_glb(tmp_path / "plain.glb")
    packed = encoded_glb(plain, tmp_path / "packed.glb")
    assert uses_meshopt(packed) and not uses_meshopt(plain)
    decoded = decoded_glb(packed, tmp_path / "decoded.glb")
    got, want = view_bytes(decoded), view_bytes(plain)
    assert got[:2] == want[:2]  # the vertex attributes, bit for bit
    assert canonical(got[2]) == canonical(want[2])  # the same triangles (the codec may rotate one's corners)
    document, _ = read_gltf(decoded)
    assert "extensionsUsed" not in document and document["buffers"] == [{"byteLength": document["buffers"][0]
                                                                          ["byteLength"]}]


def test_a_plain_file_is_imported_as_it_is(tmp_path):
    plain = plain_glb(tmp_path / "plain.glb")
    with importable(plain) as readable:
        assert readable == plain


def test_meshopt_data_that_does_not_decode_is_one_sentence(tmp_path):
    from scenefit.core.base.errors import InputError

    packed = encoded_glb(plain_glb(tmp_path / "plain.glb"), tmp_path / "packed.glb")
    document, chunk = read_gltf(packed)
    write_glb(packed, document, bytes(len(chunk)))  # the compressed bytes zeroed
    with pytest.raises(InputError, match=r"^The EXT_meshopt_compression data of 'packed.glb' does not decode .*; "
                                         r"check the file with the Khronos glTF validator\.$"):
        with importable(packed):
            pass


@pytest.mark.blender
def test_a_required_extension_blender_lacks_is_named_and_never_called_a_broken_file(tmp_path):
    import json
    import subprocess
    import sys

    plain = plain_glb(tmp_path / "plain.glb")
    document, chunk = read_gltf(plain)
    document["extensionsUsed"] = document["extensionsRequired"] = ["EXT_made_up"]
    write_glb(plain, document, chunk)
    proc = subprocess.run([sys.executable, "-m", "scenefit.cli", "convert", str(plain), "--out", str(tmp_path / "c"),
                           "--quiet"], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)
    assert proc.returncode == 2, proc.stderr[-1500:]
    assert "requires the glTF extension EXT_made_up, which Blender's importer does not read" in proc.stderr
    assert "export it again" not in proc.stderr, json.dumps(proc.stderr)
