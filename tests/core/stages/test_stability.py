"""The stability matrix: every extreme gives finite outputs or a clear error.

Covered here: HDR maps 1e-4..1e6, roughness/metallic 0 and 1, degenerate triangles, meshes at 1e-3
and 1e3 scale through conversion, photos 1e-4..1e6 (EXR), black and white photos, 1x1 and 8000x6000
photos (the light stage's peak memory bounded by its working size), small lights at every preset,
each light preset doing clearly less work than the next, grazing and straight-down photo cameras in
the compose stage, fp16 LoRA gradients (no loss scaling needed).
Covered elsewhere: timesteps 0/1/998/999 and fp16 guards (test_guidance.py), grazing cameras and
meshes at 1e-4/1e4 through the renderer (test_render.py), light scales at 1e-3/1e4 (test_lighting.py).
"""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch

from scenefit.core.render.orbit_camera import Camera
from scenefit.core.stages.convert import convert_asset
from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.data.photo import load_photo
from scenefit.core.stages.light import estimate_light
from scenefit.core.stages.light.depth import DepthConfig
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.mesh import Mesh
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.render.renderer import AssetRenderer

from conftest import printed_json, shared_tiny_pair

TEX = (16, 16)
GEOMETRIC = DepthConfig(depth_type="geometric")


def maps(color=0.5, roughness=0.5, metallic=0.0):
    h, w = TEX
    return (torch.full((h, w, 3), color), torch.full((h, w, 1), roughness), torch.full((h, w, 1), metallic))


def env(value: float, height: int = 8) -> np.ndarray:
    return np.full((height, 2 * height, 3), value, np.float32)


@pytest.fixture(scope="module")
def sphere_renderer():
    return AssetRenderer(uv_sphere(segments=16, rings=8), TEX, env(1.0))


# -- rendering ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("radiance", [1e-4, 1e6])
def test_hdr_maps_from_1e_4_to_1e6_render_in_proportion(sphere_renderer, radiance):
    camera = Camera(azimuth_deg=20, elevation_deg=10, width=24, height=24)
    unit = sphere_renderer.render(camera, *maps(), torch.tensor(env(1.0)), spp=4, seed=0)
    out = sphere_renderer.render(camera, *maps(), torch.tensor(env(radiance)), spp=4, seed=0)
    assert torch.isfinite(out.rgb).all()
    inside = out.alpha[..., 0] > 0.99
    ratio = out.rgb[inside] / unit.rgb[inside].clamp_min(1e-12)
    assert torch.allclose(ratio, torch.full_like(ratio, radiance), rtol=1e-3)   # light transport is linear


@pytest.mark.parametrize("roughness, metallic", [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0)])
def test_roughness_and_metallic_at_0_and_1_give_finite_images_and_gradients(sphere_renderer, roughness, metallic):
    base, rough, metal = maps(0.8, roughness, metallic)
    for t in (base, rough, metal):
        t.requires_grad_(True)
    environment = torch.tensor(env(1.0))
    environment[:2] = 50.0                                      # a bright sky makes a sharp highlight
    out = sphere_renderer.render(Camera(azimuth_deg=0, elevation_deg=30, width=24, height=24), base, rough, metal,
                                 environment, spp=4, seed=1)
    out.rgb.mean().backward()
    assert torch.isfinite(out.rgb).all() and out.rgb.max() > 0
    assert all(torch.isfinite(t.grad).all() for t in (base, rough, metal))


