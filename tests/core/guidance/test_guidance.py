"""Diffusion critics with tiny random-weight models loaded through the real loading code."""
from __future__ import annotations

import numpy as np
import math

import pytest
import torch

from scenefit.core.base.errors import InputError, ModelMissingError
from scenefit.core.guidance import (CriticConfig, LoraCritic, ModelConfig, ReferenceInjector, ScoreCritic,
                                    camera_condition, load_guidance_models, locate_models, models_available)
from scenefit.core.scene.placement import Placement
from conftest import shared_tiny_pair
from scenefit.core.guidance.views import (global_view, inpainting_input, latent_mask, local_view,
                                          masked_image, sample_crops)
from scenefit.core.guidance.weighting import (add_noise, guard_gradient, interpolation_lambda, predicted_x0,
                                              sample_timestep)


@pytest.fixture(scope="module")
def tiny_folders(tmp_path_factory):
    return shared_tiny_pair()


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """Torch's CPU kernels split sums by thread count, so a UNet's output changes in the last bits with
    it (seen: 3.2777727 on one thread, 3.2777786 on two). With the count fixed for the module, the same
    ops on the same inputs give the same bits on any machine, so a comparison of two calls that do the
    same arithmetic can be exact; comparisons of two different implementations use ROUNDING below."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# Two float32 implementations of the same attention (diffusers' processor and ours, which splits the
# batch's rows) differ only by rounding: about 2^-24 relative per operation, compounded through the
# tiny UNet's ~40 layers, i.e. ~1e-6 of the output's scale (measured: 1.0e-6 to 1.2e-6 on 1 and 2
# threads). 1e-5 of the scale leaves a margin of 8 for other CPUs' summation orders, and lies 1000x
# below the effects these tests look for (reference injection changes the output by ~1e-2 of it).
ROUNDING = 1e-5


@pytest.fixture()
def models(tiny_folders):
    base, inpaint = tiny_folders
    # fp32: these tests check the critics' arithmetic exactly (bf16, "auto" on CPUs that compute it, is
    # checked against fp32 in tests/core/stages/adapt/test_adapt.py).
    return load_guidance_models(ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type="fp32"),
                                need_inpaint=True)


def _inputs(models, seed=0):
    g = torch.Generator().manual_seed(seed)
    latents = torch.randn(1, 4, 16, 16, generator=g).requires_grad_(True)
    noise = torch.randn(1, 4, 16, 16, generator=g)
    return latents, noise, models.embed("a leather sofa in a swamp"), models.embed("")


def test_loads_tiny_models_through_the_real_loader(models):
    assert models.unet.config.in_channels == 4 and models.inpaint_unet.config.in_channels == 9
    from scenefit.core.guidance.models import cpu_computes_bf16

    # "auto": bf16 where the CPU computes it (AVX512-BF16 / AMX), else fp32; the fixture asks fp32.
    assert ModelConfig().dtype() == (torch.bfloat16 if cpu_computes_bf16() else torch.float32)
    assert models.dtype == torch.float32 == models.unet.dtype and models.device.type == "cpu"
    emb = models.embed("a sofa")
    assert emb.shape == (1, 77, 32) and torch.isfinite(emb).all()
    assert not torch.equal(emb, models.embed("a chair"))
    models.release_text_encoder()
    assert models.embed("a sofa") is emb  # cached embeddings survive the release
    with pytest.raises(RuntimeError, match="released"):
        models.embed("something new")
    assert not any(p.requires_grad for p in models.unet.parameters())


def test_missing_weights_give_a_clear_message(tmp_path, monkeypatch, tiny_folders):
    empty_cache = tmp_path / "empty-cache"
    empty_cache.mkdir()
    config = ModelConfig(cache_dir=str(empty_cache), local_files_only=True)
    with pytest.raises(ModelMissingError) as info:
        locate_models(config, need_inpaint=True)
    message = str(info.value)
    assert "stabilityai/stable-diffusion-2-base" in message and str(empty_cache) in message
    assert "scenefit models download" in message and "hf download stabilityai/stable-diffusion-2-base" in message
    assert "--guidance-type none" in message and "about 5.2 GB" in message
    # HF_HUB_OFFLINE changes nothing: a run never downloads.
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(ModelMissingError, match="scenefit models download"):
        locate_models(ModelConfig(cache_dir=str(empty_cache)), need_inpaint=False)
    ok, why = models_available(ModelConfig(cache_dir=str(empty_cache)))
    assert not ok and "stable-diffusion-2-base" in why
    # A local folder that lacks a part names it; the inpainting model is checked too.
    broken = tmp_path / "broken"
    (broken / "unet").mkdir(parents=True)
    (broken / "unet" / "config.json").write_text("{}")   # (a config without weights: the loader reads both)
    with pytest.raises(ModelMissingError, match=r"lacks unet/, vae/, text_encoder/, tokenizer/, scheduler/"):
        locate_models(ModelConfig(base_model=str(broken)), need_inpaint=False)
    with pytest.raises(ModelMissingError, match="inpainting"):
        locate_models(ModelConfig(base_model=str(tiny_folders[0]), inpaint_model=str(tmp_path / "nope")), True)
    ok, where = models_available(ModelConfig(base_model=str(tiny_folders[0]), inpaint_model=str(tiny_folders[1])))
    assert ok and str(tiny_folders[0]) in where
    # Online, a missing model is still not downloaded: only `scenefit models download` (or the
    # Preferences' Download) fetches, when asked; every command treats the models alike.
    import huggingface_hub

    asked = []

    def lookup(*_, local_files_only=False, **__):
        asked.append(local_files_only)
        raise OSError("not in the cache")

    monkeypatch.delenv("HF_HUB_OFFLINE")
    monkeypatch.setattr(huggingface_hub, "snapshot_download", lookup)
    with pytest.raises(ModelMissingError) as info:
        locate_models(ModelConfig(cache_dir=str(empty_cache)), need_inpaint=True)
    assert asked == [True] and "\n" not in str(info.value) and "scenefit models download" in str(info.value)


def test_sds_gradient_is_w_t_times_eps_phi_minus_eps(models):
    critic = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds", reference_type="none"))
    latents, noise, cond, uncond = _inputs(models)
    t = 600
    out = critic(latents, t, noise, cond, uncond)
    out.loss.backward()
    # The same deterministic UNet called by hand.
    a = float(models.scheduler.alphas_cumprod[t])
    x_t = (a ** 0.5) * latents.detach() + ((1 - a) ** 0.5) * noise
    with torch.no_grad():
        pred = models.unet(torch.cat([x_t, x_t]), torch.full((2,), t), encoder_hidden_states=torch.cat([uncond, cond])).sample
    eps_phi = pred[:1] + 7.5 * (pred[1:] - pred[:1])
    expected = (1 - a) * (eps_phi - noise)
    assert latents.grad.shape == latents.shape and torch.isfinite(latents.grad).all()
    # The critic does this arithmetic with the same ops on the same inputs: the same bits.
    torch.testing.assert_close(latents.grad, expected, rtol=0, atol=0)
    assert expected.abs().max() > 1e-3  # not trivially zero
    # A second scale on the loss scales the gradient (it is a real autograd node); x3 is exact in float32
    # up to one rounding of each product, which 3 * expected rounds the same way.
    latents.grad = None
    (3.0 * critic(latents, t, noise, cond, uncond).loss).backward()
    torch.testing.assert_close(latents.grad, 3 * expected, rtol=0, atol=0)


def _lora(models, seed=0):
    return LoraCritic(models.unet, rank=4, lr=1e-2, condition_dropout=0.1, seed=seed)


def _train(lora, models, steps=2):
    g = torch.Generator().manual_seed(5)
    cond = models.embed("a sofa")
    condition = camera_condition([0, -2, 0.5], [0, 1, -0.25])
    for i in range(steps):
        lora.train_step(torch.randn(1, 4, 16, 16, generator=g), cond, condition, 500, torch.randn(1, 4, 16, 16, generator=g),
                        float(models.scheduler.alphas_cumprod[500]), drop_condition=i == 1)
        lora.step()


def test_lora_step_changes_lora_weights_only(models):
    x, t, text = torch.randn(1, 4, 16, 16, generator=torch.Generator().manual_seed(1)), torch.tensor([500]), models.embed("a sofa")
    with torch.no_grad():
        base_output = models.unet(x, t, encoder_hidden_states=text).sample
    lora = _lora(models)
    base_before = {n: p.detach().clone() for n, p in models.unet.named_parameters() if "lora_" not in n}
    lora_before = {n: p.detach().clone() for n, p in models.unet.named_parameters() if "lora_" in n}
    emb_before = [p.detach().clone() for p in lora.embedding.parameters()]
    assert lora_before and len(base_before) > 10
    _train(lora, models)
    after = dict(models.unet.named_parameters())
    for n, v in base_before.items():
        assert torch.equal(after[n], v), f"base weight {n} changed"
    changed = [n for n, v in lora_before.items() if not torch.equal(after[n], v)]
    assert len(changed) == len(lora_before)
    assert any(not torch.equal(a, b) for a, b in zip(emb_before, lora.embedding.parameters()))
    # The adapter is off outside `active()`: there the UNet is ε_φ, the base model, bit for bit.
    x, t, text = torch.randn(1, 4, 16, 16, generator=torch.Generator().manual_seed(1)), torch.tensor([500]), models.embed("a sofa")
    with torch.no_grad():
        outside = models.unet(x, t, encoder_hidden_states=text).sample
        with lora.active():
            inside = models.unet(x, t, encoder_hidden_states=text,
                                 class_labels=camera_condition([0, -2, 0.5], [0, 1, -0.25])[None]).sample
    assert torch.equal(outside, base_output) and not torch.equal(inside, outside)


def test_vsd_with_lambda_zero_is_sds_and_lambda_one_is_not(models):
    lora = _lora(models)
    _train(lora, models)  # ε_ψ now differs from ε_φ
    latents, noise, cond, uncond = _inputs(models, seed=1)
    condition = camera_condition([0, -2, 0.5], [0, 1, -0.25])
    sds = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds", reference_type="none"))
    vsd = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="vsd", reference_type="none"), lora=lora)
    g_sds = sds(latents, 700, noise, cond, uncond).grad
    g_vsd0 = vsd(latents, 700, noise, cond, uncond, lam=0.0, condition=condition).grad
    g_vsd1 = vsd(latents, 700, noise, cond, uncond, lam=1.0, condition=condition).grad
    torch.testing.assert_close(g_vsd0, g_sds, rtol=0, atol=0)
    assert (g_vsd1 - g_sds).abs().max() > 1e-4
    # λ = 1: ε̂ is ε_ψ itself.
    out = vsd(latents, 700, noise, cond, uncond, lam=1.0, condition=condition)
    eps_psi = vsd.predict_psi(add_noise(latents.detach(), noise, float(vsd.alpha_bar[700])), 700, cond, uncond, condition)
    torch.testing.assert_close(out.eps_hat, eps_psi)
    assert interpolation_lambda(0.0, 0.3, "vsd") == 1.0 and interpolation_lambda(1.0, 0.3, "vsd") == pytest.approx(0.3)
    assert interpolation_lambda(0.5, 0.3, "sds") == 0.0


def test_reference_injection_control_scale(models):
    g = torch.Generator().manual_seed(3)
    x = torch.randn(2, 4, 16, 16, generator=g)
    ref = torch.randn(2, 4, 16, 16, generator=g)
    text = torch.cat([models.embed(""), models.embed("a sofa")])
    t = torch.full((2,), 500)
    with torch.no_grad():
        plain = models.unet(x, t, encoder_hidden_states=text).sample
    injector = ReferenceInjector(models.unet, fraction=1.0)
    assert len(injector.injected) == 4  # one down, one middle and two up transformer blocks
    critic = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds", control_scale=1.0),
                         injector=injector)
    # No layout: the installed processors are plain attention.
    with torch.no_grad():
        again = models.unet(x, t, encoder_hidden_states=text).sample
    scale = float(plain.abs().max())
    torch.testing.assert_close(again, plain, rtol=0, atol=ROUNDING * scale)   # our attention and diffusers'
    out_sc1 = critic._unet(x, 500, text, ref, (0,), None, None)
    # s_c = 1: the unconditional row is the uninjected one (up to the two implementations' rounding);
    # the text row is injected.
    torch.testing.assert_close(out_sc1[:1], plain[:1], rtol=0, atol=ROUNDING * scale)
    assert (out_sc1[1:] - plain[1:]).abs().max() > 100 * ROUNDING * scale
    critic0 = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds", control_scale=0.0),
                          injector=injector)
    out_sc0 = critic0._unet(x, 500, text, ref, (0,), None, None)
    assert (out_sc0[:1] - plain[:1]).abs().max() > 100 * ROUNDING * scale
    torch.testing.assert_close(out_sc0[1:], out_sc1[1:], rtol=0, atol=0)  # s_c only touches the ∅ branch
    # p = 0 injects nothing.
    none = ReferenceInjector(models.unet, fraction=0.0)
    assert none.injected == []
    critic_p0 = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds"), injector=none)
    torch.testing.assert_close(critic_p0._unet(x, 500, text, ref, (0,), None, None), plain, rtol=0,
                               atol=ROUNDING * scale)
    assert len(ReferenceInjector(models.unet, fraction=0.5).injected) == 2


def test_inpainting_input_has_nine_channels_with_the_mask_on_the_object(models):
    h = 24
    rgb = torch.zeros(h, h, 3)
    alpha = torch.zeros(h, h, 1)
    alpha[8:16, 8:16] = 1.0
    rgb[8:16, 8:16] = 0.7
    rgb.requires_grad_(True)
    photo = np.full((60, 90, 3), 0.3, np.float32)
    ox, oy, oside = 30.0, 15.0, 30.0          # the object's square: half the photo's height, centred
    crops = sample_crops(photo.shape[:2], (ox, oy, oside), 3, np.random.default_rng(0))
    for x0, y0, side in crops:  # every crop holds the whole object
        assert x0 <= ox + 1e-6 and y0 <= oy + 1e-6 and x0 + side >= ox + oside - 1e-6 and y0 + side >= oy + oside - 1e-6
    # Several scales: crop i's side lies in the i-th third of [object side 30, photo height 60].
    assert [30 + 10 * i <= side <= 30 + 10 * (i + 1) for i, (_, _, side) in enumerate(crops)] == [True] * 3
    sides = np.array([[c[2] for c in sample_crops(photo.shape[:2], (ox, oy, oside), 2, np.random.default_rng(s))]
                      for s in range(200)])
    assert sides[:, 0].max() <= 45 < sides[:, 1].min() and sides.min() < 31 and sides.max() > 59
    # A crop centred on the object (x 30..60 of the photo): the object's square spans pixels 8..24 of 32.
    rect = (ox, oy, oside, oside)  # the 24 px layer covers the object's square
    image, obj_alpha = global_view(rgb, alpha, rect, photo, np.ones_like(photo), (15.0, 0.0, 60.0), 32)
    assert image.shape == (1, 3, 32, 32) and obj_alpha.shape == (1, 1, 32, 32)
    assert obj_alpha[0, 0, 16, 16] > 0.9 and obj_alpha[0, 0, 2, 2] == 0
    image.sum().backward()
    assert rgb.grad is not None and rgb.grad[10, 10].abs().sum() > 0 and torch.isfinite(rgb.grad).all()
    mask = latent_mask(obj_alpha, (16, 16))
    assert mask.shape == (1, 1, 16, 16) and set(mask.unique().tolist()) == {0.0, 1.0}
    assert mask[0, 0, 8, 8] == 1 and mask[0, 0, 0, 0] == 0
    blank = masked_image(image, obj_alpha)
    assert torch.allclose(blank[0, :, 16, 16], torch.full((3,), 0.5))
    x_t = torch.randn(1, 4, 16, 16)
    masked_latents = torch.randn(1, 4, 16, 16)
    sample = inpainting_input(x_t, mask, masked_latents)
    assert sample.shape == (1, 9, 16, 16)
    assert torch.equal(sample[:, :4], x_t) and torch.equal(sample[:, 4:5], mask) and torch.equal(sample[:, 5:], masked_latents)
    # The 9-channel UNet accepts it through the critic.
    critic = ScoreCritic(models.inpaint_unet, models.scheduler, CriticConfig(critic_type="sds", reference_type="none"))
    lat = torch.randn(1, 4, 16, 16, requires_grad=True)
    out = critic(lat, 800, torch.randn(1, 4, 16, 16), models.embed("a sofa in a swamp"), models.embed(""),
                 extra=(mask, masked_latents))
    assert out.grad.shape == lat.shape and torch.isfinite(out.grad).all()
    with pytest.raises(InputError):
        inpainting_input(x_t, mask[..., :8, :8], masked_latents)


def test_local_view_composites_over_solid_colour():
    rgb = torch.zeros(8, 8, 3)
    alpha = torch.zeros(8, 8, 1)
    image = local_view(rgb, alpha, (0.5, 0.5, 0.5), size=16)
    assert image.shape == (1, 3, 16, 16)
    # Grey 0.5 through the sRGB curve and back in float32: a few ulps of 0.5 (6e-8 each); the resize of a
    # constant image is exact.
    torch.testing.assert_close(image, torch.full_like(image, 0.5), rtol=0, atol=1e-6)


def test_guard_rails_at_extreme_timesteps_and_fp16(models):
    critic = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="sds", reference_type="none",
                                                                     grad_clip=0.5))
    latents, noise, cond, uncond = _inputs(models)
    for t in (0, 1, 998, 999):
        out = critic(latents, t, noise, cond, uncond)
        assert torch.isfinite(out.grad).all() and out.grad.abs().max() <= 0.5
        x0 = predicted_x0(add_noise(latents.detach(), noise, float(critic.alpha_bar[t])), out.eps_phi,
                          float(critic.alpha_bar[t]))
        assert torch.isfinite(x0).all()
    with pytest.raises(InputError):
        critic(latents, 1000, noise, cond, uncond)
    rng = np.random.default_rng(0)
    assert all(30 <= sample_timestep(rng, (30, 990), p) <= 990 for p in np.linspace(0, 1, 20))
    early = [sample_timestep(rng, (500, 990), 0.0) for _ in range(20)]
    late = [sample_timestep(rng, (500, 990), 1.0) for _ in range(20)]
    assert min(early) > max(late)  # annealed from high to low noise
    # fp16 overflow: infinities and NaNs become zeros, counted.
    big = torch.tensor([6.0e4, 6.0e4, 1.0], dtype=torch.float16)
    overflow = big * 2  # inf in fp16
    grad, bad = guard_gradient(torch.stack([overflow, big - big * float("nan")]))
    assert bad == 5 and torch.isfinite(grad).all() and grad.dtype == torch.float32
    assert float(predicted_x0(torch.ones(1), torch.ones(1), 0.0)) < 1e4  # ᾱ -> 0 kept finite


def test_fp16_models_on_cpu_give_finite_float32_gradients(tiny_folders):
    base, inpaint = tiny_folders
    models = load_guidance_models(ModelConfig(base_model=str(base), dtype_type="fp16"), need_inpaint=False)
    assert models.unet.dtype == torch.float16
    lora = LoraCritic(models.unet, seed=0)
    critic = ScoreCritic(models.unet, models.scheduler, CriticConfig(critic_type="vsd", reference_type="none"), lora=lora)
    latents = torch.randn(1, 4, 16, 16, requires_grad=True)
    out = critic(latents, 999, torch.randn(1, 4, 16, 16), models.embed("a sofa"), models.embed(""), lam=1.0,
                 condition=camera_condition([0, -2, 0], [0, 1, 0]))
    assert out.grad.dtype == torch.float32 and torch.isfinite(out.grad).all()
    out.loss.backward()
    assert torch.isfinite(latents.grad).all()
    assert all(p.dtype == torch.float32 for p in lora.parameters())
    # The LoRA's own step takes float32 rendered latents against the fp16 UNet.
    before = [p.detach().clone() for p in lora.parameters()]
    loss = lora.train_step(torch.randn(1, 4, 16, 16), models.embed("a sofa"), camera_condition([0, -2, 0], [0, 1, 0]),
                           500, torch.randn(1, 4, 16, 16), float(models.scheduler.alphas_cumprod[500]),
                           drop_condition=False)
    lora.step()
    assert math.isfinite(loss)
    assert any(not torch.equal(a, b) for a, b in zip(before, lora.parameters()))


def test_configs_are_validated_when_built():
    with pytest.raises(InputError, match="critic_type"):
        CriticConfig(critic_type="dreamfusion")
    with pytest.raises(InputError, match="control_scale"):
        CriticConfig(control_scale=2.0)
    with pytest.raises(InputError, match="dtype_type"):
        ModelConfig(dtype_type="fp8")
    with pytest.raises(InputError, match="placement"):
        Placement(center=(1.5, 0.5))
