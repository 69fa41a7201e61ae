"""The Mitsuba rendering core against known answers."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from scenefit.core.render.orbit_camera import Camera, fov_from_multiplier, whole_object_multiplier
from scenefit.core.base.errors import InputError
from scenefit.core.data.mesh import Mesh, normalize_to_unit_sphere
from scenefit.core.data.primitives import grid_plane, uv_sphere
from scenefit.core.render.renderer import AssetRenderer, SceneOptions, SphereSpec
from scenefit.core.scene.frame import blender_direction_to_equirect_uv, equirect_directions, look_frame

TEX = (32, 32)


def constant_maps(color=0.5, roughness=0.5, metallic=0.0):
    h, w = TEX
    return (torch.full((h, w, 3), color), torch.full((h, w, 1), roughness), torch.full((h, w, 1), metallic))


def constant_env(value: float, height: int = 16) -> np.ndarray:
    return np.full((height, 2 * height, 3), value, np.float32)


def test_render_is_finite_and_repeatable_for_a_fixed_seed():
    renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
    env = torch.tensor(constant_env(1.0))
    cam = Camera(azimuth_deg=30, elevation_deg=20, width=48, height=48)
    a = renderer.render(cam, *constant_maps(), env, spp=4, seed=7).rgb
    b = renderer.render(cam, *constant_maps(), env, spp=4, seed=7).rgb
    c = renderer.render(cam, *constant_maps(), env, spp=4, seed=8).rgb
    assert torch.isfinite(a).all()
    assert torch.equal(a, b)
    assert not torch.equal(a, c)


@pytest.mark.parametrize("radiance", [1e-3, 0.7, 1e3])
def test_white_diffuse_sphere_under_constant_light_renders_to_that_light(radiance):
    # A convex white Lambertian surface under uniform radiance L reflects exactly L in every
    # direction (no interreflection), so every pixel of the apparatus is L: from very dark to very bright.
    sphere = SphereSpec(center=(3.0, 0.0, 0.0), radius=0.4, albedo=1.0)
    renderer = AssetRenderer(uv_sphere(radius=0.1), TEX, constant_env(radiance), SceneOptions(sphere=sphere))
    cam = Camera(azimuth_deg=0, elevation_deg=0, width=32, height=32, target=sphere.center)
    out = renderer.render(cam, *constant_maps(), torch.tensor(constant_env(radiance)), spp=64, seed=1)
    covered = out.alpha[..., 0] > 0.999
    assert covered.float().mean() > 0.3
    pixels = out.rgb[covered]
    assert torch.allclose(pixels.mean(), torch.tensor(radiance), rtol=0.01)
    # Per pixel only Monte Carlo noise remains (64 spp, MIS with envmap sampling): a few percent.
    relative_error = ((pixels - radiance).abs() / radiance).flatten()
    assert relative_error.median() < 0.04
    assert relative_error.max() < 0.15


def test_gradients_reach_maps_and_environment():
    renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
    base, rough, metal = (t.clone().requires_grad_(True) for t in constant_maps())
    env = torch.tensor(constant_env(1.0), requires_grad=True)
    out = renderer.render(Camera(width=32, height=32), base, rough, metal, env, spp=8, seed=3)
    out.rgb.mean().backward()
    for name, tensor in (("base", base), ("roughness", rough), ("environment", env)):
        assert tensor.grad is not None, name
        assert torch.isfinite(tensor.grad).all(), name
        assert tensor.grad.abs().sum() > 0, name
    # Brighter base colour and brighter light both brighten the image.
    assert base.grad.sum() > 0 and env.grad.sum() > 0


def test_each_variant_takes_torch_tensors_from_its_own_device():
    """dr.wrap hands CUDA tensors to Dr.Jit's CUDA backend and CPU ones to LLVM; the renderer moves its
    inputs to its variant's side (the first GPU run failed on a CPU environment map beside a CUDA texture)."""
    from scenefit.core.render.backend import Backend

    assert Backend("cuda_ad_rgb", "", None).torch_device == "cuda"
    assert Backend("llvm_ad_rgb", "", None).torch_device == "cpu"


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_maps_on_the_gpu_and_a_map_of_light_on_the_cpu_render_together():
    renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
    base, rough, metal = (t.cuda().requires_grad_(True) for t in constant_maps())
    env = torch.tensor(constant_env(1.0))
    out = renderer.render(Camera(width=16, height=16), base, rough, metal, env, spp=4, seed=0)
    assert out.rgb.device == base.device
    out.rgb.mean().backward()
    assert base.grad is not None and base.grad.abs().sum() > 0


