"""The model manager against a hub on 127.0.0.1 (tests/hub_server.py) serving tiny files in the hub's
layout: a download with bytes and speed, a cancel mid-file, a resume that asks only for the rest, the
loader finding the result offline, a removal; a model given as a folder is never removed."""
from __future__ import annotations

import os
import threading

import pytest

from hub_server import HubServer
from scenefit.core.base.errors import Cancelled, InputError, ModelMissingError
from scenefit.core.guidance import model_store as store
from scenefit.core.guidance.models import ModelConfig, locate_models

BIG = 23 * 1024 * 1024   # over two of the hub downloader's 10 MiB chunks: a cancel can land inside it
BASE = "tiny/sd2-base"
INPAINT = "tiny/sd2-inpainting"


def _base_files() -> dict[str, bytes]:
    files = {f"{sub}/config.json": b'{"name": "%s"}' % sub.encode() for sub in ("unet", "vae", "text_encoder")}
    # every file's bytes differ (the hub stores equal files once, as one blob)
    files.update({"tokenizer/vocab.json": b'{"a": 0}', "tokenizer/merges.txt": b"#",
                  "scheduler/scheduler_config.json": b'{"_class_name": "DDPMScheduler"}',
                  "model_index.json": b'{"_class_name": "StableDiffusionPipeline"}', "vae/diffusion_pytorch_model.safetensors": os.urandom(2048),
                  "text_encoder/model.safetensors": os.urandom(1024),
                  "unet/diffusion_pytorch_model.safetensors": os.urandom(BIG),
                  # never fetched: a variant the loader does not read, and a file outside the parts
                  "unet/diffusion_pytorch_model.fp16.safetensors": os.urandom(4096),
                  "v2-base.ckpt": os.urandom(4096)})
    return files


@pytest.fixture
def hub(monkeypatch):
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    server = HubServer({BASE: _base_files()}).start()
    yield server
    server.stop()


def test_download_cancel_resume_find_remove(hub, tmp_path, monkeypatch):
    cache = tmp_path / "hub"
    config = ModelConfig(base_model=BASE, inpaint_model=INPAINT, cache_dir=str(cache))
    spec = store.spec_named(store.model_specs(config), "base")
    assert store.model_state(spec, cache).state == store.MISSING
    fetch = store.model_state(spec, cache).fetch        # what to fetch and where, for an offline machine
    assert f"hf download {BASE} " in fetch and f"models--tiny--sd2-base into '{cache}'" in fetch
    assert all(f"--include '{pattern}'" in fetch for pattern in spec.allow) and "unet/*.safetensors" in spec.allow

    cancel, events = threading.Event(), []

    def stop_inside_big_file(event):
        events.append(event)
        if event.step >= 10 * 1024 * 1024:      # the first chunk of the big file has arrived
            cancel.set()

    with pytest.raises(Cancelled):
        store.download_model(spec, cache, stop_inside_big_file, cancel, endpoint=hub.url)
    partial = list((store.storage_folder(cache, BASE) / "blobs").glob("*" + store.PARTIAL_SUFFIX))
    assert len(partial) == 1 and 0 < partial[0].stat().st_size < BIG
    kept = partial[0].stat().st_size
    assert store.model_state(spec, cache).state == store.PARTIAL
    total = events[-1].total
    wanted = {n: d for n, d in hub.repos[BASE].items() if "fp16" not in n and not n.endswith(".ckpt")}
    assert total == sum(map(len, wanted.values()))
    assert all(e.metrics["bytes_per_s"] > 0 for e in events if e.step) and "MB" in events[-1].message

    blobs = store.storage_folder(cache, BASE) / "blobs"
    already = kept + sum(p.stat().st_size for p in blobs.iterdir() if not p.name.endswith(store.PARTIAL_SUFFIX))
    hub.requests.clear()
    sent_before = hub.bytes_sent
    resumed = []
    state = store.download_model(spec, cache, resumed.append, threading.Event(), endpoint=hub.url)
    ranges = [r["range"] for r in hub.requests if r["method"] == "GET" and r["range"]]
    assert ranges == [f"bytes={kept}-"]                          # only the rest of the big file was asked for
    assert hub.bytes_sent - sent_before == total - already        # and nothing fetched twice
    assert resumed[-1].step == resumed[-1].total == total
    assert state.state == store.FOUND and state.bytes_on_disk == total
    snapshot = state.where
    for name, data in wanted.items():
        assert (cache / store.storage_folder(cache, BASE).name / "snapshots").is_dir()
        assert open(os.path.join(snapshot, name), "rb").read() == data
    assert not os.path.exists(os.path.join(snapshot, "unet/diffusion_pytorch_model.fp16.safetensors"))

    # the loader's own lookup finds it with downloads off, in the same folder
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    assert str(locate_models(config, need_inpaint=False)["base"]) == snapshot
    with pytest.raises(ModelMissingError, match=INPAINT):
        store.download_missing(config, ("base", "inpaint"))
    monkeypatch.delenv("HF_HUB_OFFLINE")

    freed = store.remove_model(spec, cache)
    assert freed >= total and not store.storage_folder(cache, BASE).exists()
    assert store.model_state(spec, cache).state == store.MISSING


