"""The adapt stage end to end with tiny random-weight models, 16-32 px renders and 2 spp."""
from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from scenefit.core.stages.adapt import (GENERATE_STAGES, SCENE_STAGES, AdaptConfig, AdaptInputs, AdaptSystem, StageSpec,
                                 adapt_texture, edit_prompt, sample_camera, sample_view,
                                 spherical_gaussian_environment, stage_at, view_suffix)
from scenefit.core.base.errors import Cancelled, InputError, ModelMissingError
from scenefit.core.guidance import CriticConfig, ModelConfig
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.placement import Placement
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.texture import NeuralTexture
from conftest import shared_tiny_pair

TINY_STAGES = (StageSpec(0.5, 16, 2, (30, 990)), StageSpec(0.5, 32, 2, (500, 990)))


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory):
    return shared_tiny_pair()


@pytest.fixture(scope="module")
def asset():
    mesh = uv_sphere(segments=16, rings=8)
    raster = rasterize_uv(mesh, 32)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=0)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    return mesh, raster, texture, photo


def _config(tiny_models, **overrides) -> AdaptConfig:
    base, inpaint = tiny_models
    values = dict(prompt="a mossy sphere in a swamp", iterations=4, stages=TINY_STAGES, model_resolution=32,
                  views=4, views_per_step=1, checkpoint_every=2, preview_every=2, lr_texture=1e-2,
                  models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))
    values.update(overrides)
    return AdaptConfig(**values)


def _inputs(asset, **overrides) -> AdaptInputs:
    mesh, raster, texture, photo = asset
    values = dict(mesh=mesh, raster=raster, texture=texture, photo=photo, placement=Placement((0.5, 0.6), 0.5))
    values.update(overrides)
    return AdaptInputs(**values)


@pytest.fixture
def one_render_thread():
    """Mitsuba scatters texture gradients with atomic adds from its worker threads, and their order,
    hence the float rounding of each sum, varies run to run (seen: 1e-6..4e-6 on a few texels, more on
    other machines). On one thread the order is fixed, so two runs of the same code must agree bit for
    bit, and a comparison can be exact instead of guessing a tolerance per machine."""
    import drjit as dr

    before = dr.thread_count()
    dr.set_thread_count(1)
    yield
    dr.set_thread_count(before)


def _maps(texture, raster):
    with torch.no_grad():
        return texture.texture(raster.position, raster.border, raster.fill_index)


def test_short_scene_run_changes_the_texture_and_resumes_exactly(tiny_models, asset, tmp_path, one_render_thread):
    mesh, raster, texture, photo = asset
    before = _maps(texture, raster).clone()
    config = _config(tiny_models)
    events = []
    full = adapt_texture(_inputs(asset), config, progress=events.append)
    after = _maps(full.texture, raster)
    assert torch.isfinite(after).all()
    assert (after - before).abs().max() > 1e-4, "the texture did not change"
    assert torch.equal(_maps(texture, raster), before), "the input texture was modified"
    assert full.iterations == 4 and len(full.history) == 4
    assert all(np.isfinite(h["local_grad_norm"]) and np.isfinite(h["global_grad_norm"]) for h in full.history)
    assert all("lora_loss" in h for h in full.history)
    assert [e.step for e in events] == [1, 2, 3, 4]
    assert events[1].preview is not None and events[1].preview.shape == (32, 32, 3) and events[0].preview is None
    assert full.decisions["reference_injection"].choice == 4   # the tiny UNet's 4 self-attention layers
    # Every phase is timed, and the phases are parts of the run (they cannot add up to more than it).
    # ("trace": the loop renderer's G-buffers, the default renderer's, traced once per view.)
    assert set(full.timings) == {"constants", "trace", "render", "vae", "unet", "vae_backward", "render_backward", "lora",
                                 "step"}
    assert sum(full.timings.values()) <= full.seconds
    # The coarse stage renders 16 px, the fine one 32 px.
    assert [h["stage_size"] for h in full.history] == [16, 16, 32, 32]

    # Interrupted after iteration 2 (cancel between iterations), then resumed from the checkpoint.
    cancel = threading.Event()
    seen = []

    def stop_after_two(event):
        seen.append(event.step)
        if event.step == 2:
            cancel.set()

    with pytest.raises(Cancelled):
        adapt_texture(_inputs(asset), config, progress=stop_after_two, cancel=cancel, checkpoint_dir=tmp_path)
    assert seen == [1, 2], "iterations ran after cancel"
    assert (tmp_path / "adapt_checkpoint.pt").is_file()
    resumed = adapt_texture(_inputs(asset), config, checkpoint_dir=tmp_path)
    assert resumed.resumed_from == 2 and len(resumed.history) == 4
    # Bit for bit on one render thread (a broken resume differs by ~1e-2).
    assert torch.equal(_maps(resumed.texture, raster), after)
    # Other settings refuse to resume from that checkpoint.
    with pytest.raises(InputError, match="other settings"):
        adapt_texture(_inputs(asset), _config(tiny_models, seed=1), checkpoint_dir=tmp_path)


