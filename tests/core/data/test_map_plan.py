"""A material's maps planned on Blender's main thread and computed in a job (core only): a texture's stored
bytes decode as Blender's image.pixels gives them, a file and the same bytes packed alike; constants are
computed at once and maps later, by named steps; a truncated texture is one sentence naming the image."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import srgb_to_linear, write_image
from scenefit.core.data.map_plan import (Deferred, PendingMaterial, PlannedAsset, TextureFile, later, resolve,
                                         rgba_linear)
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.workers.background import check_plain


def stored(h: int = 6, w: int = 5, c: int = 3) -> np.ndarray:
    return np.random.default_rng(c).integers(0, 256, (h, w, c), dtype=np.uint8)


def test_stored_values_become_blenders_floats_grey_spread_and_alpha_added():
    grey = stored(c=1)
    pixels = rgba_linear(grey, decode_srgb=False)
    assert pixels.shape == (6, 5, 4) and pixels.dtype == np.float32
    assert np.array_equal(pixels[..., 0], grey[..., 0].astype(np.float32) * np.float32(1 / 255))   # Blender's rule
    assert np.array_equal(pixels[..., 2], pixels[..., 0]) and np.all(pixels[..., 3] == 1.0)
    rgb = stored()
    assert np.array_equal(rgba_linear(rgb, True)[..., :3], srgb_to_linear(rgb.astype(np.float32) * np.float32(1 / 255)))


def test_a_file_and_its_packed_bytes_decode_alike(tmp_path):
    values = stored(c=4)
    path = write_image(tmp_path / "t.png", values / 255.0, "uint8")
    from_file = TextureFile(str(path), path=str(path)).pixels()
    from_bytes = TextureFile("packed", packed=path.read_bytes()).pixels()
    assert np.array_equal(from_file, from_bytes)
    assert np.array_equal(from_file[..., 3], values[..., 3].astype(np.float32) * np.float32(1 / 255))   # not premultiplied


def test_a_truncated_packed_texture_is_one_sentence_naming_the_image(tmp_path):
    path = write_image(tmp_path / "t.jpg", np.full((64, 64, 3), 0.5, np.float32), "uint8")
    cut = path.read_bytes()[:200]
    with pytest.raises(InputError) as refused:
        TextureFile("Crate Albedo", packed=cut).pixels()
    said = str(refused.value)
    assert said.startswith("Image 'Crate Albedo' cannot be") and ".jpg" not in said and "\n" not in said, said


def test_constants_are_computed_now_and_maps_later_as_plain_data(tmp_path):
    assert later("product", 0.5, 0.5) == 0.25   # no pixels waited for: computed at once
    path = write_image(tmp_path / "r.png", stored() / 255.0, "uint8")
    texture = TextureFile(str(path), path=str(path), decode_srgb=False)
    roughness = later("clamp", True, later("product", later("convert", later("colour", texture), "float"), 0.5))
    assert isinstance(roughness, Deferred)
    maps = later("pbr_maps", np.full(3, 0.5, np.float32), roughness, 0.0, None)
    sphere = uv_sphere(segments=8, rings=4)
    planned = PlannedAsset(mesh=sphere, materials=(PendingMaterial(name="m", maps=maps),))
    check_plain(planned)   # what a job's worker may hold: no functions, no bpy
    read = planned.resolved().materials[0].maps
    assert isinstance(read, PBRMaps) and read.base_color.shape == (6, 5, 3)   # a constant colour at the map's size
    expected = np.clip(resolve(later("convert", later("colour", texture), "float")) * 0.5, 0.0, 1.0)
    assert np.array_equal(read.roughness, expected)
    assert dataclasses.is_dataclass(roughness) and roughness.step == "clamp"
