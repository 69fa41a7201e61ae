"""`scenefit render --renderer loop|path`: the same views drawn by the adapt stage's loop renderer and by
path tracing, so anyone can compare them; the report names the renderer."""
from __future__ import annotations

import json

import numpy as np

from conftest import scenefit_here
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import read_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere


def test_render_draws_a_view_with_either_renderer(tmp_path):
    yy, xx = np.mgrid[0:32, 0:32] / 31.0
    maps = PBRMaps(base_color=np.stack([0.2 + 0.6 * xx, 0.3 + 0.4 * yy, 0.5 + 0 * xx], -1).astype(np.float32),
                   roughness=np.full((32, 32), 0.6, np.float32), metallic=np.zeros((32, 32), np.float32))
    asset = save_asset_folder(uv_sphere(segments=24, rings=12), maps, tmp_path / "asset")
    images, reports = {}, {}
    for renderer in ("loop", "path"):
        out = tmp_path / renderer
        proc = scenefit_here("render", str(asset), "--out", str(out), "--views", "1", "--size", "48", "--spp", "256",
                             "--renderer", renderer, "--quiet")
        assert proc.returncode == 0, proc.stderr
        images[renderer] = read_image(next(out.glob("view_*.png")))
        reports[renderer] = json.loads((out / "report.json").read_text())
    assert reports["loop"]["renderer"].startswith("loop") and reports["path"]["renderer"].startswith("path")
    # The loop renderer draws the asset alone (black around it); the path tracer shows the white light there.
    asset_pixels = images["loop"].max(axis=2) > 0.02
    assert 0.2 < asset_pixels.mean() < 0.9 and images["path"][~asset_pixels].min() > 0.9
    inside = asset_pixels.copy()     # not the edge pixels, where path blends the asset with the white light
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inside &= np.roll(np.roll(asset_pixels, dy, 0), dx, 1)
    diff = images["loop"][inside] - images["path"][inside]
    assert inside.sum() > 0.6 * asset_pixels.sum() and np.sqrt(np.mean(diff ** 2)) < 0.03
    proc = scenefit_here("render", str(asset), "--out", str(tmp_path / "x"), "--renderer", "raster")
    assert proc.returncode == 2
