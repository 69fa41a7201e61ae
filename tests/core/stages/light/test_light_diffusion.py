"""The diffusion light critic (VSD through core/guidance) with a tiny random-weight SD model."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from scenefit.core.base.errors import ModelMissingError
from scenefit.core.guidance import ModelConfig, load_guidance_models
from scenefit.core.guidance.lora import ADAPTER
from scenefit.core.data.imageio import write_image
from scenefit.core.stages.light import estimate as estimate_module
from scenefit.core.stages.light.diffusion_critic import DiffusionCriticConfig, DiffusionLightCritic
from scenefit.core.stages.light.estimate import LightConfig, estimate_light
from conftest import shared_tiny_pair
from scenefit.core.stages.light.hdr import (SPHERE_PROMPT, ApparatusConfig, ApparatusScene, CriticRequest, OptimiseConfig,
                                        optimise_scales)
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.frame import equirect_directions


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """The tiny UNet's ops are microseconds long: with a busy machine, OpenMP's waiting between them
    cost 10-30x (145 s against 8 s for this file under a concurrent benchmark). One thread is as fast."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def tiny_base():
    return shared_tiny_pair()[0]


def _scene():
    maps = torch.cat([torch.full((4, 4, 3), 0.6), torch.full((4, 4, 1), 0.4), torch.zeros(4, 4, 1)], -1)
    config = ApparatusConfig(render_size=32, spp=2, object_azimuths=(0.0,), view_weights=(0.5, 0.5))
    return ApparatusScene(uv_sphere(radius=0.5, segments=16, rings=8), maps, (16, 32), config)


def _bright_spot(shape=(16, 32)):
    h, w = shape
    ldr = np.full((h, w, 3), 0.35, np.float32)
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    mask = equirect_directions(h, w) @ d > np.cos(np.radians(30))
    ldr[mask] = 1.0
    return ldr, {"near": mask}


PHOTO = np.random.default_rng(5).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
OBJECT_BOX = (24.0, 18.0, 16.0)   # x0, y0, side: the object stands at (32, 34), 1/3 of the photo tall


def _critic(tiny_base, scene, **config):
    models = load_guidance_models(ModelConfig(base_model=str(tiny_base)), need_inpaint=False)
    prompts = ("a 3D object", SPHERE_PROMPT)
    return DiffusionLightCritic(models, scene.cameras, prompts, DiffusionCriticConfig(model_resolution=32, **config),
                                photo=PHOTO, squares=scene.photo_squares(OBJECT_BOX)), prompts


def _request(scene, v, prompts, render_alpha, iteration=0, light=None):
    coverage = scene.object_alpha(v)
    return CriticRequest((prompts[v],), (scene.view_names[v],), iteration, 4, (750, 990), coverage[None], (v,), light,
                         (render_alpha - coverage).clamp(0, 1)[None])


def test_critic_gives_finite_image_gradients_for_every_view_and_trains_its_lora(tiny_base):
    scene = _scene()
    critic, prompts = _critic(tiny_base, scene)
    lora_before = {n: p.detach().clone() for n, p in critic.models.unet.named_parameters() if ADAPTER in n}
    envmap = torch.full((16, 32, 3), 0.8)
    for v in range(len(scene.cameras)):
        render, alpha = scene.render_view(envmap, v, seed=3)
        grad = critic(render[None], _request(scene, v, prompts, alpha))
        assert grad.shape == (1, 32, 32, 3) and grad.dtype == render.dtype
        assert torch.isfinite(grad).all() and float(grad.abs().sum()) > 0
    # The paper's two global views per view: the full scene and an interpolated crop.
    assert [(h["view"], h["image"]) for h in critic.history] == [(0, "full"), (0, "crop"), (1, "full"), (1, "crop")]
    assert all(750 <= h["t"] <= 990 for h in critic.history)
    # One LoRA step per view: ε_ψ moved.
    changed = [not torch.equal(p, lora_before[n]) for n, p in critic.models.unet.named_parameters() if ADAPTER in n]
    assert changed and any(changed)
    # The LoRA learning rate is annealed with the scales': 1e-4 at the start, 1e-5 at the last iteration.
    assert critic.lora.optimizer.param_groups[0]["lr"] == pytest.approx(1e-4)
    render, alpha = scene.render_view(envmap, 1, seed=4)
    critic(render[None], _request(scene, 1, prompts, alpha, iteration=3))
    assert critic.lora.optimizer.param_groups[0]["lr"] == pytest.approx(1e-5)