def test_cancel_stops_before_the_first_step(tiny_models, asset, tmp_path):
    cancel = threading.Event()
    cancel.set()
    events = []
    with pytest.raises(Cancelled):
        adapt_texture(_inputs(asset), _config(tiny_models, iterations=50), cancel=cancel, progress=events.append,
                      checkpoint_dir=tmp_path)
    # Cancelled before the first step: no iteration reported, no checkpoint written (what ran is not
    # judged by the clock, which depends on the machine and its load).
    assert events == [] and not any(tmp_path.iterdir())


def test_generate_and_edit_modes(tiny_models, asset):
    mesh, raster, texture, _ = asset
    generate = stage_config("adapt", "draft", mode_type="generate", prompt="a red umbrella", iterations=2, stages=TINY_STAGES,
                            model_resolution=32, light_type="random", light_random_p=1.0, critic=CriticConfig(
                                critic_type="sds", reference_type="none"),
                            models=_config(tiny_models).models)
    assert generate.views == 72 and generate.fov_range == (0.6, 1.21) and generate.views_type == "local"
    result = adapt_texture(AdaptInputs(mesh=mesh, raster=raster), generate)
    assert torch.isfinite(_maps(result.texture, raster)).all() and "lora_loss" not in result.history[0]
    edit = stage_config("adapt", "draft", mode_type="edit", object_prompt="a leather sofa", instruction="add dust to the sofa",
                        iterations=2, stages=(StageSpec(1.0, 16, 2, (500, 990)),), model_resolution=32,
                        models=_config(tiny_models).models)
    assert edit.effective_prompt == "a leather sofa, with dust to the sofa"
    result = adapt_texture(AdaptInputs(mesh=mesh, raster=raster, texture=texture), edit)
    assert result.decisions["reference_injection"].choice > 0 and torch.isfinite(_maps(result.texture, raster)).all()


def test_distributed_single_process_gloo(tiny_models, asset, tmp_path, one_render_thread):
    """torch.distributed with world size 1: the same code path, the same result."""
    import torch.distributed as dist

    config = _config(tiny_models, iterations=2, views_type="local", checkpoint_every=0)
    alone = adapt_texture(_inputs(asset), config)
    dist.init_process_group("gloo", init_method=f"file://{tmp_path / 'pg'}", rank=0, world_size=1)
    try:
        spread = adapt_texture(_inputs(asset), config)
    finally:
        dist.destroy_process_group()
    assert spread.decisions["world_size"].choice == 1
    assert torch.equal(_maps(spread.texture, asset[1]), _maps(alone.texture, asset[1]))


def test_a_step_averages_its_views(tiny_models, asset, one_render_thread):
    """views_per_step = 2: the step's texture gradient is exactly the sum of each view's (each weighted 1/2),
    and the two views differ (their own camera, background, t and noise)."""
    config = _config(tiny_models, views_per_step=2, checkpoint_every=0, preview_every=0)
    system = AdaptSystem.build(_inputs(asset), config)
    views = [system.sample(0, j) for j in range(2)]
    assert views[0].t != views[1].t or views[0].camera != views[1].camera

    def grads(indices):
        system.optimizer.zero_grad(set_to_none=True)
        for j in indices:
            system.train_view(views[j])
        return [p.grad.clone() for p in system.texture.parameters()]

    g0, g1, both = grads([0]), grads([1]), grads([0, 1])
    assert any((a - b).abs().max() > 0 for a, b in zip(g0, g1))
    assert all(torch.equal(a + b, ab) for a, b, ab in zip(g0, g1, both))
    metrics = system.step(0)
    assert len(metrics["t"]) == 2 and system.decisions()["views_per_step"].choice == 2


