"""Fuzz test of the model downloader's reader of a hub's answers (core/guidance/model_store.download_model):
a hub on 127.0.0.1 answering random commits, ETags and file names gives a found model or one
ModelMissingError sentence, and never a file outside the cache. Seeded and bounded."""
from __future__ import annotations

import hashlib

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from hub_server import HubServer
from scenefit.core.base.errors import ModelMissingError
from scenefit.core.guidance import model_store as store

FUZZ = settings(derandomize=True, max_examples=40, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
FILES = {"config.json": b'{"model_type": "dpt"}', "preprocessor_config.json": b'{"p": 1}',
         "model.safetensors": b"w" * 3000}
HOSTILE = st.one_of(st.text(max_size=70), st.sampled_from(
    ["../../../home/.bash_profile", "/etc/passwd", "..", "", "a" * 64, "A" * 40, "0" * 63, "W/" + "b" * 64,
     "..%2f..%2fx", "c" * 40 + "/../x"]))


@pytest.fixture(scope="module")
def hub():
    server = HubServer({"tiny/depth": dict(FILES)}).start()
    yield server
    server.stop()


@FUZZ
@given(etag=st.one_of(st.none(), HOSTILE), commit=st.one_of(st.none(), HOSTILE),
       name=st.one_of(st.none(), st.sampled_from(["../x.safetensors", "a/../../x.safetensors", "/abs.safetensors",
                                                   "./model.safetensors", "x\\..\\y.safetensors", "a//b.safetensors"])))
def test_fuzz_hub_answers_give_a_model_or_one_sentence(hub, tmp_path_factory, monkeypatch, etag, commit, name):
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    root = tmp_path_factory.mktemp("fuzz")
    cache = root / "a" / "b" / "hub"
    files = dict(FILES)
    if name is not None:
        files[name] = b"x" * 10
    hub.repos["tiny/depth"] = files
    hub.etags = {"model.safetensors": etag} if etag is not None else {}
    hub.commits = {"tiny/depth": commit} if commit is not None else {}
    try:
        state = store.download_model(store.depth_spec("tiny/depth"), cache, endpoint=hub.url)
        assert state.state == store.FOUND
        assert etag in (None, hashlib.sha256(FILES["model.safetensors"]).hexdigest())
    except ModelMissingError as error:
        assert "\n" not in str(error)
    outside = [p for p in root.rglob("*") if p.is_file() and cache not in p.parents]
    assert outside == []
