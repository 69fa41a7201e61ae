"""What the model manager downloads is what the loaders read: tiny random-weight SD2 base, inpainting and
depth models (built by the test) served from 127.0.0.1 in the hub's layout, fetched into an empty cache,
then loaded by the real loaders with downloads off."""
from __future__ import annotations

from pathlib import Path

import pytest

from scenefit.devtools.tiny_models import build_tiny_depth

from hub_server import HubServer
from scenefit.core.guidance import model_store as store
from scenefit.core.base.errors import ModelMissingError
from scenefit.core.guidance.models import ModelConfig, load_depth_estimator, load_guidance_models
from scenefit.core.stages.light.depth import DepthConfig, load_depth_model
from scenefit.devtools.tiny_models import build_tiny_pair




def _repo(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_downloaded_models_load_offline(tmp_path, monkeypatch):
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    base, inpaint = build_tiny_pair(tmp_path / "built")
    depth = build_tiny_depth(tmp_path / "built" / "depth")
    server = HubServer({"tiny/base": _repo(base), "tiny/inpaint": _repo(inpaint), "tiny/depth": _repo(depth)}).start()
    cache = tmp_path / "hub"
    config = ModelConfig(base_model="tiny/base", inpaint_model="tiny/inpaint", cache_dir=str(cache), dtype_type="fp32")
    depth_auto = DepthConfig(depth_type="auto", model="tiny/depth", cache_dir=str(cache))
    with pytest.raises(ModelMissingError, match="scenefit models download depth"):
        load_depth_model(depth_auto)
    try:
        fetched = store.download_missing(config, ("base", "inpaint", "depth"), depth_model="tiny/depth",
                                         endpoint=server.url)
    finally:
        server.stop()
    assert [s.state for s in fetched] == [store.FOUND] * 3

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    models = load_guidance_models(config, need_inpaint=True)
    assert models.paths["base"] == Path(fetched[0].where) and models.paths["inpaint"] == Path(fetched[1].where)
    assert models.unet.config.in_channels == 4 and models.inpaint_unet.config.in_channels == 9
    for name, data in _repo(base).items():     # every file the loader read is the served one, byte for byte
        if name.endswith((".json", ".safetensors", ".txt")):
            assert (Path(fetched[0].where) / name).read_bytes() == data, name
    estimator = load_depth_estimator("tiny/depth", str(cache), local_files_only=True)
    assert estimator.kind == "disparity" and estimator.model.config.model_type == "depth_anything"
    assert load_depth_model(depth_auto) is estimator    # found in this process once downloaded, not absent for good