def test_a_second_render_before_backward_is_refused_not_silently_wrong():
    renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
    base = constant_maps()[0].clone().requires_grad_(True)
    env = torch.tensor(constant_env(1.0))
    first = renderer.render(Camera(width=16, height=16), base, *constant_maps()[1:], env, spp=2, seed=0)
    with pytest.raises(RuntimeError, match="waiting for backward"):
        renderer.render(Camera(azimuth_deg=90, width=16, height=16), base, *constant_maps()[1:], env, spp=2, seed=1)
    first.rgb.sum().backward()
    assert base.grad is not None and base.grad.abs().sum() > 0
    # After backward, and after dropping a result without backward, rendering goes on.
    second = renderer.render(Camera(azimuth_deg=90, width=16, height=16), base, *constant_maps()[1:], env, spp=2, seed=1)
    del second
    with torch.no_grad():
        renderer.render(Camera(width=16, height=16), base, *constant_maps()[1:], env, spp=2, seed=2)


def test_a_dropped_renderer_is_freed_at_once_not_by_the_cycle_collector():
    """A renderer no longer referenced (after a differentiable render and its backward) is freed by
    reference counting: while its Mitsuba objects live, every later scene's kernels dispatch to them too,
    so they differ from the cached ones and compile again."""
    import gc
    import weakref

    gc.collect()
    gc.disable()
    try:
        renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
        base = constant_maps()[0].clone().requires_grad_(True)
        out = renderer.render(Camera(width=8, height=8), base, *constant_maps()[1:],
                              torch.tensor(constant_env(1.0)), spp=1)
        out.rgb.sum().backward()
        gone = weakref.ref(renderer)
        del renderer, out
        assert gone() is None
    finally:
        gc.enable()