def test_degenerate_triangles_render_and_convert_finite():
    sphere = uv_sphere(segments=12, rings=6)
    # Zero-area triangles (a repeated corner, three collinear corners) and a triangle with no UV area.
    faces = np.concatenate([sphere.faces, [[0, 0, 1], [5, 6, 7]]]).astype(np.int32)
    positions = sphere.positions.copy()
    positions[7] = 2 * positions[6] - positions[5]
    mesh = Mesh.from_arrays(positions, faces, sphere.uvs, sphere.normals)
    renderer = AssetRenderer(mesh, TEX, env(1.0))
    out = renderer.render(Camera(width=24, height=24), *maps(), torch.tensor(env(1.0)), spp=4, seed=0)
    assert torch.isfinite(out.rgb).all()
    h, w = TEX
    result = convert_asset(mesh, PBRMaps(np.full((h, w, 3), 0.4, np.float32), 0.5, 0.0),
                           stage_config("convert", "draft", iterations=3))
    assert np.isfinite(result.psnr) or result.psnr == float("inf")
    assert torch.isfinite(result.predicted()).all()


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_meshes_at_1e_3_and_1e3_scale_convert_alike(scale):
    sphere = uv_sphere(segments=12, rings=6)
    yy, xx = np.mgrid[0:16, 0:16] / 16
    asset_maps = PBRMaps(np.stack([xx, yy, 0.5 + 0 * xx], -1).astype(np.float32), 0.5, 0.0)
    config = stage_config("convert", "draft", init_type="fit", iterations=20, resolution=16)
    unit = convert_asset(sphere, asset_maps, config)
    scaled = convert_asset(Mesh.from_arrays(sphere.positions * scale, sphere.faces, sphere.uvs, sphere.normals),
                           asset_maps, config)
    assert np.isfinite(scaled.psnr) and abs(scaled.psnr - unit.psnr) < 0.5


# -- photos and light -------------------------------------------------------------------------------------
@pytest.mark.parametrize("radiance", [1e-4, 1e6])
def test_exr_photos_from_1e_4_to_1e6_give_finite_maps(tmp_path, radiance):
    rng = np.random.default_rng(2)
    photo = (radiance * rng.uniform(0.2, 1.0, size=(24, 32, 3))).astype(np.float32)
    photo[:4] *= 20.0
    write_image(tmp_path / "photo.exr", photo)
    srgb, info = load_photo(tmp_path / "photo.exr")
    result = estimate_light(srgb, (16.0, 18.0), stage_config("light", "draft", depth=GEOMETRIC))
    assert np.isfinite(result.hdr).all() and result.hdr.min() >= 0 and result.hdr.max() > 0
    # The same scene at another exposure reads as the same photo (the camera meters it).
    assert np.allclose(srgb, load_photo_scaled(tmp_path, photo / radiance)[0], atol=2e-3)


def load_photo_scaled(tmp_path, photo):
    write_image(tmp_path / "unit.exr", photo)
    return load_photo(tmp_path / "unit.exr")


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_black_and_white_photos_give_finite_maps(value):
    photo = np.full((24, 32, 3), value, np.float32)
    for scene in ("indoor", "outdoor"):
        result = estimate_light(photo, (16.0, 18.0), stage_config("light", "draft", depth=GEOMETRIC, scene_type=scene))
        assert np.isfinite(result.hdr).all() and result.hdr.min() >= 0
        assert np.isfinite(list(result.scales.values())).all()


def test_a_1x1_photo_is_a_clear_error(tmp_path):
    write_image(tmp_path / "dot.png", np.full((1, 1, 3), 0.5, np.float32))
    with pytest.raises(InputError, match="at least 2x2"):
        load_photo(tmp_path / "dot.png")


LIGHT_PEAK = textwrap.dedent("""
    import json, sys
    from scenefit.core.data.photo import load_photo
    from scenefit.core.stages.light import estimate_light
    from scenefit.core.stages.light.depth import DepthConfig
    from scenefit.core.pipeline.presets import stage_config
    config = stage_config("light", "draft", depth=DepthConfig(depth_type="geometric"))
    estimate_light(load_photo(sys.argv[2])[0], (8.0, 10.0), config)    # imports and caches, on a small photo
    def status_mb(key):
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith(key)) / 1024
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")                      # the peak (VmHWM) restarts from here: the imports' peak is not the stage's
    before = status_mb("VmRSS")
    photo, info = load_photo(sys.argv[1])
    h, w = photo.shape[:2]
    result = estimate_light(photo, (0.5 * w, 0.8 * h), config)
    grew = status_mb("VmHWM") - before
    print("JSON" + json.dumps({"shape": list(photo.shape), "grew_mb": grew, "info": info,
                               "map": list(result.hdr.shape), "finite": bool((result.hdr >= 0).all())}))
""")


