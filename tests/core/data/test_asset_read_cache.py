"""A run folder keeps what Blender read from a glTF or OBJ asset (core/data/asset_read_cache.py): the same
arrays come back under the same key, and any change to the files, the object or the reader's code is
another key."""
from __future__ import annotations

import numpy as np

from scenefit.core.data.asset_read_cache import CACHE_FILE, load_read, read_key, save_read
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import Mesh
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.pipeline.run import asset_digest


def two_material_asset() -> tuple[Mesh, PBRMaps]:
    sphere = uv_sphere(0.5, 12, 6)
    rng = np.random.default_rng(1)
    mesh = Mesh(positions=sphere.positions, faces=sphere.faces, uvs=sphere.uvs * 3.0 - 1.0, normals=sphere.normals,
                name="Chair", material_index=(np.arange(len(sphere.faces)) % 2).astype(np.int32),
                wraps=(("repeat", "mirror"), ("clamp", "clamp")), atlas=True)
    maps = PBRMaps(base_color=rng.uniform(size=(8, 16, 3)).astype(np.float32), roughness=0.25,
                   metallic=rng.uniform(size=(8, 16)).astype(np.float32),
                   normal=rng.uniform(size=(4, 4, 3)).astype(np.float32))
    return mesh, maps


def test_a_kept_read_comes_back_exactly_under_its_key_only(tmp_path):
    mesh, maps = two_material_asset()
    assert save_read(tmp_path, None, mesh, maps) is None and not (tmp_path / CACHE_FILE).exists()
    save_read(tmp_path, "k1", mesh, maps)
    again_mesh, again_maps = load_read(tmp_path, "k1")
    assert asset_digest(again_mesh, again_maps) == asset_digest(mesh, maps)   # what the convert stage's key uses
    assert (again_mesh.name, again_mesh.wraps, again_mesh.atlas) == ("Chair", mesh.wraps, True)
    assert np.array_equal(again_mesh.material_index, mesh.material_index) and np.array_equal(again_maps.normal,
                                                                                               maps.normal)
    assert again_maps.roughness == 0.25 and isinstance(again_maps.metallic, np.ndarray)
    assert load_read(tmp_path, "k2") is None and load_read(tmp_path / "elsewhere", "k1") is None
    (tmp_path / CACHE_FILE).write_bytes(b"PK\x03\x04 not a whole archive")
    assert load_read(tmp_path, "k1") is None


def test_the_key_changes_with_every_file_the_asset_reads_and_the_object(tmp_path):
    (tmp_path / "ball.mtl").write_text("newmtl Ball\nmap_Kd albedo.png\n")
    (tmp_path / "albedo.png").write_bytes(b"first")
    obj = tmp_path / "ball.obj"
    obj.write_text("mtllib ball.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    key = read_key(obj, None)
    assert key is not None and read_key(obj, None) == key and read_key(obj, "Ball") != key
    (tmp_path / "albedo.png").write_bytes(b"second")            # a texture changed: read the asset again
    assert read_key(obj, None) != key
    (tmp_path / "model.fbx").write_bytes(b"Kaydara FBX Binary  \x00")
    assert read_key(tmp_path / "model.fbx", None) is None       # its external images are not all known
    assert read_key(tmp_path / "missing.glb", None) is None


def test_the_key_follows_every_module_the_reader_reaches(tmp_path):
    """The reader's code in the key is the import graph from Blender's reader, not a hand-kept list
    (which had missed the UV rasteriser and the asset path checks): on a small tree, modules reached
    at module level, in a function, relatively and through a package's __init__ are in; the rest out."""
    from scenefit.core.data.asset_read_cache import READER
    from scenefit.core.base.source_graph import ROOT, reachable_sources

    files = {
        "blender_io/__init__.py": "",
        "blender_io/asset_file.py": "from ..core.data import mesh\n\ndef read():\n    from ..core.data.uv_raster import r\n",
        "core/__init__.py": "", "core/data/__init__.py": "", "core/data/mesh.py": "import numpy\n",
        "core/data/uv_raster.py": "from ..base.errors import E\n", "core/base/__init__.py": "", "core/base/errors.py": "",
        "core/stages/__init__.py": "", "core/stages/compose.py": "from ..data.mesh import Mesh\n",
        "cli/__init__.py": "from ..blender_io import asset_file\n",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    got = {str(p.relative_to(tmp_path)) for p in reachable_sources("blender_io.asset_file", root=tmp_path)}
    assert got == {"blender_io/__init__.py", "blender_io/asset_file.py", "core/__init__.py", "core/data/__init__.py",
                   "core/data/mesh.py", "core/data/uv_raster.py", "core/base/__init__.py", "core/base/errors.py"}
    # and on the project itself
    real = {str(p.relative_to(ROOT)) for p in reachable_sources(READER)}
    assert {"blender_io/asset_file.py", "blender_io/fbx_ascii.py", "core/data/gltf_meshopt.py", "core/data/mesh.py",
            "core/data/uv_raster.py"} <= real and "core/stages/compose.py" not in real and "cli/run.py" not in real
