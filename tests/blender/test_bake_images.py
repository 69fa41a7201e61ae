"""The images a bake writes into the exporter: the exact baked bytes, shared between materials that bake
to the same pixels, and at zlib's highest level only where the file ships those PNG bytes."""
import pytest

from conftest import printed_json

pytestmark = pytest.mark.blender

SCRIPT = r"""
import json, tempfile
from pathlib import Path
import numpy as np
import bpy
from scenefit.blender_io.gltf_export import BakeImages

bpy.ops.wm.read_factory_settings(use_empty=True)
yy, xx = np.mgrid[0:256, 0:256]
rng = np.random.default_rng(0)
pixels = np.stack([xx, yy, (xx + yy) // 2], -1) + rng.integers(0, 6, (256, 256, 3))   # gradients with grain
pixels = np.clip(pixels, 0, 255).astype(np.uint8)
out = {}
for ships in (True, False):
    images = BakeImages(Path(tempfile.mkdtemp()), ships_png=ships)
    image = images.load(f"ships_{ships}", pixels, "sRGB")
    again = images.load(f"again_{ships}", pixels.copy(), "sRGB")
    other = images.load(f"other_{ships}", 255 - pixels, "sRGB")
    read = np.array(image.pixels[:], np.float32).reshape(256, 256, 4)[::-1, :, :3]   # Blender's rows: bottom first
    out[str(ships)] = {"bytes": len(image.packed_file.data), "exact": bool((np.round(read * 255) == pixels).all()),
                       "shared": again is image, "other": other is not image, "png": image.file_format}
print("JSON" + json.dumps(out))
"""


def test_baked_images_are_exact_shared_and_smallest_only_where_the_png_ships(run_py):
    out = printed_json(run_py(SCRIPT))
    shipped, reencoded = out["True"], out["False"]
    for case in (shipped, reencoded):
        assert case["exact"] and case["shared"] and case["other"] and case["png"] == "PNG", case
    # Level 9 where the file carries these bytes; the faster level where the exporter re-encodes them.
    assert shipped["bytes"] < reencoded["bytes"], out