def light_stage_peak(photo_path, tmp_path) -> dict:
    """The light stage (read + estimate, draft) on one photo in a fresh process: how far its peak
    resident memory grows over a warmed-up process."""
    small = tmp_path / "warm.png"
    if not small.exists():
        write_image(small, np.full((24, 32, 3), 0.5, np.float32))
    proc = subprocess.run([sys.executable, "-c", LIGHT_PEAK, str(photo_path), str(small)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return printed_json(proc)


def test_an_8000x6000_photo_costs_the_light_stage_what_its_working_size_costs(tmp_path):
    """The light stage works at most 1024 px wide (its panorama, depth and critics need no more), so an
    8000x6000 photo must cost what the same photo at 1024x768 costs, plus at most the band the reader
    reduces at a time: not one full-size copy (8000x6000x3 float32 = 576 MB; it used to peak at 5.1 GB)."""
    import cv2

    from scenefit.core.data.photo import PHOTO_WORKING_SIDE

    big = np.full((6000, 8000, 3), 90, np.uint8)
    big[:400] = 250
    cv2.imwrite(str(tmp_path / "big.jpg"), big)
    cv2.imwrite(str(tmp_path / "working.jpg"), cv2.resize(big, (1024, 768), interpolation=cv2.INTER_AREA))
    del big
    full, working = light_stage_peak(tmp_path / "big.jpg", tmp_path), light_stage_peak(tmp_path / "working.jpg", tmp_path)
    assert full["info"]["size"] == [8000, 6000] and max(full["shape"][:2]) <= PHOTO_WORKING_SIDE
    assert np.isclose(full["shape"][1] / full["shape"][0], 8000 / 6000, rtol=0.01)
    assert full["finite"] and full["map"] == working["map"]
    one_full_copy_mb = 8000 * 6000 * 3 * 4 / 2**20
    # The reader's bands (32 rows x 8000 px, 3 MB) and the decoder's buffers: far below one full-size
    # copy (measured here: +0.1 MB, against 576 MB).
    assert full["grew_mb"] - working["grew_mb"] < one_full_copy_mb / 32, (full, working)
    # At the working size the stage holds a few per-pixel arrays (rays, depth, colours; measured here
    # about 6 float32 RGB copies of the working photo): bounded by the size it works at.
    working_copy_mb = 1024 * 768 * 3 * 4 / 2**20
    assert working["grew_mb"] < 16 * working_copy_mb, working


@pytest.mark.parametrize("preset", ["draft", "balanced", "final"])
def test_a_small_lamp_is_found_at_every_preset(preset):
    photo = np.full((480, 640, 3), 0.25, np.float32)
    photo[100:116, 300:316] = 1.0                         # a lamp 16 px across (1.5 degrees)
    result = estimate_light(photo, (320.0, 400.0), stage_config("light", preset, depth=GEOMETRIC, scene_type="indoor"))
    assert result.regions, "no light region found"
    assert result.hdr.max() > 10.0 * 0.25


def light_work(preset: str) -> dict[str, int]:
    """What the light stage at `preset` does: panorama texels it builds (counted from a run) and the
    critic's rendered samples when a critic runs (iterations x views x pixels x spp, from the config)."""
    photo = np.full((240, 320, 3), 0.3, np.float32)
    photo[40:60, 150:170] = 1.0
    config = stage_config("light", preset, depth=GEOMETRIC, scene_type="indoor")
    built = estimate_light(photo, (160.0, 200.0), config).panorama.ldr.shape
    views = len(config.apparatus.object_azimuths) + 1
    return {"panorama texels": built[0] * built[1],
            "critic samples": config.optimise.iterations * views * config.apparatus.render_size ** 2 * config.apparatus.spp}


def test_each_light_preset_does_clearly_less_work_than_the_next():
    """A preset that costs as much as a better one is a bug: draft light used to build balanced's
    128-row panorama for its 64-row map (same seconds, same error in the bench)."""
    work = {preset: light_work(preset) for preset in ("draft", "balanced", "final")}
    for cheaper, dearer in (("draft", "balanced"), ("balanced", "final")):
        for measure in ("panorama texels", "critic samples"):
            assert work[cheaper][measure] * 2 <= work[dearer][measure], (cheaper, dearer, measure, work)


def test_a_tiny_1e6_spot_in_an_exr_photo_is_kept(tmp_path):
    radiance = np.full((480, 640, 3), 0.5, np.float32)
    radiance[100:102, 301:303] = 1e6                      # 2x2 px
    write_image(tmp_path / "spot.exr", radiance)
    photo, _ = load_photo(tmp_path / "spot.exr")
    result = estimate_light(photo, (320.0, 400.0), stage_config("light", "draft", depth=GEOMETRIC, scene_type="indoor"))
    assert result.regions and result.hdr.max() > 10.0


# -- grazing cameras ------------------------------------------------------------------------------------
@pytest.mark.parametrize("pitch", [-0.5, -89.0])
def test_grazing_and_straight_down_photo_cameras_compose_finite(pitch):
    """A photo camera a half degree below the horizon (the object one row under it, seen edge-on on a
    floor that is nearly a line) and one looking straight down both give a finite composite."""
    from scenefit.core.stages.compose import ComposeInputs, compose
    from scenefit.core.scene.camera import PhotoCamera, horizon_row

    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=pitch, fov_deg=60.0, width=32, height=24)
    y = min(23.0, horizon_row(camera) + 1.0) if pitch > -45 else 12.0
    stack = np.concatenate([np.full((8, 8, 3), 0.5), np.full((8, 8, 1), 0.5), np.zeros((8, 8, 1))], -1).astype(np.float32)
    environment = env(1.0, 16)
    environment[:4] = 20.0
    result = compose(ComposeInputs(uv_sphere(0.5, 16, 8), stack, np.full((24, 32, 3), 0.5, np.float32), (16.0, y),
                                   environment, camera), stage_config("compose", "draft", spp=1, denoiser_type="none"))
    assert np.isfinite(result.composite_linear).all() and result.changed.any()


# -- fp16 ------------------------------------------------------------------------------------------------
def test_fp16_unet_gives_the_lora_the_same_gradients_as_fp32(tmp_path):
    """The LoRA trains in float32 while the UNet runs in fp16: its gradients neither underflow nor
    drift, so no loss scaling is needed (GradScaler would only matter for fp16 parameters)."""
    from scenefit.core.guidance import LoraCritic, ModelConfig, load_guidance_models
    from scenefit.core.guidance.lora import camera_condition
    base, _ = shared_tiny_pair()
    grads = {}
    generator = torch.Generator().manual_seed(0)
    latents, noise = torch.randn(1, 4, 16, 16, generator=generator), torch.randn(1, 4, 16, 16, generator=generator)
    for dtype in ("fp32", "fp16"):
        models = load_guidance_models(ModelConfig(base_model=str(base), dtype_type=dtype), need_inpaint=False)
        lora = LoraCritic(models.unet, seed=0)
        with torch.no_grad():  # start away from zero so every LoRA weight gets a gradient
            for p in lora.lora_parameters():
                p.normal_(0.0, 0.05, generator=torch.Generator().manual_seed(p.numel()))
        lora.train_step(latents, models.embed("a sofa"), camera_condition([0, -2, 0], [0, 1, 0]), 500, noise,
                        float(models.scheduler.alphas_cumprod[500]), drop_condition=False)
        grads[dtype] = torch.cat([p.grad.float().flatten() for p in lora.lora_parameters()])
    full, half = grads["fp32"], grads["fp16"]
    assert torch.isfinite(half).all()
    underflowed = ((half == 0) & (full != 0)).float().mean()
    assert underflowed < 0.01
    assert float((half - full).norm() / full.norm()) < 0.05
