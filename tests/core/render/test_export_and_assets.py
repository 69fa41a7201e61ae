"""Mitsuba scene export, asset folders and synthetic photos."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import torch

from scenefit.core.data.asset_io import load_asset_folder, save_asset_folder
from scenefit.core.render.orbit_camera import Camera
from scenefit.core.base.errors import InputError
from scenefit.core.render.export import export_mitsuba_scene
from scenefit.core.data.imageio import linear_to_srgb, read_image, srgb_to_linear
from scenefit.core.data.maps import PBRMaps
from scenefit.core.render.photo import develop_photo, perspective_view, studiolight_path
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.renderer import AssetRenderer, SceneOptions
from scenefit.core.scene.camera import PhotoCamera
from scenefit.core.scene.frame import blender_direction_to_equirect_uv


def striped_maps(h: int = 32, w: int = 64) -> PBRMaps:
    base = np.zeros((h, w, 3), np.float32)
    base[..., 0] = np.linspace(0.05, 0.9, w)[None]
    base[..., 1] = np.linspace(0.9, 0.1, h)[:, None]
    base[..., 2] = 0.3
    rough = np.tile(np.linspace(0.2, 0.9, w, dtype=np.float32), (h, 1))
    # Round-trip through 8-bit sRGB so the export's quantisation is not what the test measures.
    base = srgb_to_linear(np.round(linear_to_srgb(base) * 255) / 255)
    return PBRMaps(base_color=base, roughness=rough, metallic=0.0)


def test_exported_scene_renders_alone_like_the_live_scene(tmp_path):
    mesh, maps = uv_sphere(), striped_maps()
    cam = Camera(azimuth_deg=40, elevation_deg=20, width=48, height=48)
    env = np.full((16, 32, 3), 0.8, np.float32)
    env[:4] = 3.0
    xml = export_mitsuba_scene(mesh, maps, tmp_path / "scene", camera=cam, envmap=env, spp=64)
    assert {p.name for p in xml.parent.iterdir()} >= {"scene.xml", "mesh.ply", "base_color.png", "roughness.png", "envmap.exr"}
    ET.parse(xml)  # well-formed

    # A fresh interpreter that knows nothing of SceneFit renders the folder with Mitsuba alone.
    code = (
        "import sys, numpy as np, mitsuba as mi; mi.set_variant('scalar_rgb');"
        "img = mi.render(mi.load_file(sys.argv[1]), spp=64); np.save(sys.argv[2], np.array(img))"
    )
    out_npy = tmp_path / "alone.npy"
    subprocess.run([sys.executable, "-c", code, str(xml), str(out_npy)], check=True, timeout=300)
    alone = np.load(out_npy)[..., :3]

    renderer = AssetRenderer(mesh, maps.resolution, env, SceneOptions(integrator_type="path", max_depth=8))
    live = renderer.render(cam, torch.tensor(maps.base_color), torch.tensor(maps.channel("roughness"))[..., None],
                           torch.zeros(*maps.resolution, 1), torch.tensor(env), spp=64, seed=0).rgb.numpy()
    assert alone.shape == live.shape
    # Same picture up to Monte Carlo noise: compare blurred images.
    import cv2
    blur = lambda im: cv2.GaussianBlur(im, (7, 7), 2)
    assert np.abs(blur(alone) - blur(live)).mean() < 0.02 * live.mean()


def test_export_keeps_the_assets_size_and_frames_it_like_the_normalised_render(tmp_path):
    from scenefit.core.data.mesh import Mesh
    import mitsuba as mi

    small = uv_sphere(radius=0.5)
    big = Mesh.from_arrays(small.positions * 40.0 + np.array([100.0, -20.0, 5.0]), small.faces, small.uvs, small.normals)
    cam = Camera(azimuth_deg=10, elevation_deg=20, width=32, height=32)
    images = []
    for name, mesh in (("small", small), ("big", big)):
        xml = export_mitsuba_scene(mesh, striped_maps(), tmp_path / name, camera=cam, spp=16)
        scene = mi.load_file(str(xml))
        assert np.allclose(np.array(scene.shapes()[0].bbox().max), mesh.positions.max(0), rtol=1e-4, atol=1e-3)
        images.append(np.array(mi.render(scene, spp=16)))
    assert np.abs(images[0] - images[1]).mean() < 0.01


def test_asset_folder_round_trip(tmp_path):
    mesh, maps = uv_sphere(segments=12, rings=6), striped_maps()
    folder = save_asset_folder(mesh, maps, tmp_path / "asset")
    mesh2, maps2 = load_asset_folder(folder)
    assert np.array_equal(mesh.positions, mesh2.positions) and np.array_equal(mesh.faces, mesh2.faces)
    assert np.array_equal(mesh.uvs, mesh2.uvs)
    assert np.abs(maps2.base_color - maps.base_color).max() < 1e-3
    assert np.abs(maps2.roughness - maps.roughness).max() < 1 / 65535 + 1e-6
    assert maps2.metallic == 0.0


def test_loading_something_that_is_not_an_asset_folder_says_so(tmp_path):
    with pytest.raises(InputError, match="not a SceneFit asset folder"):
        load_asset_folder(tmp_path)


def test_photo_looks_where_the_camera_points():
    env = np.zeros((32, 64, 3), np.float32)
    u, v = blender_direction_to_equirect_uv(np.array([0.0, 1.0, 0.0]))  # +Y
    env[int(v * 32) - 1:int(v * 32) + 1, int(u * 64) - 1:int(u * 64) + 1] = 10.0
    ahead = perspective_view(env, PhotoCamera(yaw_deg=90, pitch_deg=0, fov_deg=40, width=32, height=32))
    behind = perspective_view(env, PhotoCamera(yaw_deg=-90, pitch_deg=0, fov_deg=40, width=32, height=32))
    assert ahead[12:20, 12:20].max() > 5 and behind.max() == 0


def test_developed_photo_clips_highlights_like_a_camera():
    hdr = read_image(studiolight_path("interior"))[..., :3]
    view = perspective_view(hdr, PhotoCamera(width=96, height=64))
    photo = develop_photo(view)
    assert photo.dtype == np.uint8 and photo.shape == (64, 96, 3)
    assert 40 < photo.mean() < 200
    # Brightness is exposure-normalised: a 100x brighter scene gives the same photo.
    assert np.abs(develop_photo(view * 100).astype(int) - photo.astype(int)).max() <= 1


def test_several_materials_export_as_shapes_that_each_read_their_own_maps_wrapped_as_their_sampler_says(tmp_path):
    """Three materials whose UVs tile about 3.8 times, each wrapped its own way: the exported scene, loaded
    by Mitsuba alone, shows each material's own texels where an atlas would reach into its neighbour's."""
    import mitsuba as mi
    from scenefit.core.render.export import LookAt
    from material_scenes import banded_plane, expected_albedo

    asset = banded_plane([("repeat", "repeat"), ("mirror", "mirror"), ("clamp", "clamp")])
    mesh, maps = asset.fitting_view()
    camera = LookAt(origin=(0.0, -2.5, 0.0), target=(0.0, 0.0, 0.0), fov_deg=24.0, width=96, height=96)
    xml = export_mitsuba_scene(mesh, maps, tmp_path / "scene", camera=camera, spp=1)
    assert {"mesh_0.ply", "mesh_2.ply", "base_color_1.png"} <= {p.name for p in xml.parent.iterdir()}
    integrator = mi.load_dict({"type": "aov", "aovs": "albedo:albedo,p:position,d:depth"})
    image = np.array(mi.render(mi.load_file(str(xml)), integrator=integrator, spp=1), dtype=np.float64)
    hit = image[..., 6] > 0
    expected, clear = expected_albedo(asset, image[..., 3:6][hit])
    error = np.abs(image[..., 0:3][hit] - expected).max(axis=1)[clear]
    assert len(error) > 3000
    # 8-bit sRGB images: a few thousandths; a neighbour's texels or another wrap mode: tenths.
    assert np.quantile(error, 0.99) < 0.02, np.quantile(error, [0.5, 0.99])


def test_a_downloaded_gltf_folder_means_its_one_gltf(tmp_path):
    from scenefit.core.data.asset_io import resolve_asset_path

    folder = tmp_path / "ToyCar"
    folder.mkdir()
    for name in ("ToyCar.gltf", "ToyCar.bin", "ToyCar_basecolor.png", "SOURCE_README.md"):
        (folder / name).write_bytes(b"x")
    assert resolve_asset_path(folder) == folder / "ToyCar.gltf"
    (folder / "ToyCar.glb").write_bytes(b"x")
    with pytest.raises(InputError, match="holds 2 asset files \\(ToyCar.glb, ToyCar.gltf\\); give the one"):
        resolve_asset_path(folder)
    converted = save_asset_folder(uv_sphere(segments=8, rings=4), striped_maps(), tmp_path / "asset")
    (converted / "extra.glb").write_bytes(b"x")
    assert resolve_asset_path(converted) == converted           # an asset folder is itself
    assert resolve_asset_path(tmp_path / "empty") == tmp_path / "empty"


def test_the_command_line_takes_the_folder_a_gltf_came_in(tmp_path, monkeypatch, capsys):
    import scenefit.cli.render as render_command
    from scenefit.cli import main

    folder = tmp_path / "Fox"
    folder.mkdir()
    (folder / "Fox.glb").write_bytes(b"glTF")
    (folder / "SOURCE_LICENSE.md").write_text("CC-BY")
    seen = []
    monkeypatch.setattr(render_command, "run", lambda args: seen.append(args.asset) or 0)
    assert main(["render", str(folder), "--out", str(tmp_path / "out")]) == 0
    assert seen == [str(folder / "Fox.glb")]
    assert "using Fox.glb" in capsys.readouterr().err
    (tmp_path / "nothing").mkdir()
    assert main(["render", str(tmp_path / "nothing"), "--out", str(tmp_path / "out")]) == 2
    assert "not a SceneFit asset folder" in capsys.readouterr().err and len(seen) == 1
