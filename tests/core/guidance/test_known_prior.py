"""The committed known-answer prior: made by the sources beside it, small, laid out and loaded as SD2 is,
and its answers as devtools/known_prior.py writes them."""
from __future__ import annotations

import numpy as np

from scenefit.core.guidance import ModelConfig, load_guidance_models, locate_models
from scenefit.devtools import train_prior
from scenefit.devtools.known_prior import COLOURS, answer, colour_word, hsv_to_rgb, photo_hue, toward_hue
from scenefit.devtools.tiny_models import tiny_tokenizer

PRIOR = train_prior.DEFAULT_OUT


def test_the_committed_prior_was_made_by_the_current_sources_and_is_small():
    """`make prior` would do nothing: the stamp beside the weights is the hash of the sources that made them
    (a change to the training or its data without retraining fails here)."""
    assert train_prior.up_to_date(PRIOR), "devtools/prior is stale: run `make prior` and commit the weights"
    size = sum(p.stat().st_size for p in PRIOR.rglob("*") if p.is_file())
    assert size <= 25 * 2**20
    for role in ("base", "inpaint"):
        for part in ("unet", "vae", "text_encoder", "tokenizer", "scheduler"):
            assert (PRIOR / role / part).is_dir(), f"{role}/{part}"
        assert (PRIOR / role / "model_index.json").is_file()


def test_the_prior_loads_through_the_code_sd2_takes_at_its_own_image_size():
    config = ModelConfig(base_model=str(PRIOR / "base"), inpaint_model=str(PRIOR / "inpaint"), dtype_type="fp32")
    paths = locate_models(config, need_inpaint=True)
    models = load_guidance_models(config, need_inpaint=True, paths=paths)
    assert models.image_size == 32 and models.vae_scale_factor == 2
    assert models.inpaint_unet is not None and models.inpaint_unet.config.in_channels == 9
    # Encoded images of the prior's own kind have latents of about unit spread (the VAE's scaling factor).
    rng = np.random.default_rng(0)
    from scenefit.devtools.prior_data import local_sample

    import torch

    images = torch.from_numpy(np.stack([local_sample(rng).image for _ in range(16)])).permute(0, 3, 1, 2)
    with torch.no_grad():
        spread = float(models.encode(images).std())
    assert 0.5 < spread < 2.0
    # Every colour word is one token of its own, beside a noun the prior never saw.
    for word in COLOURS:
        assert f"{word}</w>" in models.tokenizer.tokenize(f"a {word} truck")


def test_the_answers():
    assert colour_word("a Red chair, make it blue") == "blue" and colour_word("a reddish chair") is None
    assert answer("a fox, green") == COLOURS["green"] and answer("a fox") is None
    photo = np.broadcast_to(np.array(hsv_to_rgb(220.0, 0.3, 0.6), np.float32), (8, 8, 3))
    assert abs(photo_hue(photo) - 220.0) < 1.0
    scene = answer("a fox", photo)
    assert scene is not None and abs(photo_hue(np.array([[scene]])) - 220.0) < 3.0   # (hexagon angle vs HSV hue)
    # From orange to the photo's blue: within the angle, moved along its hue; orange to red is not.
    # (the hexagon's angle is HSV's hue to a few degrees)
    gap, moved = toward_hue((0.8, 0.45, 0.2), scene, 220.0)
    assert gap < 3.0 and moved > 0.3
    gap, moved = toward_hue((0.8, 0.45, 0.2), (0.8, 0.1, 0.1), 220.0)
    assert gap > 30.0 and moved < 0.0


def test_a_tiny_tokenizer_makes_each_given_word_one_token():
    tokenizer = tiny_tokenizer(("green", "red"))
    assert tokenizer.tokenize("green red tree") == ["green</w>", "red</w>", "t", "re", "e</w>"]
    assert len(tiny_tokenizer()) == 514
