"""A run folder's .asset-read.npz is data from wherever the folder came from: one that inflates past a
gigabyte, whose headers ask for more than they hold, whose JSON is of another shape, or whose bytes are
mutated is no copy (None: Blender reads the asset again), never an exception or a runaway allocation."""
from __future__ import annotations

import io
import json
import struct
import zipfile
import zlib

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from conftest import printed_json, run_python
from scenefit.core.data.asset_read_cache import CACHE_FILE, load_read, save_read
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere

META = {"key": "k", "name": "Chair", "wraps": [["repeat", "repeat"]], "atlas": False, "roughness": 0.5,
        "metallic": 0.0}


def saved_copy(folder):
    sphere = uv_sphere(0.5, 8, 4)
    maps = PBRMaps(base_color=np.full((8, 8, 3), 0.5, np.float32), roughness=0.5, metallic=0.0)
    return save_read(folder, "k", sphere, maps)


def npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def zeros_member(name: str, header: bytes, count: int) -> tuple[bytes, int, int, bytes]:
    """(deflated bytes, inflated size, CRC-32, name) of `header` and `count` zero bytes, made without
    compressing them all: a deflate stream fully flushed after each zero block repeats that block's bytes."""
    block = bytes(2**24)
    deflate = zlib.compressobj(9, zlib.DEFLATED, -15)
    head = deflate.compress(header) + deflate.flush(zlib.Z_FULL_FLUSH)
    repeated = deflate.compress(block) + deflate.flush(zlib.Z_FULL_FLUSH)
    crc = zlib.crc32(header)
    for _ in range(count // len(block)):
        crc = zlib.crc32(block, crc)
    return head + repeated * (count // len(block)) + deflate.flush(), len(header) + count, crc, name.encode()


def write_zip(path, members: list[tuple[bytes, int, int, bytes]]) -> None:
    """A zip of already deflated members (zipfile compresses what it writes, which here takes minutes)."""
    with open(path, "wb") as out:
        central = b""
        for data, size, crc, name in members:
            offset = out.tell()
            fields = struct.pack("<HHHHHIII", 20, 0, 8, 0, 0, crc, len(data), size)
            out.write(b"PK\x03\x04" + fields + struct.pack("<HH", len(name), 0) + name + data)
            central += (b"PK\x01\x02" + struct.pack("<H", 20) + fields
                        + struct.pack("<HHHHHII", len(name), 0, 0, 0, 0, 0, offset) + name)
        start = out.tell()
        out.write(central + b"PK\x05\x06" + struct.pack("<HHHHIIH", 0, 0, len(members), len(members), len(central),
                                                         start, 0))


def plain_member(name: str, data: bytes) -> tuple[bytes, int, int, bytes]:
    deflate = zlib.compressobj(9, zlib.DEFLATED, -15)
    return deflate.compress(data) + deflate.flush(), len(data), zlib.crc32(data), name.encode()


def test_a_copy_inflating_past_a_gigabyte_is_refused_without_inflating_it(tmp_path):
    path = tmp_path / CACHE_FILE
    sphere = uv_sphere(0.5, 8, 4)
    count = 9 * 2**27   # 1.125 GiB of float32 zeros: about a megabyte on disk
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (count // 12, 3)})
    write_zip(path, [plain_member("meta.npy", npy(np.array(json.dumps(META))))]
              + [plain_member(f"{name}.npy", npy(getattr(sphere, name))) for name in ("positions", "faces", "uvs")]
              + [zeros_member("base_color.npy", header.getvalue(), count)])
    with zipfile.ZipFile(path) as archive:   # a well-formed archive, its first block as numpy writes it
        assert archive.getinfo("base_color.npy").file_size > 2**30
        assert archive.open("base_color.npy").read(2**20).startswith(header.getvalue())
    assert path.stat().st_size < 8 * 2**20
    proc = run_python(f"""
import json, resource
from scenefit.core.data.asset_read_cache import load_read
before_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
found = load_read({str(tmp_path)!r}, "k")
grown_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - before_mb
print("JSON", json.dumps({{"found": found is not None, "grown_mb": grown_mb}}))
""")
    result = printed_json(proc)
    # The peak grows by less than a quarter of the array (1152 MB), whatever the imports themselves take.
    assert not result["found"] and result["grown_mb"] < 288, result


def test_a_header_asking_for_more_than_it_holds_is_no_copy(tmp_path):
    path = saved_copy(tmp_path)
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (10**12, 3)})
    members["base_color.npy"] = header.getvalue() + b"\0" * 64
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    assert load_read(tmp_path, "k") is None


def test_meta_of_another_shape_or_non_finite_arrays_are_no_copy(tmp_path):
    path = saved_copy(tmp_path)
    assert load_read(tmp_path, "k") is not None
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    for meta in ([], dict(META, wraps=[["sideways", "repeat"]]), dict(META, wraps="x"), dict(META, name=None),
                 "{" * 10_000):
        replaced = dict(members, **{"meta.npy": npy(np.array(meta if isinstance(meta, str) else json.dumps(meta)))})
        with zipfile.ZipFile(path, "w") as archive:
            for name, data in replaced.items():
                archive.writestr(name, data)
        assert load_read(tmp_path, "k") is None, meta
    faces = np.load(io.BytesIO(members["faces.npy"]))
    for name, array in (("positions.npy", np.full((5, 3), np.nan, np.float32)),
                        ("faces.npy", faces.astype(np.float64) + 0.5),   # float faces: no copy, however whole
                        ("faces.npy", faces.astype(np.float32))):
        with zipfile.ZipFile(path, "w") as archive:
            for member, data in dict(members, **{name: npy(array)}).items():
                archive.writestr(member, data)
        assert load_read(tmp_path, "k") is None, (name, array.dtype)


@settings(derandomize=True, max_examples=100, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.data())
def test_fuzz_mutated_copies_read_whole_or_not_at_all(tmp_path, data):
    folder = tmp_path / "run"
    folder.mkdir(exist_ok=True)
    raw = bytearray(saved_copy(folder).read_bytes())
    for _ in range(data.draw(st.integers(1, 6))):
        at = data.draw(st.integers(0, len(raw) - 1))
        raw[at] = data.draw(st.integers(0, 255))
    (folder / CACHE_FILE).write_bytes(bytes(raw))
    found = load_read(folder, "k")
    assert found is None or (len(found) == 2 and np.isfinite(found[0].positions).all())