def test_dry_run_prints_the_papers_schedule(capsys):
    import json

    from scenefit.cli import main

    assert main(["adapt", "--mode", "scene", "--preset", "final", "--prompt", "a sofa", "--dry-run"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["schedule"] == [{"fraction": 1.0, "iterations": 4000, "t_range": [500, 990], "t_anneal": "linear",
                                  "render_size": 512, "spp": 128, "views_per_step": 4, "global_crops": 2}]
    assert main(["adapt", "--mode", "generate", "--preset", "draft", "--prompt", "a sofa", "--dry-run"]) == 0
    stages = json.loads(capsys.readouterr().out)["schedule"]
    assert [(s["render_size"], s["t_range"]) for s in stages] == [(128, [30, 990]), (256, [500, 990])]
    assert main(["light", "--preset", "final", "--dry-run"]) == 0
    light = json.loads(capsys.readouterr().out)["config"]
    assert light["optimise"]["iterations"] == 2000 and light["optimise"]["lr"] == 0.01
    assert light["optimise"]["t_range"] == [750, 990]
    # Without --dry-run the inputs are required, and asked for in one sentence.
    assert main(["adapt", "--prompt", "a sofa"]) == 2
    assert "needs asset and --out" in capsys.readouterr().err


def test_missing_weights_stop_before_any_work(tmp_path, asset, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    config = AdaptConfig(prompt="a sofa", models=ModelConfig(cache_dir=str(tmp_path)))
    events = []
    with pytest.raises(ModelMissingError, match="stable-diffusion-2-base"):
        adapt_texture(_inputs(asset), config, progress=events.append)
    assert events == []


def test_config_validation_and_helpers():
    with pytest.raises(InputError, match="prompt"):
        AdaptConfig(prompt="")
    with pytest.raises(InputError, match="mode_type"):
        AdaptConfig(prompt="x", mode_type="stylise")
    with pytest.raises(InputError, match="add up to 1"):
        AdaptConfig(prompt="x", stages=(StageSpec(0.5, 64, 4, (30, 990)),))
    with pytest.raises(InputError, match="views_type 'local'"):
        AdaptConfig(prompt="x", mode_type="generate")
    with pytest.raises(InputError):
        StageSpec(1.0, 64, 4, (30, 1200))
    with pytest.raises(InputError, match="prompt"):
        stage_config("adapt", "final")  # no prompt
    draft = stage_config("adapt", "draft", prompt="x")
    assert (draft.iterations < stage_config("adapt", "balanced", prompt="x").iterations
            < stage_config("adapt", "final", prompt="x").iterations)
    # "final" is the appendix's setup (m): 512 px, 128 spp, t in [500, 990] throughout, 4 views per step.
    paper = stage_config("adapt", "final", prompt="x")
    assert paper == AdaptConfig(prompt="x")
    assert paper.stages == SCENE_STAGES == (StageSpec(1.0, 512, 128, (500, 990)),)
    assert paper.views_per_step == 4 and paper.global_crops >= 2 and paper.iterations == 4000
    assert paper.lr_texture == 1e-3 and paper.lr_lora == 1e-4 and paper.views == 24 and paper.fov_range == (1.0, 1.21)
    # Scene-agnostic generation keeps the coarse-to-fine schedule (20% at 256 px, t in [30, 990]).
    generate = stage_config("adapt", "final", mode_type="generate", prompt="x")
    assert generate.stages == GENERATE_STAGES
    assert [stage_at(generate, i).render_size for i in (0, 799, 800, 3999)] == [256, 256, 512, 512]
    # Noise annealed from high to low over the run, inside [500, 990].
    ts = [[sample_view(paper, it, v, 8, None, None, None).t for v in range(4)] for it in (0, 1999, 3999)]
    assert min(ts[0]) >= 929 and 684 <= min(ts[1]) and max(ts[1]) <= 806 and max(ts[2]) <= 561
    assert min(min(t) for t in ts) >= 500
    rng = np.random.default_rng(0)
    cams = [sample_camera(paper, rng, 64) for _ in range(50)]
    assert {c.azimuth_deg % 15 for c in cams} == {0.0} and all(1.0 <= c.fov_multiplier <= 1.21 for c in cams)
    assert view_suffix(10) == "front view" and view_suffix(180) == "back view" and view_suffix(-90) == "side view"
    assert edit_prompt("a cottage", "make it snowy") == "a cottage, snowy"
    env = spherical_gaussian_environment((0.25, 0.3, 0.08, 12.0, 0.8), 16)
    assert env.shape == (16, 32, 3) and env.min() >= 0.8 - 1e-6 and env.max() > 10
    with pytest.raises(InputError, match="photo"):
        _inputs((uv_sphere(), rasterize_uv(uv_sphere(), 16),
                  NeuralTexture(stage_config("texture", "draft", resolution=16)), None),
                placement=None).validate(AdaptConfig(prompt="x"))
    with pytest.raises(InputError, match="convert the asset first"):
        _inputs((uv_sphere(), rasterize_uv(uv_sphere(), 16), None, None)).validate(AdaptConfig(prompt="x"))


def test_cli_adapt_and_demo_guidance(tiny_models, asset, tmp_path, monkeypatch, capsys):
    from scenefit.cli import main
    from scenefit.core.data.asset_io import save_asset_folder
    from scenefit.core.data.imageio import write_image
    from scenefit.core.data.maps import PBRMaps
    from scenefit.core.texture import save_neural_texture

    mesh, raster, texture, photo = asset
    folder = tmp_path / "asset"
    grey = np.full((32, 32, 3), 0.5, np.float32)
    save_asset_folder(mesh, PBRMaps(base_color=grey, roughness=0.5, metallic=0.0), folder)
    save_neural_texture(texture, tmp_path / "texture.pt")
    write_image(tmp_path / "photo.png", photo)
    base, inpaint = tiny_models
    args = ["adapt", str(folder), "--texture", str(tmp_path / "texture.pt"), "--prompt", "a mossy ball",
            "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.6", "--object-size", "0.5", "--preset", "draft",
            "--iterations", "2",
            "--model-resolution", "32", "--render-size", "16", "--base-model", str(base), "--inpaint-model",
            str(inpaint), "--out", str(tmp_path / "out"), "--quiet"]
    assert main(args) == 0
    assert (tmp_path / "out" / "maps" / "base_color.png").is_file() and (tmp_path / "out" / "report.json").is_file()
    assert (tmp_path / "out" / "checkpoint" / "adapt_checkpoint.pt").is_file()
    # `demo --guidance sd2` with no weights stops before any work with the clear message.
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty"))
    capsys.readouterr()
    assert main(["demo", "--guidance", "sd2", "--out", str(tmp_path / "demo"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "stabilityai/stable-diffusion-2-base" in err and "Traceback" not in err
    assert not (tmp_path / "demo").exists()


# -- cost: the constant work of the fixed view bank, half-precision frozen weights ------

def _cost_config(tiny_models, dtype_type: str = "fp32", **overrides) -> AdaptConfig:
    """One bank view (so every step comes back to it), one stage, fp32 unless asked."""
    base, inpaint = tiny_models
    values = dict(iterations=3, stages=(StageSpec(1.0, 32, 2, (500, 990)),), views=1, view_variants=1,
                  checkpoint_every=0, preview_every=0,
                  models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type=dtype_type))
    values.update(overrides)
    return _config(tiny_models, **values)


def test_the_view_bank_is_fixed_by_the_seed_and_spans_the_papers_azimuths(tiny_models):
    from scenefit.core.stages.adapt.sampling import draw_view_bank

    config, box = _cost_config(tiny_models, views=24, view_variants=2), (20.0, 10.0, 16.0)
    bank = draw_view_bank(config, (48, 64), box)
    assert len(bank) == 48 and bank == draw_view_bank(config, (48, 64), box)
    assert sorted({b.azimuth_deg for b in bank}) == [15.0 * k for k in range(24)]
    assert all(len(b.crops) == config.global_crops for b in bank)
    assert bank != draw_view_bank(_cost_config(tiny_models, views=24, view_variants=2, seed=1), (48, 64), box)


def test_cached_constant_work_gives_the_same_steps_as_recomputing_it(tiny_models, asset, one_render_thread):
    """One bank view, three steps: the cached run computes its constants (reference latents, normal
    weights, crop masks, masked-photo latents) once and reuses them twice; the uncached run recomputes
    them every step by the same code. Equal bit for bit (one render thread)."""
    config = _cost_config(tiny_models)
    runs = {}
    for cache in (True, False):
        system = AdaptSystem.build(_inputs(asset), config, cache_constants=cache)
        history = [system.step(i) for i in range(config.iterations)]
        runs[cache] = (system.constants, [p.detach().clone() for p in system.texture.parameters()], history)
    (cached, after, history), (uncached, after_uncached, history_uncached) = runs[True], runs[False]
    assert (cached.misses, cached.hits) == (1, 2) and (uncached.misses, uncached.hits) == (3, 0)
    assert all(torch.equal(a, b) for a, b in zip(after, after_uncached)) and history == history_uncached
    assert any((a - b).abs().max() > 0 for a, b in zip(after, asset[2].parameters())), "the steps did nothing"


def _view_gradient(tiny_models, asset, dtype_type: str) -> torch.Tensor:
    system = AdaptSystem.build(_inputs(asset), _cost_config(tiny_models, dtype_type))
    system.optimizer.zero_grad(set_to_none=True)
    system.train_view(system.sample(0, 0))
    return torch.cat([p.grad.flatten() for p in system.texture.parameters() if p.grad is not None]).double()


def test_bf16_frozen_weights_give_the_fp32_gradient_within_tolerance(tiny_models, asset, one_render_thread):
    """bf16 keeps 8 significant bits (unit roundoff 2^-9 = 0.2%). The texture's gradient passes the VAE
    forward, the UNet passes whose difference is the score, and the VAE backward, each rounding its
    activations; some 40 layers of independent 0.2% roundings add up to a few percent, so we ask for
    the direction within cos >= 0.98 (angle <= 11 degrees) and the norm within 10% (seen here: cos
    0.998, norm +0.3%). A wrong cast (a gradient truncated to bf16 before its sum, a layer in the
    wrong scale) is off by far more. Runs wherever torch has bf16 (emulated on older CPUs: slower, same
    numbers); ModelConfig's "auto" picks it only where the CPU computes it natively."""
    from scenefit.core.guidance.models import cpu_computes_bf16

    if cpu_computes_bf16():
        assert ModelConfig().dtype() == torch.bfloat16
    full = _view_gradient(tiny_models, asset, "fp32")
    half = _view_gradient(tiny_models, asset, "bf16")
    assert torch.isfinite(half).all() and full.norm() > 0
    cosine = float(torch.dot(full, half) / (full.norm() * half.norm()))
    assert cosine >= 0.98, cosine
    assert abs(float(half.norm() / full.norm()) - 1.0) <= 0.10


def test_the_model_image_size_comes_from_the_models_own_config_unless_set(tiny_models, asset, tmp_path):
    """SD2-base's config gives 64 x 8 = 512 and SD 2.1's 96 x 8 = 768: the image size is read, not assumed.
    The tiny model (16 latents, a VAE that halves once) gives 32; a 768-px-shaped config gives 768."""
    from scenefit.core.guidance import load_guidance_models
    from scenefit.devtools.tiny_models import build_tiny_sd

    base, inpaint = tiny_models
    models = load_guidance_models(ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type="fp32"),
                                  need_inpaint=True)
    assert models.image_size == 32
    own = AdaptSystem.build(_inputs(asset), _config(tiny_models, model_resolution=0), models=models)
    assert (own.model_resolution, own.latent_res) == (32, 16)
    asked = AdaptSystem.build(_inputs(asset), _config(tiny_models, model_resolution=48), models=models)
    assert (asked.model_resolution, asked.latent_res) == (48, 24)
    wide = build_tiny_sd(tmp_path / "sd21-shaped", sample_size=96, block_out_channels=(8, 16),
                         vae_block_out_channels=(8, 8, 8, 8))
    wide_models = load_guidance_models(ModelConfig(base_model=str(wide), inpaint_model=str(inpaint),
                                                   dtype_type="fp32"), need_inpaint=False)
    assert wide_models.image_size == 768
    assert AdaptConfig(prompt="x").model_resolution == 0


def test_a_critic_table_in_the_overrides_changes_only_what_it_names():
    """A jobs file's `overrides = { adapt = { critic = { critic_type = "sds" } } }` picks the critic and keeps the
    mode's other critic settings (generate: λ_end 0.9, no reference)."""
    scene = stage_config("adapt", "draft", prompt="x", critic={"critic_type": "sds"})
    assert scene.critic == CriticConfig(critic_type="sds")
    generate = stage_config("adapt", "draft", prompt="x", mode_type="generate", critic={"critic_type": "sds"})
    assert (generate.critic.critic_type, generate.critic.lambda_end, generate.critic.reference_type) == ("sds", 0.9, "none")