def test_uv_convention_top_of_texture_lands_on_top_of_plane():
    # OpenGL UVs (v = 0 at the bottom) with an image whose top rows are red: the plane's top is red.
    renderer = AssetRenderer(grid_plane(size=0.9), TEX, constant_env(1.0))
    h, w = TEX
    base = torch.zeros(h, w, 3)
    base[: h // 2, :, 0] = 1.0   # top half of the image red
    base[h // 2:, :, 2] = 1.0    # bottom half blue
    out = renderer.render(Camera(width=32, height=32), base, torch.ones(h, w, 1), torch.zeros(h, w, 1),
                          torch.tensor(constant_env(1.0)), spp=4, seed=0).rgb
    top, bottom = out[8], out[24]
    assert top[16, 0] > 3 * top[16, 2]
    assert bottom[16, 2] > 3 * bottom[16, 0]


def test_environment_lights_from_the_direction_blender_would():
    # A small bright disc around world +X in Blender's mapping must light the sphere's +X side.
    env = constant_env(0.01, height=32)
    directions = equirect_directions(*env.shape[:2])
    env[directions @ np.array([1.0, 0.0, 0.0]) > np.cos(np.radians(12))] = 200.0
    renderer = AssetRenderer(uv_sphere(), TEX, env)
    cam = Camera(azimuth_deg=0, elevation_deg=0, width=48, height=48)  # looks along +Y; +X is image right
    out = renderer.render(cam, *constant_maps(color=0.8, roughness=1.0), torch.tensor(env), spp=32, seed=0)
    normals = renderer.render_aovs(cam)["normal"]
    lum = out.rgb.mean(-1).numpy()
    facing_x = normals[..., 0] > 0.7
    facing_minus_x = normals[..., 0] < -0.7
    assert lum[facing_x].mean() > 20 * lum[facing_minus_x].mean()


def test_equirect_directions_invert_blenders_mapping():
    directions = equirect_directions(16, 32)
    uv = blender_direction_to_equirect_uv(directions)
    rows, cols = np.meshgrid(np.arange(16), np.arange(32), indexing="ij")
    assert np.allclose(uv[..., 0] * 32 - 0.5, cols, atol=1e-6)
    assert np.allclose(uv[..., 1] * 16 - 0.5, rows, atol=1e-6)
    # Blender (checked against Cycles in test_lighting_blender.py): the u = 0.5 column looks along +X,
    # u = 0.25 along +Y.
    assert np.allclose(directions[8, 16] + directions[7, 16], [2 * np.cos(np.pi / 32), 0, 0], atol=0.2)
    assert np.allclose(blender_direction_to_equirect_uv(np.array([0.0, 1.0, 0.0])), [0.25, 0.5])


def test_fov_multiplier_one_spans_the_normalised_radius_at_the_target():
    """The paper's FOV = tanh(r lambda / d) as the half-angle: at lambda = 1 the image's edge passes
    through the point r from the target, perpendicular to the view (tight framing). A whole radius-r
    sphere is inside the view from lambda = 1.033 on (perspective shows a little more of it than the
    plane through its centre)."""
    for multiplier in (1.0, 1.21, 1.65):
        cam = Camera(azimuth_deg=30.0, elevation_deg=15.0, fov_multiplier=multiplier, width=64, height=64)
        _, right, up = look_frame(cam.forward)
        # The half-angle is tanh(r lambda / d) exactly: the image edge at the target's depth is d tan of it.
        half = 2.0 * np.tan(np.tanh(0.5 * multiplier / 2.0))
        edge = cam.project(np.array([cam.target + half * right, cam.target + half * up]))
        assert np.allclose(edge, [[64.0, 32.0], [32.0, 0.0]], atol=1e-6)
    # At lambda = 1 that edge is r from the target to 0.02% (tanh x = atan x here): the tight frame.
    cam = Camera(fov_multiplier=1.0, width=64, height=64)
    assert abs(cam.project(np.array([cam.target + 0.5 * look_frame(cam.forward)[1]]))[0, 0] - 64.0) < 0.01
    assert 1.03 < whole_object_multiplier() < 1.04

    renderer = AssetRenderer(uv_sphere(), TEX, constant_env(1.0))
    env = torch.tensor(constant_env(1.0))

    def border_coverage(multiplier):
        cam = Camera(fov_multiplier=multiplier, width=64, height=64)
        alpha = renderer.render(cam, *constant_maps(), env, spp=4, seed=0).alpha[..., 0]
        border = torch.cat([alpha[0], alpha[-1], alpha[:, 0], alpha[:, -1]])
        return float(border.max())

    # At lambda = 1 the sphere spills ~1 px past the 64 px frame; 0.05 above the whole-object multiplier
    # its silhouette stays 1.5 px inside it, so the border pixels see none of it.
    assert border_coverage(1.0) > 0.0
    assert border_coverage(whole_object_multiplier() + 0.05) == 0.0
    assert border_coverage(0.8) > 0.5
    assert fov_from_multiplier(1.21) > fov_from_multiplier(1.0)


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_tiny_and_huge_meshes_render_the_same_after_normalisation(scale):
    base = uv_sphere(radius=1.0, segments=24, rings=12)
    reference, _ = normalize_to_unit_sphere(base)
    scaled = Mesh.from_arrays((base.positions + 3.0) * scale, base.faces, base.uvs, base.normals)
    normalized, transform = normalize_to_unit_sphere(scaled)
    assert np.allclose(transform.to_object(normalized.positions), scaled.positions, rtol=1e-4, atol=1e-3 * scale)
    cam = Camera(azimuth_deg=45, elevation_deg=30, width=32, height=32)
    env = torch.tensor(constant_env(1.0))
    images = [AssetRenderer(m, TEX, constant_env(1.0)).render(cam, *constant_maps(), env, spp=4, seed=2).rgb
              for m in (reference, normalized)]
    assert torch.allclose(images[0], images[1], atol=1e-3)


def test_projection_matches_the_rendered_silhouette():
    renderer = AssetRenderer(uv_sphere(radius=0.2), TEX, constant_env(1.0))
    cam = Camera(azimuth_deg=20, elevation_deg=10, width=64, height=48, target=(0.3, 0.0, 0.1))
    alpha = renderer.render(cam, *constant_maps(), torch.tensor(constant_env(1.0)), spp=4, seed=0).alpha[..., 0]
    rows, cols = np.nonzero(alpha.numpy() > 0.5)
    x, y = cam.project(np.zeros(3))
    assert abs(cols.mean() + 0.5 - x) < 0.5 and abs(rows.mean() + 0.5 - y) < 0.5


def test_grazing_elevation_renders_finite_values():
    renderer = AssetRenderer(grid_plane(), TEX, constant_env(1.0))
    out = renderer.render(Camera(elevation_deg=89.5, width=32, height=32), *constant_maps(),
                          torch.tensor(constant_env(1.0)), spp=4, seed=0)
    assert torch.isfinite(out.rgb).all()
    with pytest.raises(InputError):
        Camera(elevation_deg=90.0)


def test_floor_catches_the_asset_shadow():
    env = constant_env(0.02, height=32)
    env[:4] = 50.0  # light from straight above
    renderer = AssetRenderer(uv_sphere(), TEX, env, SceneOptions(floor=True))
    cam = Camera(elevation_deg=30, fov_multiplier=1.65, width=64, height=64)
    out = renderer.render(cam, *constant_maps(), torch.tensor(env), spp=32, seed=0)
    aov = renderer.render_aovs(cam)
    floor = aov["normal"][..., 2] > 0.99           # floor pixels face straight up
    lum = out.rgb.mean(-1).numpy()
    # Floor pixels right below the sphere are darker than floor pixels far from it.
    assert floor.sum() > 100
    x, y = cam.project(np.array([0.0, 0.0, -0.5]))
    rows, cols = np.nonzero(floor)
    dist = np.hypot(rows + 0.5 - y, cols + 0.5 - x)
    assert lum[rows[dist < 6], cols[dist < 6]].mean() < 0.5 * lum[rows[dist > 20], cols[dist > 20]].mean()


def test_bad_environment_map_is_rejected():
    with pytest.raises(InputError):
        AssetRenderer(uv_sphere(), TEX, np.ones((16, 16, 3), np.float32))
    with pytest.raises(InputError):
        AssetRenderer(uv_sphere(), TEX, np.full((16, 32, 3), np.nan, np.float32))


def test_render_albedo_is_the_base_colour_where_the_asset_is_hit_and_nothing_elsewhere():
    from scenefit.core.render.backend import init_mitsuba

    init_mitsuba()
    maps = np.zeros((8, 8, 5), np.float32)
    maps[..., :3], maps[..., 3] = (0.2, 0.5, 0.7), 0.5
    renderer = AssetRenderer(uv_sphere(0.5, 16, 8), (8, 8), np.ones((8, 16, 3), np.float32))
    out = renderer.render_albedo(Camera(width=32, height=32), maps)
    hit = out[..., 3] > 0
    assert 0.2 < hit.mean() < 0.9
    assert np.allclose(out[hit][:, :3], (0.2, 0.5, 0.7), atol=1e-4) and not out[~hit][:, :3].any()


def test_a_ctrl_c_during_a_render_is_a_keyboard_interrupt_not_a_partial_image(run_py):
    """Mitsuba catches a Ctrl-C while it renders and winds down. In a process that ignores SIGINT (a shell's
    background job, nohup) Python raises nothing, and the partial image came back as if finished;
    render_whole ends such a render with KeyboardInterrupt, as Python does where it takes SIGINT."""
    proc = run_py("""
        import json, os, signal, threading, time
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # as a shell starts a background job
        from scenefit.core.render.backend import init_mitsuba, render_whole
        init_mitsuba()
        import mitsuba as mi
        scene = mi.load_dict({"type": "scene", "ball": {"type": "sphere"}, "light": {"type": "constant"},
                              "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
                                  origin=[0, -4, 0], target=[0, 0, 0], up=[0, 0, 1]),
                                  "film": {"type": "hdrfilm", "width": 160, "height": 160}}})
        integrator = mi.load_dict({"type": "path", "max_depth": 8})
        render_whole(mi, scene, integrator, spp=4)                   # compiled: the next one only renders
        t = time.perf_counter()
        whole = render_whole(mi, scene, integrator, spp=64)
        one = time.perf_counter() - t
        threading.Timer(one * 2, os.kill, (os.getpid(), signal.SIGINT)).start()
        t = time.perf_counter()
        try:
            render_whole(mi, scene, integrator, spp=64 * 40)        # about 40 times as long as `one`
            said = "finished"
        except KeyboardInterrupt:
            said = "interrupted"
        print("\\nJSON" + json.dumps({"said": said, "after": time.perf_counter() - t, "one": one}))
    """)
    from conftest import printed_json

    out = printed_json(proc)
    assert out["said"] == "interrupted" and out["after"] < 20 * out["one"] + 5, out
