"""`scenefit models`: a download from a hub on 127.0.0.1 (HF_ENDPOINT, as a user points it at a mirror),
then with HF_HUB_OFFLINE=1 the three models and their state as JSON, a refused download that says what to
fetch and where, and a removal."""
from __future__ import annotations

import json

from conftest import scenefit_here, scenefit_process
from hub_server import HubServer

BASE = "tiny/sd2-base"
FILES = {"unet/config.json": b'{"u": 1}', "unet/diffusion_pytorch_model.safetensors": b"u" * 3000,
         "vae/config.json": b'{"v": 1}', "vae/diffusion_pytorch_model.safetensors": b"v" * 2000,
         "text_encoder/config.json": b'{"t": 1}', "text_encoder/model.safetensors": b"t" * 1000,
         "tokenizer/vocab.json": b'{"a": 1}', "tokenizer/merges.txt": b"#m", "scheduler/scheduler_config.json": b'{"s": 1}',
         "model_index.json": b'{"i": 1}', "unet/diffusion_pytorch_model.fp16.safetensors": b"h" * 1500}


def test_download_then_list_offline_and_remove(tmp_path, monkeypatch):
    cache = tmp_path / "hub"
    server = HubServer({BASE: FILES}).start()
    try:
        proc = scenefit_process("models", "download", "base", "--base-model", BASE,
                                env={"HF_ENDPOINT": server.url, "HF_HUB_CACHE": str(cache), "HF_HUB_OFFLINE": "0"})
    finally:
        server.stop()
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "base: found" in proc.stdout
    # The size is said before the download starts: the files a run reads, the half-precision copy left out.
    size = sum(len(d) for n, d in FILES.items() if "fp16" not in n)
    said = proc.stdout.splitlines()
    assert said[0] == f"base: downloading {BASE}, {size / 1000:.1f} KB, into {cache}" and "found" in said[-1]

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_CACHE", str(cache))
    listed = scenefit_here("models", "--json", "--base-model", BASE)
    assert listed.returncode == 0, listed.stderr
    report = json.loads(listed.stdout)
    assert report["cache"] == str(cache) and report["offline"] is True
    states = {m["key"]: m for m in report["models"]}
    assert list(states) == ["base", "inpaint", "depth"]
    base = states["base"]
    assert base["state"] == "found" and base["bytes_on_disk"] == sum(len(d) for n, d in FILES.items() if "fp16" not in n)
    assert base["where"].startswith(str(cache / "models--tiny--sd2-base" / "snapshots"))
    for key in ("inpaint", "depth"):
        assert states[key]["state"] == "missing" and states[key]["where"] is None
        assert states[key]["model"] in states[key]["fetch"] and str(cache) in states[key]["fetch"]
    assert report["device"] in ("cpu", "cuda", "mps")

    refused = scenefit_here("models", "download", "inpaint")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert "stabilityai/stable-diffusion-2-inpainting" in refused.stderr and str(cache) in refused.stderr

    removed = scenefit_here("models", "remove", "base", "--base-model", BASE)
    assert removed.returncode == 0 and "removed" in removed.stdout
    assert not (cache / "models--tiny--sd2-base").exists()
    assert json.loads(scenefit_here("models", "--json", "--base-model", BASE).stdout)["models"][0]["state"] == "missing"


def test_a_hub_that_cannot_be_reached_is_one_sentence(tmp_path):
    """A download with no hub to reach (a closed port) ends in one sentence that says what to fetch and where."""
    import socket

    with socket.socket() as probe:          # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        closed = f"http://127.0.0.1:{probe.getsockname()[1]}"
    proc = scenefit_process("models", "download", "depth", env={"HF_ENDPOINT": closed, "HF_HUB_OFFLINE": "0",
                                                                 "HF_HUB_CACHE": str(tmp_path / "hub")})
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr[-2000:]
    assert "could not be downloaded" in proc.stderr and "hf download depth-anything/Depth-Anything-V2-Small-hf" in proc.stderr


def test_removing_a_model_whose_folder_is_a_link_names_the_link(tmp_path):
    """The cache's model folder is a link to the user's folder: nothing is deleted, and the sentence names both."""
    cache, mine = tmp_path / "hub", tmp_path / "mine"
    (mine / "keep").mkdir(parents=True)
    cache.mkdir()
    (cache / "models--tiny--sd2-base").symlink_to(mine)
    proc = scenefit_process("models", "remove", "base", "--base-model", BASE, env={"HF_HUB_CACHE": str(cache)})
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert str(cache / "models--tiny--sd2-base") in proc.stderr and str(mine) in proc.stderr
    assert (mine / "keep").is_dir()
