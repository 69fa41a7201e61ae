"""The loop renderer: G-buffers traced once by Mitsuba, shaded in torch with exact gradients.

Checked against known answers (Mitsuba's bilinear taps and wrap modes), against autograd's own
numerical Jacobian (gradients exact to the texture), against a fresh computation of the stored BRDF
tables, the pre-filtered light map against its lobes' integrals summed texel by texel, and against
Mitsuba's `path` integrator on a textured sphere (agreement in dB).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.base.errors import InputError
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.brdf_tables import brdf_tables, compute_tables
from scenefit.core.render.gbuffer import GBufferOptions, PrefilteredEnvironment, bilinear_taps
from scenefit.core.render.loop_renderer import LoopRenderer, shade
from scenefit.core.render.orbit_camera import Camera
from scenefit.core.render.renderer import AssetRenderer, SceneOptions
from scenefit.core.texture.views import image_psnr, tonemap_srgb


def checker_maps(size: int = 32) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size]
    maps = np.zeros((size, size, 5), np.float32)
    maps[..., 0:3] = np.where(((xx // 4 + yy // 4) % 2)[..., None] == 0, [0.8, 0.3, 0.2], [0.2, 0.5, 0.9])
    maps[..., 3] = np.linspace(0.05, 0.95, size)[None, :]
    maps[..., 4] = (yy >= size // 2)
    return maps


@pytest.fixture(scope="module")
def sphere_scene():
    mesh = uv_sphere(segments=48, rings=24)
    env = np.ones((16, 32, 3), np.float32)
    loop = LoopRenderer(mesh, (32, 32), env, SceneOptions(max_depth=2, hide_emitters=True),
                        gbuffer=GBufferOptions(samples=4, diffuse_rays=4, specular_rays=2, edge_samples=16))
    return mesh, env, loop


def test_bilinear_taps_follow_mitsuba_wrap_modes():
    # A 2 x 4 image: u = 0 sits on the left edge, halfway between texel -1 (wrapped: 3) and texel 0.
    taps, weights = bilinear_taps(np.array([[0.0, 0.25], [0.375, 0.75]]), (2, 4), "repeat")
    assert taps[0, :, 0].tolist() == [3, 0, 3, 0] and taps[0, :, 1].tolist() == [0, 0, 1, 1]
    np.testing.assert_allclose(weights[0], [0.5, 0.5, 0.0, 0.0])
    assert taps[1, 0].tolist() == [1, 1] and np.isclose(weights[1, 0], 1.0)   # a texel centre: one tap
    clamp, _ = bilinear_taps(np.array([[0.0, 1.0]]), (2, 4), "clamp")
    assert clamp[0, :, 0].tolist() == [0, 0, 0, 0] and clamp[0, :, 1].tolist() == [1, 1, 1, 1]
    mirror, _ = bilinear_taps(np.array([[-0.375, 0.5]]), (2, 4), "mirror")   # x = -2, -1: texels 1, 0 mirrored
    assert mirror[0, :, 0].tolist() == [1, 0, 1, 0]


def test_stored_tables_are_mitsubas_principled_bsdf():
    stored = brdf_tables()
    fresh = compute_tables(stored.shape[1], 512)     # fewer samples: noisier, same expectation
    assert np.abs(stored - fresh).mean() < 0.005 and np.abs(stored - fresh).max() < 0.05
    d, s, a, b = stored
    assert np.all(d[1:] > 0.4) and np.all(s >= 0) and np.all(a[1:] + b[1:] <= 1.02)
    assert abs(a[-1, 0] + b[-1, 0] - 1.0) < 0.02     # a smooth white metal head-on reflects everything


def test_gradients_are_exact(sphere_scene):
    mesh, env, loop = sphere_scene
    camera = Camera(20, 10, 1.1, width=12, height=12)
    gb, colour = loop.gbuffer(camera, torch.from_numpy(env))
    tables = torch.from_numpy(brdf_tables()).double()
    rng = np.random.default_rng(1)
    stack = np.concatenate([rng.uniform(0.1, 0.9, (32, 32, 3)), rng.uniform(0.3, 0.34, (32, 32, 1)),
                            rng.uniform(0.2, 0.8, (32, 32, 1))], -1)
    maps = torch.from_numpy(stack).requires_grad_(True)
    # fast_mode: the Jacobian checked along random directions of all 5120 texel values at once.
    assert torch.autograd.gradcheck(lambda m: shade(gb, m, colour.double(), tables)[0], (maps,), eps=1e-6,
                                    atol=1e-5, rtol=1e-3, fast_mode=True)
    shade(gb, maps, colour.double(), tables)[0].sum().backward()
    touched = (maps.grad.abs().sum(-1) > 0).sum().item()
    assert 0 < touched < 32 * 32     # the texels the view sees, and only those


def test_agrees_with_mitsuba_path_tracing(sphere_scene):
    mesh, env, loop = sphere_scene
    camera = Camera(30, 15, 1.1, width=64, height=64)
    maps = torch.from_numpy(checker_maps())
    split = (maps[..., 0:3], maps[..., 3:4], maps[..., 4:5])
    traced = loop.traced
    out = loop.render(camera, *split, torch.from_numpy(env))
    path = AssetRenderer(mesh, (32, 32), env, SceneOptions(max_depth=2, hide_emitters=True, integrator_type="path"))
    with torch.no_grad():
        ref = path.render(camera, *split, torch.from_numpy(env), spp=512, seed=3)
    psnr = image_psnr(tonemap_srgb(out.rgb.numpy()), tonemap_srgb(ref.rgb.numpy()))
    assert psnr >= 35.0, psnr
    assert np.abs(out.alpha.numpy() - ref.alpha.numpy()).mean() < 0.01
    # The metallic half (rows below the middle of the texture) is not the dielectric one: shading is live.
    flipped = torch.from_numpy(checker_maps()[..., [0, 1, 2, 3, 4]].copy())
    flipped[..., 4] = 1 - flipped[..., 4]
    other = loop.render(camera, flipped[..., 0:3], flipped[..., 3:4], flipped[..., 4:5], torch.from_numpy(env))
    assert image_psnr(tonemap_srgb(other.rgb.numpy()), tonemap_srgb(ref.rgb.numpy())) < 30.0
    assert loop.traced == traced + 1 and loop.reused >= 1     # the view was traced once, then reused


def test_each_sample_reads_the_texture_a_pixel_covers():
    """A texture finer than the pixels (a one-texel checker of metal and rough dielectric, 2 texels per
    pixel): the path tracer averages what each pixel covers. The default 16 samples per pixel, each shaded
    with its own texture values, come closer to it than 4 did (the setting that cost the corpus's ambient
    views 7 dB, benchmarks/FINDINGS.md)."""
    mesh = uv_sphere(segments=48, rings=24)
    env = np.ones((16, 32, 3), np.float32)
    yy, xx = np.mgrid[0:64, 0:64]
    odd = ((xx + yy) % 2 == 0)[..., None]
    maps = torch.from_numpy(np.concatenate([np.where(odd, [0.9, 0.8, 0.7], [0.1, 0.2, 0.3]), np.where(odd, 0.05, 0.9),
                                            odd.astype(np.float64)], -1).astype(np.float32))
    split = (maps[..., 0:3], maps[..., 3:4], maps[..., 4:5])
    camera = Camera(30, 15, 1.1, width=32, height=32)
    path = AssetRenderer(mesh, (64, 64), env, SceneOptions(max_depth=2, hide_emitters=True, integrator_type="path"))
    with torch.no_grad():
        ref = tonemap_srgb(path.render(camera, *split, torch.from_numpy(env), spp=1024, seed=3).rgb.numpy())
    psnr = {}
    for samples, rays in ((4, 16), (16, 4)):   # the same 64 diffuse rays per pixel
        loop = LoopRenderer(mesh, (64, 64), env, SceneOptions(max_depth=2, hide_emitters=True),
                            gbuffer=GBufferOptions(samples=samples, diffuse_rays=rays))
        psnr[samples] = image_psnr(tonemap_srgb(loop.render(camera, *split, torch.from_numpy(env)).rgb.numpy()), ref)
    assert GBufferOptions().samples == 16
    assert psnr[16] > psnr[4] + 1.0 and psnr[16] > 33.0, psnr


def test_a_view_under_a_light_map_is_traced_with_the_map_settings_and_ambient_views_with_their_own():
    mesh = uv_sphere(segments=16, rings=8)
    ambient = np.ones((8, 16, 3), np.float32)
    light_map = np.full((8, 16, 3), 0.5, np.float32)
    light_map[2, 5] = 40.0
    options = GBufferOptions(samples=9, diffuse_rays=2, map_samples=4, map_diffuse_rays=3, specular_rays=1)
    loop = LoopRenderer(mesh, (8, 8), ambient, SceneOptions(max_depth=2, hide_emitters=True), gbuffer=options)
    camera = Camera(30, 15, 1.1, width=8, height=8)
    assert loop.gbuffer(camera, torch.from_numpy(ambient))[0].samples == 9
    assert loop.gbuffer(camera, torch.from_numpy(light_map))[0].samples == 4
    assert options.for_light(False) == GBufferOptions(samples=4, diffuse_rays=3, map_samples=4, map_diffuse_rays=3,
                                                      specular_rays=1)
    with pytest.raises(InputError, match="square"):
        GBufferOptions(map_samples=5)


def _brute_force_tables(env: np.ndarray, node: np.ndarray, roughness: float) -> tuple[np.ndarray, np.ndarray]:
    """The cosine lobe's and a GGX lobe's light about unit `node`, summed texel by texel in float64."""
    from scenefit.core.scene.frame import equirect_directions

    h, w = env.shape[:2]
    dirs = equirect_directions(h, w).reshape(-1, 3).astype(np.float64)
    elevation = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
    solid = np.repeat(np.cos(elevation) * (np.pi / h) * (2 * np.pi / w), w)
    light = env.reshape(-1, 3).astype(np.float64) * solid[:, None]
    cos = dirs @ node
    diffuse = np.clip(cos, 0, None) @ light / np.pi
    a2 = max(1e-3, roughness ** 2) ** 2
    cos_h2 = np.clip((1 + cos) / 2, 0, None)
    weight = np.clip(cos, 0, None) / (cos_h2 * (a2 - 1) + 1) ** 2 / np.maximum(np.sqrt(cos_h2), 1e-6)
    return diffuse, weight @ light / (weight @ solid)


def test_prefiltered_tables_are_the_lobes_integrals_of_the_map():
    rng = np.random.default_rng(4)
    env = rng.uniform(0.05, 1.0, (16, 32, 3)).astype(np.float32)
    env[3, 7] = 60.0                                          # a sun: the lobes must weigh it right
    tables = PrefilteredEnvironment(None, env, grid=(8, 16))
    t, a = (np.arange(8) + 0.5) / 8 * np.pi, (np.arange(16) + 0.5) / 16 * 2 * np.pi
    for i, j in ((0, 0), (2, 5), (4, 11), (7, 15)):
        node = np.array([np.sin(t[i]) * np.cos(a[j]), np.sin(t[i]) * np.sin(a[j]), np.cos(t[i])])
        for roughness in (0.2, 0.6, 1.0):
            diffuse, specular = _brute_force_tables(env, node, roughness)
            np.testing.assert_allclose(tables.diffuse(node[None])[0], diffuse, rtol=1e-4)   # a node reads its own value
            np.testing.assert_allclose(tables.specular(node[None], roughness)[0], specular, rtol=1e-4)
    # Under a constant sky every lobe sees the sky's radiance.
    sky = PrefilteredEnvironment(None, np.full((16, 32, 3), [0.5, 1.0, 2.0], np.float32), grid=(8, 16))
    up = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, -0.8]])
    np.testing.assert_allclose(sky.specular(up, 0.4), [[0.5, 1.0, 2.0]] * 2, rtol=1e-4)
    np.testing.assert_allclose(sky.diffuse(up), [[0.5, 1.0, 2.0]] * 2, rtol=0.02)   # the grid's quadrature
    with pytest.raises(ValueError, match="roughness 0.3"):
        sky.specular(up, 0.3)


def test_views_under_one_light_map_share_its_prefiltered_tables(monkeypatch):
    import scenefit.core.render.loop_renderer as loop_module
    from scenefit.core.render.gbuffer import trace_gbuffer
    from scenefit.core.render.renderer import ENVMAP_KEY, pad_envmap

    built = []

    class Counted(PrefilteredEnvironment):
        def __init__(self, *args, **kwargs):
            built.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(loop_module, "PrefilteredEnvironment", Counted)
    mesh = uv_sphere(segments=16, rings=8)
    light_map = np.full((8, 16, 3), 0.5, np.float32)
    light_map[2, 5] = 40.0
    options = GBufferOptions(samples=4, diffuse_rays=2, map_samples=4, map_diffuse_rays=2, specular_rays=1)
    loop = LoopRenderer(mesh, (8, 8), light_map, SceneOptions(max_depth=2, hide_emitters=True), gbuffer=options)
    views = [Camera(azimuth, 15, 1.1, width=8, height=8) for azimuth in (0, 90, 180)]
    shared = [loop.gbuffer(camera, torch.from_numpy(light_map))[0] for camera in views]
    assert len(built) == 1 and loop.traced == 3
    other = light_map.copy()
    other[5, 12] = 20.0
    loop.gbuffer(views[0], torch.from_numpy(other))
    assert len(built) == 2                                   # a new map: its own tables
    # Kept tables change nothing: the last view traced afresh, its tables built for it alone, is the same.
    loop.tracer.params[ENVMAP_KEY] = pad_envmap(torch.from_numpy(light_map)).numpy()   # the scene lit by the first map again
    loop.tracer.params.update()
    fresh = trace_gbuffer(loop.tracer, views[2], options, None, light_map, False)
    for kept, new in zip(shared[2].tensors(), fresh.tensors()):
        assert torch.equal(kept, new)
