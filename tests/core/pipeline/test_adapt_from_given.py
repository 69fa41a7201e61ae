"""Adapt alone from a texture and a light map made before (Blender's Adapt after its Convert and Estimate
Light) goes through run_pipeline as the pipeline's own adapt does: a camera stage of the photo, adapt's key
made of what the given files hold, reuse of a finished adaptation, local views without a photo; any other
stage list, or a given file that is missing, is one sentence before any work."""
from __future__ import annotations

import json
import threading
from dataclasses import replace

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.guidance import ModelConfig
from scenefit.core.pipeline.run import GivenOutputs, run_pipeline
from scenefit.core.pipeline.run_config import RunConfig

from conftest import shared_tiny_pair

# Two steps of 16 px views at the tiny models' 32 px: what the Blender operators' quick looks ask for.
QUICK = {"adapt": {"iterations": 2, "model_resolution": 32, "stages": [[1.0, 16, 2, [500, 990]]]}}


@pytest.fixture(scope="module")
def made_before(tmp_path_factory):
    """The sphere, its converted texture and an estimated light map, as Convert and Estimate Light leave them."""
    folder = tmp_path_factory.mktemp("made_before")
    mesh = replace(uv_sphere(0.5, 16, 8), name="ball")
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    photo = write_image(folder / "room.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                             (48, 64, 3)).astype(np.float32))
    converted = run_pipeline(mesh, maps, None, None, folder / "convert",
                             RunConfig(stage_overrides={"convert": {"iterations": 5}}), stages=("convert",))
    lit = run_pipeline(None, None, photo, (0.5, 0.8), folder / "light",
                       RunConfig(preset="draft", stage_overrides={"light": {
                           "critic_type": "none", "outpaint": {"completion_type": "prior"}}}), stages=("light",))
    return mesh, converted.outputs("convert")["weights"], lit.outputs("light")["hdr_exr"], photo


def config(**settings) -> RunConfig:
    base, inpaint = shared_tiny_pair()
    return RunConfig(preset="draft", models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)),
                     stage_overrides=QUICK, **settings)


def test_adapt_of_the_photo_under_the_given_light_runs_once_and_is_reused(tmp_path, made_before):
    mesh, texture, light, photo = made_before
    given = GivenOutputs(texture=texture, light=light)
    first = run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "adapt", config(prompt="a ball in a room"),
                         cancel=threading.Event(), stages=("adapt",), given=given)
    assert list(first.stages) == ["adapt"] and first.stages["adapt"].status == "ran"
    assert first.camera is not None and first.camera.status == "ran"   # the photo's camera, its own stage
    adapted = first.stages["adapt"].report
    assert adapted["iterations"] == 2 and adapted["config"]["light_type"] == "envmap"   # lit by the given map
    assert adapted["config"]["views_type"] == "local+global"                           # the photo's global views
    report = json.loads((tmp_path / "adapt" / "report.json").read_text())
    assert list(report["stages"]) == ["adapt"] and report["inputs"]["asset"] == "ball"
    again = run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "adapt", config(prompt="a ball in a room"),
                         stages=("adapt",), given=given)
    assert again.stages["adapt"].status == "reused"
    # The same bytes under another name are the same adaptation; another texture is another one.
    copy = tmp_path / "copy.pt"
    copy.write_bytes(open(texture, "rb").read())
    assert run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "adapt", config(prompt="a ball in a room"),
                        stages=("adapt",), given=GivenOutputs(texture=copy, light=light)).stages["adapt"].status \
        == "reused"
    adapted_again = run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "adapt", config(prompt="a ball in a room"),
                                 stages=("adapt",), given=GivenOutputs(texture=first.outputs("adapt")["weights"],
                                                                       light=light))
    assert adapted_again.stages["adapt"].status == "ran"


def test_an_edit_without_a_photo_adapts_local_views_under_the_presets_light_or_the_given_one(tmp_path, made_before):
    mesh, texture, light, photo = made_before
    result = run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "edit",
                          config(mode="edit", object_prompt="a ball", instruction="make it rusty"),
                          stages=("adapt",), given=GivenOutputs(texture=texture))
    adapted = result.stages["adapt"].report["config"]
    assert result.camera is None and not (tmp_path / "edit" / "camera").exists()   # an edit reads no photo
    assert adapted["views_type"] == "local" and adapted["light_type"] == "ambient"
    assert adapted["instruction"] == "make it rusty" and adapted["mode_type"] == "edit"
    lit = run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "edit_lit",
                       config(mode="edit", object_prompt="a ball", instruction="make it rusty"),
                       stages=("adapt",), given=GivenOutputs(texture=texture, light=light))
    assert lit.stages["adapt"].report["config"]["light_type"] == "envmap" and lit.camera is None


def test_a_run_from_given_outputs_is_adapt_alone_and_its_files_must_exist(tmp_path, made_before):
    mesh, texture, _, photo = made_before
    for stages in [("convert", "adapt"), ("adapt", "compose"), ("light",)]:
        with pytest.raises(InputError, match="runs adapt alone") as error:
            run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "run", config(), stages=stages,
                         given=GivenOutputs(texture=texture))
        assert "\n" not in str(error.value)
    with pytest.raises(InputError, match="Cannot read .*missing.pt.*run the stage that makes it again"):
        run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "run", config(), stages=("adapt",),
                     given=GivenOutputs(texture=tmp_path / "missing.pt"))
    with pytest.raises(InputError, match="Cannot read .*missing.exr"):
        run_pipeline(mesh, None, photo, (0.5, 0.8), tmp_path / "run", config(), stages=("adapt",),
                     given=GivenOutputs(texture=texture, light=tmp_path / "missing.exr"))
    assert not (tmp_path / "run").exists()
