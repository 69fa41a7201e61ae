"""Only what the scene needs: each size and representation chosen from the asset and the shot."""
from __future__ import annotations

import json

import numpy as np
import pytest

from scenefit.core.stages.convert import ConvertConfig, choose_resolution
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.data.maps import PBRMaps
from scenefit.core.base.report import write_report
from scenefit.core.stages.convert import convert_and_bake
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.data.scene_needs import constant_channels, envmap_height_for, texture_size_for_screen


def base(size: int = 16) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size] / size
    return np.stack([xx, yy, 0.5 + 0 * xx], -1).astype(np.float32)


def test_constant_channels_stay_constants_and_the_report_says_why(tmp_path):
    # metallic: a map holding 0 everywhere (as the example's); roughness varies.
    rough = (0.2 + 0.6 * base()[..., 0]).astype(np.float32)
    maps = PBRMaps(base(), rough, np.zeros((16, 16), np.float32))
    result, report = convert_and_bake(uv_sphere(segments=12, rings=6), maps, tmp_path / "maps",
                                      stage_config("convert", "draft", iterations=3), keep_constants=True)
    assert report["outputs"]["metallic"] == 0.0 and not (tmp_path / "maps" / "metallic.png").exists()
    assert (tmp_path / "maps" / "roughness.png").is_file()
    channels = report["decisions"]["channels"]
    assert channels["metallic"]["value"] == 0.0 and "one value" in channels["metallic"]["why"]
    assert channels["roughness"]["value"] == "map"
    write_report(tmp_path / "report.json", report)
    assert json.loads((tmp_path / "report.json").read_text())["decisions"]["channels"]["metallic"]["value"] == 0.0


def test_constants_given_as_numbers_stay_numbers():
    decided = constant_channels(PBRMaps(base(), 0.35, 1.0))
    assert decided["roughness"].choice == 0.35 and decided["metallic"].choice == 1.0


def test_texture_size_follows_the_objects_size_on_screen():
    big = PBRMaps(np.zeros((2048, 2048, 3), np.float32))
    size, why = choose_resolution(big, ConvertConfig(screen_px=100))
    assert size == texture_size_for_screen(100) == 256 and "100 px" in why
    # Never more than the asset has or the preset allows, and the user's choice wins.
    assert choose_resolution(PBRMaps(base(64)), ConvertConfig(screen_px=2000))[0] == 64
    assert choose_resolution(big, stage_config("convert", "draft", screen_px=2000))[0] == 512
    assert choose_resolution(big, ConvertConfig(screen_px=100, resolution=1024))[0] == 1024


@pytest.mark.parametrize("roughness, height", [(1.0, 32), (0.5, 32), (0.3, 128), (0.2, 256), (0.0, 256)])
def test_environment_map_size_follows_how_glossy_the_asset_is(roughness, height):
    decision = envmap_height_for(PBRMaps(base(), roughness, 0.0))
    assert decision.choice == height and f"{roughness:.3g}" in decision.reason


def test_the_glossiest_part_of_a_map_decides():
    rough = np.full((16, 16), 0.9, np.float32)
    rough[:4] = 0.15                                  # a quarter of the surface is glossy
    assert envmap_height_for(PBRMaps(base(), rough, 0.0)).choice == 256
    # Texels no triangle uses (padding, here glossy) do not count.
    covered = np.zeros((16, 16), bool)
    covered[4:] = True
    assert envmap_height_for(PBRMaps(base(), rough, 0.0), covered).choice == 32


def test_constants_of_several_materials_are_judged_on_each_materials_own_texels():
    """Every material's roughness exactly 1 is the constant 1, not 'varies 0 to 1' (the atlas's empty
    background once counted); differing values are a map and the reason names each."""
    from scenefit.core.data.scene_needs import material_constant_channels

    a = PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 1.0, 0.0)
    b = PBRMaps(np.full((16, 16, 3), 0.2, np.float32), np.ones((16, 16), np.float32), 0.0)
    same = material_constant_channels([a, b], ["Paint", "Rubber"])
    assert same["roughness"].choice == 1.0 and same["metallic"].choice == 0.0
    c = PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.4, 1.0)
    differ = material_constant_channels([a, c], ["Paint", "Chrome"])
    assert differ["roughness"].choice == "map" and "'Paint' 1" in differ["roughness"].reason
    assert differ["metallic"].choice == "map" and "'Chrome' 1" in differ["metallic"].reason