def test_a_folder_model_is_reported_and_never_removed(tmp_path):
    folder = tmp_path / "my_inpainting"
    (folder / "unet").mkdir(parents=True)
    (folder / "unet" / "config.json").write_text("{}")
    config = ModelConfig(inpaint_model=str(folder), cache_dir=str(tmp_path / "hub"))
    spec = store.spec_named(store.model_specs(config), "inpaint")
    assert store.model_state(spec, tmp_path / "hub").state == store.FOLDER_INCOMPLETE   # no weights yet
    (folder / "unet" / "diffusion_pytorch_model.safetensors").write_bytes(b"x" * 10)
    state = store.model_state(spec, tmp_path / "hub")
    assert state.state == store.FOLDER and state.where == str(folder) and state.bytes_on_disk == 12
    with pytest.raises(InputError, match="does not delete"):
        store.remove_model(spec, tmp_path / "hub")
    assert (folder / "unet" / "diffusion_pytorch_model.safetensors").is_file()


def test_half_precision_copies_alone_are_not_a_found_model(tmp_path):
    """SD2's repository also holds fp16 copies, which the loader never reads (it asks for no variant): a cache or
    folder holding only those was reported found, and the loader then asked for the full-precision files."""
    cache = tmp_path / "hub"
    snapshot = cache / "models--tiny--sd2-inpainting" / "snapshots" / "abc"
    folder = tmp_path / "my_inpainting"
    for where in (snapshot, folder):
        (where / "unet").mkdir(parents=True)
        (where / "unet" / "config.json").write_text("{}")
        (where / "unet" / "diffusion_pytorch_model.fp16.safetensors").write_bytes(b"h" * 10)
    (snapshot.parent.parent / "refs").mkdir()
    (snapshot.parent.parent / "refs" / "main").write_text("abc")
    hub = store.spec_named(store.model_specs(ModelConfig(inpaint_model=INPAINT, cache_dir=str(cache))), "inpaint")
    own = store.spec_named(store.model_specs(ModelConfig(inpaint_model=str(folder))), "inpaint")
    assert store.model_state(hub, cache).state != store.FOUND
    assert store.model_state(own, cache).state == store.FOLDER_INCOMPLETE
    with pytest.raises(ModelMissingError, match="lacks unet/"):
        locate_models(ModelConfig(base_model=str(folder), cache_dir=str(cache)), need_inpaint=False)
    for where in (snapshot, folder):   # the loader's own file: found
        (where / "unet" / "diffusion_pytorch_model.safetensors").write_bytes(b"f" * 10)
    assert store.model_state(hub, cache).state == store.FOUND
    assert store.model_state(own, cache).state == store.FOLDER


def test_a_run_fetches_what_it_lacks(tmp_path, monkeypatch):
    """The download step a run's job calls: only the missing models, with progress; cancelled before it starts."""
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    depth = {"config.json": b'{"model_type": "dpt"}', "preprocessor_config.json": b'{"p": 1}',
             "model.safetensors": b"d" * 5000, "README.md": b"# not fetched"}
    server = HubServer({"tiny/depth": depth}).start()
    config = ModelConfig(base_model=str(tmp_path / "no_such_folder"), cache_dir=str(tmp_path / "hub"))
    try:
        stopped = threading.Event()
        stopped.set()
        with pytest.raises(Cancelled):
            store.download_missing(config, ("depth",), None, stopped, depth_model="tiny/depth", endpoint=server.url)
        events = []
        states = store.download_missing(config, ("depth",), events.append, threading.Event(), depth_model="tiny/depth",
                                        endpoint=server.url)
        assert [s.state for s in states] == [store.FOUND] and events[-1].step == events[-1].total == sum(
            len(data) for name, data in depth.items() if name != "README.md")
        assert store.download_missing(config, ("depth",), None, None, depth_model="tiny/depth", endpoint=server.url) == []
        with pytest.raises(ModelMissingError, match=r"could not be downloaded \(RepositoryNotFoundError.*hf download"):
            store.download_missing(config, ("depth",), depth_model="tiny/no-such-model", endpoint=server.url)
    finally:
        server.stop()
    assert not any(r["path"].endswith("README.md") for r in server.requests)


