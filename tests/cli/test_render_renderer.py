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


def _small_asset(tmp_path):
    maps = PBRMaps(base_color=np.full((16, 16, 3), 0.5, np.float32), roughness=0.5, metallic=0.0)
    return save_asset_folder(uv_sphere(segments=12, rings=6), maps, tmp_path / "asset")


def test_a_loop_render_is_sized_against_memory_by_the_loop_renderers_own_cost(tmp_path, monkeypatch):
    """`--renderer loop --size 8192` passed the path tracer's 80 bytes a pixel and crossed half the machine's
    memory; on a machine of 64 GiB the path tracer may draw it, the loop renderer is refused before any work."""
    from scenefit.cli import render as render_command
    from scenefit.core.base import limits

    asset = _small_asset(tmp_path)
    monkeypatch.setattr(limits, "physical_memory", lambda: 64 * 2**30)
    drawn = []
    monkeypatch.setattr(render_command, "_render", lambda *args: drawn.append(args) or 0)
    proc = scenefit_here("render", str(asset), "--out", str(tmp_path / "loop"), "--size", "8192", "--renderer", "loop")
    assert proc.returncode == 2 and "of memory" in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
    assert not drawn and not (tmp_path / "loop").exists()
    assert scenefit_here("render", str(asset), "--out", str(tmp_path / "path"), "--size", "8192").returncode == 0
    assert len(drawn) == 1


def test_environment_maps_of_odd_sizes_give_a_view(tmp_path):
    """A 2x1 map failed in Mitsuba's sampling table (Distribution2D) with a traceback; one channel and a texel
    of 1e30 give a view too."""
    from scenefit.core.data.imageio import write_image

    asset = _small_asset(tmp_path)
    huge = np.full((8, 16, 3), 0.5, np.float32)
    huge[3, 5] = 1e30
    maps = {"two_by_one.exr": np.full((1, 2, 3), 0.8, np.float32), "grey.exr": np.full((8, 16, 1), 0.8, np.float32),
            "huge.exr": huge}
    for name, pixels in maps.items():
        write_image(tmp_path / name, pixels)
        for renderer in ("loop", "path"):
            out = tmp_path / f"{name}_{renderer}"
            proc = scenefit_here("render", str(asset), "--out", str(out), "--envmap", str(tmp_path / name), "--size",
                                 "24", "--views", "1", "--spp", "4", "--renderer", renderer, "--quiet")
            assert proc.returncode in (0, 2) and "Traceback" not in proc.stderr, proc.stderr
            if proc.returncode == 0:
                view = read_image(next(out.glob("view_*.png")))
                assert view.shape[:2] == (24, 24) and np.isfinite(view).all()
            else:
                assert proc.stderr.count("\n") == 1, proc.stderr
    assert (tmp_path / "two_by_one.exr_loop").is_dir()   # the 2x1 map gives a view


RENDER_OPTIONS = {"--size": ["0", "-3", "7", "8193", "1e3", "abc", "99999999999999999999", "16"],
                  "--views": ["0", "-1", "1", "3", "100000000", "2.5", "nan"],
                  "--spp": ["0", "1", "4", "1000000000000", "x"],
                  "--elevation": ["-90", "90", "89.9", "nan", "inf", "1e308", "10"],
                  "--exposure": ["0", "-1", "inf", "1e308", "1e-300", "2"],
                  "--renderer": ["loop", "path", "raster"], "--ambient": ["-1", "nan", "1e30", "0", "3"]}


def test_fuzz_render_options_give_views_or_one_sentence(tmp_path, monkeypatch):
    """Random render options (the renderers stubbed: the options' reading, the cameras, the envmap and the
    files are what is tried) give views or one sentence, never a traceback or a run that will not end."""
    from hypothesis import HealthCheck, given, settings, strategies as st

    from scenefit.cli import render as render_command
    from scenefit.core.texture import views as texture_views

    asset = _small_asset(tmp_path)

    def stub(normalized, stacks, env, cameras, *args, **kwargs):
        images = [np.zeros((c.height, c.width, 3), np.float32) for c in cameras]
        return {label: images for label in stacks} if isinstance(stacks, dict) else images

    monkeypatch.setattr(render_command, "_loop_views", lambda normalized, stack, env, cameras, normal_map:
                        stub(normalized, stack, env, cameras))
    monkeypatch.setattr(texture_views, "render_views", stub)
    runs = iter(range(10**6))

    @settings(derandomize=True, max_examples=60, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
    @given(st.dictionaries(st.sampled_from(sorted(RENDER_OPTIONS)), st.none(), min_size=1, max_size=4), st.data())
    def fuzz(chosen, data):
        args = [a for option in chosen for a in (option, data.draw(st.sampled_from(RENDER_OPTIONS[option])))]
        proc = scenefit_here("render", str(asset), "--out", str(tmp_path / f"out{next(runs)}"), "--quiet", *args)
        assert proc.returncode in (0, 2) and "Traceback" not in proc.stderr, (args, proc.stderr[-2000:])
        assert proc.returncode == 0 or proc.stderr.strip().count("\n") <= 1, (args, proc.stderr)

    fuzz()


def test_a_loop_view_traced_in_chunks_is_the_same_view(tmp_path, monkeypatch):
    """The G-buffer is traced in chunks (so Ctrl-C stops it): cut into a dozen chunks, a view is the one traced
    whole but for the light rays' noise."""
    from scenefit.core.render import gbuffer

    asset = _small_asset(tmp_path)
    images = []
    for chunk in (gbuffer.CHUNK_SAMPLES, 4096):
        monkeypatch.setattr(gbuffer, "CHUNK_SAMPLES", chunk)
        out = tmp_path / f"chunk{chunk}"
        proc = scenefit_here("render", str(asset), "--out", str(out), "--views", "1", "--size", "56", "--renderer",
                             "loop", "--quiet")
        assert proc.returncode == 0, proc.stderr
        images.append(read_image(next(out.glob("view_*.png"))))
    assert 56 * 56 * 16 > 12 * 4096
    assert np.sqrt(np.mean((images[0] - images[1]) ** 2)) < 0.02 and images[0].max() > 0.2


def test_ctrl_c_during_a_large_loop_render_stops_within_seconds(tmp_path):
    """A 768-px view's 9.4 million samples were traced in one Mitsuba kernel that Ctrl-C cannot stop: 38-41 s."""
    import signal
    import subprocess
    import sys
    import time

    from conftest import ROOT

    asset = _small_asset(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "scenefit.cli", "render", str(asset), "--renderer", "loop",
                             "--size", "768", "--views", "1", "--out", str(tmp_path / "out"), "--quiet"],
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    time.sleep(12)   # past the imports, inside the view's tracing
    asked = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    try:
        err = proc.communicate(timeout=120)[1]
    finally:
        proc.kill()
    stopped = time.perf_counter() - asked
    assert proc.returncode == 130 and "interrupted" in err, err[-2000:]
    assert stopped < 15, f"stopped {stopped:.1f} s after Ctrl-C"
    assert not (tmp_path / "out").exists()