def _sphere_only_scene():
    maps = torch.cat([torch.full((4, 4, 3), 0.6), torch.full((4, 4, 1), 0.4), torch.zeros(4, 4, 1)], -1)
    config = ApparatusConfig(render_size=32, spp=32, object_azimuths=(), view_weights=(1.0,))
    return ApparatusScene(uv_sphere(radius=0.5, segments=16, rings=8), maps, (16, 32), config)


def _optimal_denoiser(score, target_latents):
    """ε_φ of a model whose data is the single latent z* (the render under the true light): the exact
    denoiser ε*(x_t) = (x_t - sqrt(ᾱ_t) z*) / sqrt(1 - ᾱ_t). No SD weights exist here; this is a model
    with a known answer, and everything around it (tone curve, VAE, VSD gradient, scales) is the real path."""
    def predict_phi(x_t, t, *args, **kwargs):
        a = float(score.alpha_bar[t])
        return (x_t - math.sqrt(a) * target_latents.to(x_t.device)) / math.sqrt(1.0 - a)
    return predict_phi


@pytest.mark.parametrize("start", [2.0, 32.0])
def test_diffusion_steps_move_the_scale_toward_the_truth(tiny_base, start):
    from scenefit.core.data.imageio import srgb_to_linear
    from scenefit.core.stages.light.diffusion_critic import tonemap_srgb_torch
    from scenefit.core.stages.light.hdr import compose_hdr

    scene = _sphere_only_scene()
    ldr, regions = _bright_spot()
    truth = 8.0
    ldr_lin = torch.from_numpy(srgb_to_linear(ldr))
    masks = {k: torch.from_numpy(v) for k, v in regions.items()}
    true_map = compose_hdr(ldr_lin, masks, {"near": torch.tensor(math.log(truth))}).detach()
    # fp32: the optimal denoiser below is built from these latents; bf16 rounds them by ~0.4%, which the
    # tiny model's few steps do not outrun at the 32x start.
    models = load_guidance_models(ModelConfig(base_model=str(tiny_base), dtype_type="fp32"), need_inpaint=False)
    # The known answer is the apparatus render under the true map, so the critic scores the renders.
    critic = DiffusionLightCritic(models, scene.cameras, (SPHERE_PROMPT,),
                                  DiffusionCriticConfig(model_resolution=32, lambda_vsd=0.0, views_type="apparatus"))
    with torch.no_grad():
        target, _ = scene.render_view(true_map, 0, spp=64, seed=99)
        image = tonemap_srgb_torch(target, critic.config.l_white).permute(2, 0, 1)[None]
        critic.score.predict_phi = _optimal_denoiser(critic.score, critic.models.encode(image))
    result = optimise_scales(scene, ldr, regions, {"near": start}, critic, (SPHERE_PROMPT,),
                             OptimiseConfig(iterations=6, lr=0.3))
    end = result.log_scales["near"]
    assert math.isfinite(end)
    # Closer to the truth than where it started, from below and from above, by at least a third of the way.
    assert abs(end - math.log(truth)) < (2 / 3) * abs(math.log(start) - math.log(truth)), (start, math.exp(end))
    # ε_ψ saw the light the renders were made under: its c_v followed the scale.
    seen = [h["light"][3] for h in critic.history]
    assert (seen[-1] > seen[0]) == (start < truth)