def test_the_cache_is_the_hubs_own(tmp_path, monkeypatch):
    """No folder asked for: HF_HUB_CACHE, else HF_HOME/hub (where other tools put their weights)."""
    from scenefit.core.guidance.models import hub_cache

    monkeypatch.delenv("HF_HUB_CACHE", raising=False)
    monkeypatch.setenv("HF_HOME", str(tmp_path / "home"))
    assert hub_cache() == tmp_path / "home" / "hub"
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "elsewhere"))
    assert hub_cache() == tmp_path / "elsewhere"
    assert hub_cache(str(tmp_path / "asked")) == tmp_path / "asked"
    states = store.model_states(ModelConfig())
    assert [s.cache for s in states] == [str(tmp_path / "elsewhere")] * 3


# -- a hub's answers are data -------------------------------------------------------------------------
DEPTH = {"config.json": b'{"model_type": "dpt"}', "preprocessor_config.json": b'{"p": 1}',
         "model.safetensors": os.urandom(5000)}


def _depth_spec():
    return store.depth_spec("tiny/depth")


def _outside(tmp_path, cache) -> list[str]:
    """Files under tmp_path that are not in the cache: what a download wrote where it must not."""
    return sorted(str(p) for p in tmp_path.rglob("*") if p.is_file() and cache not in p.parents)


def test_an_etag_that_is_a_path_writes_nothing_outside_the_cache(tmp_path, monkeypatch):
    """A hub (or anyone between it and the user) answering an ETag of `../../../home/.bash_profile`: the
    downloader used to write the served bytes there; it refuses in one sentence and writes nothing outside."""
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    server = HubServer({"tiny/depth": dict(DEPTH)}, etags={"model.safetensors": "../../../home/.bash_profile"}).start()
    cache = tmp_path / "hub"
    try:
        with pytest.raises(ModelMissingError, match="not a file hash") as refused:
            store.download_model(_depth_spec(), cache, endpoint=server.url)
    finally:
        server.stop()
    assert "\n" not in str(refused.value)
    assert not (tmp_path / "home").exists() and _outside(tmp_path, cache) == []


def test_a_partial_with_a_zero_tail_is_fetched_again(tmp_path, monkeypatch):
    """A `.incomplete` as long as its file but with a zero-filled tail was taken as finished ("found", weights
    that do not match the ETag): its hash is checked, and the file fetched again whole."""
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    server = HubServer({"tiny/depth": dict(DEPTH)}).start()
    cache = tmp_path / "hub"
    weights = DEPTH["model.safetensors"]
    blobs = store.storage_folder(cache, "tiny/depth") / "blobs"
    blobs.mkdir(parents=True)
    (blobs / (HubServer.etag(weights) + store.PARTIAL_SUFFIX)).write_bytes(weights[:1000] + bytes(len(weights) - 1000))
    try:
        state = store.download_model(_depth_spec(), cache, endpoint=server.url)
    finally:
        server.stop()
    assert state.state == store.FOUND
    assert open(os.path.join(state.where, "model.safetensors"), "rb").read() == weights


def test_a_hub_serving_other_bytes_than_its_etag_says_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    server = HubServer({"tiny/depth": dict(DEPTH)}, etags={"model.safetensors": "a" * 64}).start()
    cache = tmp_path / "hub"
    try:
        with pytest.raises(ModelMissingError, match="do not match its hash"):
            store.download_model(_depth_spec(), cache, endpoint=server.url)
    finally:
        server.stop()
    blobs = store.storage_folder(cache, "tiny/depth") / "blobs"
    assert not (blobs / ("a" * 64)).exists() and not list(blobs.glob("*" + store.PARTIAL_SUFFIX))
    assert store.model_state(_depth_spec(), cache).state != store.FOUND