def test_composited_views_hold_the_photo_around_the_apparatus_and_pass_gradients_to_the_light(tiny_base):
    from scenefit.core.guidance.views import paste_layer, photo_crop
    from scenefit.core.data.imageio import srgb_to_linear
    from scenefit.core.stages.light.hdr import compose_hdr, per_view_losses

    scene = _scene()
    critic, prompts = _critic(tiny_base, scene)
    squares = scene.photo_squares(OBJECT_BOX)
    # The object view is centred on the object's square, 1.65 x as wide; the sphere's sits right of it, on the floor.
    assert squares[0] == pytest.approx((32 - 1.65 * 8, 26 - 1.65 * 8, 1.65 * 16))
    assert squares[1][0] + squares[1][2] / 2 == pytest.approx(32 + 0.9 * 16) and squares[1][2] == pytest.approx(9.6)
    # The crop schedule: the full view is the whole photo; the other lies between the view's square and it.
    sides = []
    for _ in range(50):
        full, crop = critic.global_windows(0)
        assert full == (0.0, -8.0, 64.0)
        assert all(min(a, b) - 1e-9 <= c <= max(a, b) + 1e-9 for a, b, c in zip(squares[0], full, crop))
        sides.append(crop[2])
    assert min(sides) < squares[0][2] + 10 and max(sides) > 64 - 10
    # A high bright spot: the floor carries a shadow; the views hold the photo wherever the apparatus is not.
    ldr, regions = _bright_spot()
    log_scale = torch.tensor(math.log(30.0), requires_grad=True)
    envmap = compose_hdr(torch.from_numpy(srgb_to_linear(ldr)), {k: torch.from_numpy(v) for k, v in regions.items()},
                         {"near": log_scale})
    render, alpha = scene.render_view(envmap, 0, seed=1)
    request = _request(scene, 0, prompts, alpha)
    images = critic.views(render.detach(), request, 0, 0)
    full = critic.global_windows(0)[0]
    untouched = paste_layer(torch.cat([request.alphas[0], request.floor_alphas[0]], -1), (*squares[0][:2],
                            squares[0][2], squares[0][2]), full, 32).sum(1)[0] == 0
    photo = torch.from_numpy(photo_crop(PHOTO, full, 32)).permute(2, 0, 1)
    difference = (images["full"][0] - photo).abs().amax(0)
    assert untouched.sum() > 500 and float(difference[untouched].max()) < 1e-5
    assert float(difference[~untouched].max()) > 0.05          # the object (and its shadow) are in the photo
    # The critic's image gradient reaches the light map's scale through the render.
    grad = critic(render[None], request)
    per_view_losses(grad, render[None]).sum().backward()
    assert log_scale.grad is not None and torch.isfinite(log_scale.grad) and float(log_scale.grad) != 0


def test_the_light_vector_describes_the_map_and_conditions_eps_psi(tiny_base):
    from scenefit.core.data.imageio import srgb_to_linear
    from scenefit.core.stages.light.hdr import LightVector

    ldr, regions = _bright_spot()
    vector = LightVector(torch.from_numpy(srgb_to_linear(ldr)), {k: torch.from_numpy(v) for k, v in regions.items()})
    c_x, c_y, c_r, c_v, b_v = vector({"near": 10.0})
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    assert c_x == pytest.approx((0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0, abs=0.03)
    assert c_y == pytest.approx(0.5 - math.asin(d[2]) / math.pi, abs=0.03)
    assert c_r == pytest.approx(1 - math.cos(math.radians(30)), rel=0.3)     # a 30-degree cap
    assert c_v == pytest.approx(10.0, rel=1e-3) and b_v == pytest.approx(float(srgb_to_linear(np.float32(0.35))), rel=1e-3)
    scene = _scene()
    critic, _ = _critic(tiny_base, scene)
    a, b = critic.condition(1, vector({"near": 10.0})), critic.condition(1, vector({"near": 100.0}))
    assert torch.equal(a[:16], b[:16]) and not torch.equal(a[16:], b[16:])


def test_missing_weights_fail_before_any_work_with_a_clear_message(tmp_path, monkeypatch):
    empty = tmp_path / "empty-cache"
    empty.mkdir()

    def no_work(*args, **kwargs):
        raise AssertionError("the panorama was started before the models were located")

    monkeypatch.setattr(estimate_module, "scene_type_cue", no_work)
    config = LightConfig(critic_type="diffusion", models=ModelConfig(cache_dir=str(empty), local_files_only=True))
    with pytest.raises(ModelMissingError) as info:
        estimate_light(np.full((8, 12, 3), 0.5, np.float32), (6, 6), config)
    message = str(info.value)
    assert "stabilityai/stable-diffusion-2-base" in message and str(empty) in message
    assert "--critic none" in message


def _photo(tmp_path):
    pixels = np.random.default_rng(1).uniform(0.0, 1.0, size=(24, 32, 3)).astype(np.float32)
    pixels[:8] = [0.95, 0.97, 1.0]
    write_image(tmp_path / "photo.png", pixels)
    return tmp_path / "photo.png"


def test_scenefit_light_with_the_diffusion_critic_says_so(tmp_path, tiny_base):
    from scenefit.cli import main

    out = tmp_path / "out"
    code = main(["light", "--photo", str(_photo(tmp_path)), "--at", "0.5,0.8", "--out", str(out), "--preset", "draft",
                 "--scene", "outdoor", "--critic", "diffusion", "--base-model", str(tiny_base), "--iterations", "2",
                 "--model-resolution", "32", "--quiet"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    critic = report["decisions"]["critic"]
    assert critic["type"] == "diffusion" and critic["used"] and "diffusion critic" in critic["why"]
    assert critic["models"]["base"] == str(tiny_base) and critic["choice"]["chosen"] == "diffusion"
    assert report["decisions"]["optimisation"]["iterations"] == 2
    assert report["scales"] != report["prior_scales"]


def test_scenefit_light_critic_auto_and_missing_weights(tmp_path):
    from scenefit.cli import main

    empty = tmp_path / "empty-cache"
    empty.mkdir()
    photo = _photo(tmp_path)
    common = ["light", "--photo", str(photo), "--at", "0.5,0.8", "--preset", "draft", "--scene", "outdoor",
              "--cache-dir", str(empty), "--offline", "--quiet"]
    assert main(common + ["--out", str(tmp_path / "a"), "--critic", "diffusion"]) == 2
    assert not (tmp_path / "a" / "light.exr").exists()
    assert main(common + ["--out", str(tmp_path / "b")]) == 0      # auto: no weights -> the prior
    critic = json.loads((tmp_path / "b" / "report.json").read_text())["decisions"]["critic"]
    assert critic["choice"]["asked"] == "auto" and critic["choice"]["chosen"] == "none"
    assert critic["type"] == "none" and not critic["used"]


# -- outdoor outpainting ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny_inpaint():
    return shared_tiny_pair()[1]


def _outdoor_photo():
    rng = np.random.default_rng(2)
    photo = np.empty((24, 32, 3), np.float32)
    photo[:12] = [0.55, 0.7, 0.95]
    photo[12:] = [0.35, 0.4, 0.2]
    return np.clip(photo + rng.normal(0, 0.03, photo.shape), 0, 1).astype(np.float32)


def _seam_jump(ldr, rows):
    """Mean |difference| across the wrap seam, and across every other pair of neighbouring columns."""
    x = ldr[rows]
    inner = np.abs(np.diff(x, axis=1)).mean(axis=(0, 2))
    return float(np.abs(x[:, 0] - x[:, -1]).mean()), inner


def test_outpainting_keeps_the_photo_and_paints_the_rest(tiny_base, tiny_inpaint):
    from scenefit.core.stages.light.outpaint import OutpaintConfig, outpaint_panorama
    from scenefit.core.stages.light.panorama import outdoor_panorama
    from scenefit.core.scene.camera import PhotoCamera

    models = load_guidance_models(ModelConfig(base_model=str(tiny_base), inpaint_model=str(tiny_inpaint)),
                                  need_inpaint=True)
    camera = PhotoCamera(yaw_deg=90.0, pitch_deg=-10.0, fov_deg=60.0, width=32, height=24)
    photo = _outdoor_photo()
    config = OutpaintConfig(steps=3, resolution=32)
    prior = outdoor_panorama(photo, camera, 32)
    pano = outdoor_panorama(photo, camera, 32, outpaint=lambda ldr, seen: outpaint_panorama(ldr, seen, models, config))
    assert pano.ldr.shape == (32, 64, 3) and np.isfinite(pano.ldr).all()
    assert pano.ldr.min() >= 0 and pano.ldr.max() <= 1
    assert "outpainted" in pano.decisions["completion"] and "prior" in prior.decisions["completion"]
    # Only a model's painting counts as lights drawn in the unseen part (the cues keep its clipped texels).
    assert pano.painted and not prior.painted
    # The photo's region is the photo: equal to the prior path wherever its feather does not reach.
    import cv2

    core = cv2.erode(pano.seen.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert core.any() and np.array_equal(pano.ldr[core], prior.ldr[core])
    # The rest was painted (it is no longer the prior).
    assert np.abs(pano.ldr[pano.unseen] - prior.ldr[pano.unseen]).mean() > 1e-3
    # Known texels come back bit-exactly from outpaint_panorama itself.
    ldr = np.random.default_rng(0).uniform(0, 1, (32, 64, 3)).astype(np.float32)
    known = np.zeros((32, 64), bool)
    known[8:20, 20:40] = True
    out = outpaint_panorama(ldr, known, models, config)
    assert np.array_equal(out[known], ldr[known]) and not np.array_equal(out[~known], ldr[~known])


def _row_interpolating_painter(models, image, paint, config, generator):
    """A seam-unaware stand-in for the model: each row's painted run is the straight line between the
    known texels left and right of it (constant past the image's edges; no wrap-around)."""
    x = image[0].permute(1, 2, 0).numpy().copy()
    todo = paint[0, 0].numpy() > 0.5
    cols = np.arange(x.shape[1])
    for r in range(x.shape[0]):
        if todo[r].any() and (~todo[r]).any():
            for c in range(3):
                x[r, todo[r], c] = np.interp(cols[todo[r]], cols[~todo[r]], x[r, ~todo[r], c])
    return torch.from_numpy(x).permute(2, 0, 1)[None]


@pytest.mark.parametrize("band", [0.125, 0.0])
def test_the_wrap_seam_is_painted_again_across_u_0(monkeypatch, band):
    from scenefit.core.stages.light import outpaint as outpaint_module

    monkeypatch.setattr(outpaint_module, "inpaint", _row_interpolating_painter)
    ldr = np.zeros((32, 64, 3), np.float32)
    known = np.zeros((32, 64), bool)
    known[:, 10:20], known[:, 44:54] = True, True
    ldr[:, 10:20], ldr[:, 44:54] = [0.9, 0.2, 0.1], [0.1, 0.3, 0.9]
    out = outpaint_module.outpaint_panorama(ldr, known, None,
                                            outpaint_module.OutpaintConfig(resolution=32, seam_band_fraction=band))
    assert np.array_equal(out[known], ldr[known])
    jump, inner = _seam_jump(out, slice(None))
    if band > 0:   # across u = 0 = 1 the map jumps no more than between any other two neighbouring columns
        assert jump <= inner.max() + 1e-5, (jump, inner.max())
    else:          # the control: one pass that cannot see across the seam leaves a jump there
        assert jump > 3 * inner.max()


def test_outdoor_completion_falls_back_to_the_prior_without_weights(tmp_path, monkeypatch):
    empty = tmp_path / "empty-cache"
    empty.mkdir()
    from scenefit.core.stages.light.outpaint import OutpaintConfig

    models = ModelConfig(cache_dir=str(empty), local_files_only=True)
    config = LightConfig(scene_type="outdoor", map_height=16, models=models)
    result = estimate_light(_outdoor_photo(), (16, 20), config)
    info = result.decisions["outpainting"]
    assert info["asked"] == "auto" and not info["used"] and "not on this machine" in info["why"]
    assert "prior" in info["completion"]
    # Asked for explicitly, the model must be there: a clear error before any work.
    monkeypatch.setattr(estimate_module, "scene_type_cue", lambda *a: (_ for _ in ()).throw(AssertionError("work began")))
    with pytest.raises(ModelMissingError, match="--outpaint prior"):
        estimate_light(_outdoor_photo(), (16, 20), LightConfig(scene_type="outdoor", models=models,
                                                               outpaint=OutpaintConfig(completion_type="sd2")))


def test_estimate_light_outpaints_an_outdoor_map_with_the_model(tiny_base, tiny_inpaint):
    from scenefit.core.stages.light.outpaint import OutpaintConfig

    config = LightConfig(scene_type="outdoor", map_height=32,
                         models=ModelConfig(base_model=str(tiny_base), inpaint_model=str(tiny_inpaint)),
                         outpaint=OutpaintConfig(completion_type="sd2", steps=2, resolution=32))
    result = estimate_light(_outdoor_photo(), (16, 20), config)
    info = result.decisions["outpainting"]
    assert info["used"] and "outpainted" in info["completion"]
    assert result.hdr.shape == (32, 64, 3) and np.isfinite(result.hdr).all()


def test_fp16_models_give_finite_float32_gradients_and_outpaint(tiny_base, tiny_inpaint):
    from scenefit.core.stages.light.outpaint import OutpaintConfig, outpaint_panorama

    models = load_guidance_models(ModelConfig(base_model=str(tiny_base), inpaint_model=str(tiny_inpaint),
                                              dtype_type="fp16"), need_inpaint=True)
    scene = _scene()
    critic = DiffusionLightCritic(models, scene.cameras, ("a", "b"), DiffusionCriticConfig(model_resolution=32),
                                  photo=PHOTO, squares=scene.photo_squares(OBJECT_BOX))
    render, alpha = scene.render_view(torch.full((16, 32, 3), 2.0), 0)
    grad = critic(render[None], _request(scene, 0, ("a", "b"), alpha))
    assert grad.dtype == torch.float32 and torch.isfinite(grad).all() and float(grad.abs().sum()) > 0
    known = np.zeros((32, 64), bool)
    known[10:20, 10:30] = True
    out = outpaint_panorama(np.full((32, 64, 3), 0.5, np.float32), known, models, OutpaintConfig(steps=2, resolution=32))
    assert out.dtype == np.float32 and np.isfinite(out).all()
