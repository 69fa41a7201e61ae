"""One pipeline: every entry point hands the same inputs to the same pipeline with the same
settings, so no copy can drift. Each test here pins a bug the copies once had."""
from __future__ import annotations

import dataclasses
import json
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

import scenefit.core.pipeline.run as run_module
from scenefit.cli import build_parser, main
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.placement import DEFAULT_AT, DEFAULT_OBJECT_SIZE
from scenefit.core.base.errors import InputError
from scenefit.workers.jobs import Job, load_jobs

from asset_builder import write_obj


def _obj_asset(folder: Path) -> Path:
    """An OBJ + MTL + PNG as a modelling tool writes them."""
    yy, xx = np.mgrid[0:16, 0:16] / 16
    return Path(write_obj(folder, uv_sphere(0.5, 12, 6), np.stack([0.2 + 0.6 * xx, 0.5 + 0 * xx, 0.8 - 0.5 * yy], -1)))


@pytest.fixture
def inputs(tmp_path) -> dict:
    photo = write_image(tmp_path / "room.png", np.broadcast_to(np.linspace(0.9, 0.3, 48)[:, None, None],
                                                               (48, 64, 3)).astype(np.float32))
    folder = save_asset_folder(uv_sphere(0.5, 12, 6), PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0),
                               tmp_path / "ball")
    return {"root": tmp_path, "photo": photo, "folder": folder, "obj": _obj_asset(tmp_path / "obj")}


def _jobs(root: Path, asset: Path, photo: Path, stages: list[str], name: str = "job") -> Path:
    path = root / f"{name}.toml"
    path.write_text(f'[[job]]\nname = "{name}"\nasset = "{asset}"\nphoto = "{photo}"\nat = [0.5, 0.6]\n'
                    f'preset = "draft"\nstages = {json.dumps(stages)}\n')
    return path


class Recorder:
    """run_pipeline as every entry point calls it: what it was given, and a report it can print."""

    def __init__(self) -> None:
        self.calls: list[dict] = []

    def __call__(self, mesh, maps, photo_path, placement, out_dir, config, progress=None, cancel=None, bake=None,
                 bake_skipped_why="", models=None, reuse_from=None, stages=None):
        from scenefit.core.pipeline.result import RunResult

        self.calls.append({"config": config, "placement": tuple(placement), "bake": bake is not None,
                           "mesh_faces": len(mesh.faces)})
        return RunResult(Path(out_dir), {}, {}, {}, None, 0.0)


def test_the_command_line_and_a_batch_job_give_the_pipeline_the_same_settings(inputs, monkeypatch, capsys):
    """Batch jobs once never baked (only the command line passed a bake) and differed in defaults."""
    from scenefit.workers.job_worker import run_pipeline_for_job

    recorder = Recorder()
    monkeypatch.setattr(run_module, "run_pipeline", recorder)
    assert main(["run", str(inputs["obj"]), "--photo", str(inputs["photo"]), "--at", "0.5,0.6", "--out",
                 str(inputs["root"] / "cli"), "--preset", "draft", "--guidance", "none", "--quiet"]) == 0
    job = load_jobs(_jobs(inputs["root"], inputs["obj"], inputs["photo"],
                          ["convert", "light", "compose", "bake"])).jobs[0]
    run_pipeline_for_job(job, inputs["root"] / "batch")
    cli_call, batch_call = recorder.calls
    assert cli_call == batch_call
    assert cli_call["bake"] is True            # both bake the asset's own file


def test_a_jobs_file_says_how_the_photo_is_seen_as_the_command_line_does(inputs, monkeypatch):
    """object_size, camera and sun in a [[job]] reach the pipeline as --object-size, --fov/--pitch/--roll and --sun
    do (jobs could not say them: every batch job had the default size and an estimated camera)."""
    from scenefit.workers.job_worker import run_pipeline_for_job

    recorder = Recorder()
    monkeypatch.setattr(run_module, "run_pipeline", recorder)
    assert main(["run", str(inputs["folder"]), "--photo", str(inputs["photo"]), "--at", "0.5,0.6", "--out",
                 str(inputs["root"] / "cli"), "--preset", "draft", "--guidance", "none", "--quiet", "--object-size",
                 "0.45", "--fov", "50", "--pitch", "-14", "--roll", "2", "--sun", "-30,45", "--scene", "indoor"]) == 0
    path = _jobs(inputs["root"], inputs["folder"], inputs["photo"], ["convert", "light", "compose"])
    path.write_text(path.read_text() + "object_size = 0.45\ncamera = { fov = 50, pitch = -14, roll = 2 }\n"
                                       "sun = [-30, 45]\nscene = \"indoor\"\n")
    run_pipeline_for_job(load_jobs(path).jobs[0], inputs["root"] / "batch")
    cli_call, batch_call = recorder.calls
    assert cli_call == batch_call and cli_call["config"].sun_deg == (-30.0, 45.0)
    assert cli_call["config"].size == 0.45 and cli_call["config"].camera_overrides["pitch_deg"] == -14.0
    assert cli_call["config"].scene_type == "indoor"
    for bad, says in (("object_size = 1.5", "object_size"), ("camera = { fov = 50, yaw = 3 }", "camera"),
                      ("sun = [10, 95]", "sun"), ("turn = \"left\"", "turn"), ("scene = \"cave\"", "scene"),
                      ("sun_uncertainty = -3", "sun_uncertainty")):
        path.write_text(_jobs(inputs["root"], inputs["folder"], inputs["photo"], ["light"]).read_text() + bad + "\n")
        with pytest.raises(InputError, match=f"job 'job': {says}"):
            load_jobs(path)


def test_a_remote_run_all_sees_the_photo_as_a_local_one(inputs, monkeypatch):
    """Run All on a worker: the RunConfig a local Run All builds (workers/blender_jobs.view_config), sent as a job's
    table (as operators/remote.remote_work sends it) and read back on the worker, is the same config: the scene
    camera, the panel's camera values, the asset's size and turn and Pick Sun's sun all arrive."""
    from scenefit.core.data.asset_io import load_asset_folder
    from scenefit.core.guidance import ModelConfig
    from scenefit.core.pipeline.run_table import run_table
    from scenefit.workers.blender_jobs import view_config
    from scenefit.workers import remote
    from scenefit.workers.job_worker import run_pipeline_for_job

    jobs = []
    def run_remote(job, *args, **kwargs):   # the worker's job, its asset kept past the packing's temporary folder
        jobs.append(dataclasses.replace(job, asset=shutil.copytree(job.asset, inputs["root"] / "sent")))
        return inputs["root"], {}

    monkeypatch.setattr(remote, "run_remote", run_remote)
    recorder = Recorder()
    monkeypatch.setattr(run_module, "run_pipeline", recorder)
    view = {"camera": {"fov_deg": 41.0, "pitch_deg": -9.0, "roll_deg": 1.5}, "camera_source": "blender",
            "scene_camera": "Camera", "placement": (0.4, 0.7), "size": 0.55, "turn_deg": 20.0,
            "notes": ["the scene camera 'Camera' is used as it is"], "sun_deg": (-30.0, 45.0),
            "sun_uncertainty_deg": 12.0}
    mesh, maps = load_asset_folder(inputs["folder"])
    sent = view_config(view, preset="draft", prompt="", guidance_type="none", scene_type="outdoor",
                       depth_model="my/depth")
    remote.work_remotely({"mesh": mesh, "maps": maps, "photo": str(inputs["photo"]), "worker": "auto",
                          "out": str(inputs["root"] / "remote"), "stages": ["convert", "light", "compose"],
                          "at": view["placement"], **{k: v for k, v in run_table(sent).items() if v is not None}})
    run_pipeline_for_job(Job.from_dict(jobs[0].to_dict()), inputs["root"] / "worker")
    local = view_config(view, preset="draft", prompt="", guidance_type="none", models=ModelConfig(),
                        scene_type="outdoor", depth_model="my/depth")
    remote_call = recorder.calls[0]
    assert remote_call["config"] == local and remote_call["placement"] == (0.4, 0.7)
    assert local.scene_type == "outdoor" and local.sun_deg == (-30.0, 45.0) and local.camera_source == "blender"
    assert local.sun_uncertainty_deg == 12.0   # Pick Sun's clicks' uncertainty reaches the worker too
    assert local.depth_model == "my/depth"


def test_a_light_only_job_looks_for_the_depth_model_where_a_whole_run_does(inputs):
    """A job of light alone once took the default depth settings, ignoring the file's [models] cache and
    offline switch that the same job with compose (the pipeline) follows; a depth override keeps them."""
    from scenefit.workers.job_worker import run_job_stages

    path = _jobs(inputs["root"], inputs["folder"], inputs["photo"], ["light"])
    cache = inputs["root"] / "hub"
    cache.mkdir()
    path.write_text(f'[models]\ncache_dir = "{cache}"\nlocal_files_only = true\n\n' + path.read_text()
                    + 'depth_model = "my/depth"\nscene = "indoor"\noverrides = { light = { depth = { depth_type = '
                      '"geometric" } } }\n')
    out = inputs["root"] / "out"
    out.mkdir()
    light = run_job_stages(load_jobs(path).jobs[0], out)["run"]["stages"]["light"]["report"]
    depth = light["config"]["depth"]
    assert (depth["cache_dir"], depth["local_files_only"], depth["model"]) == (str(cache), True, "my/depth")
    assert depth["depth_type"] == "geometric" and light["decisions"]["scene_type"]["chosen"] == "indoor"


def test_an_override_table_changes_only_what_it_names():
    from scenefit.core.pipeline.presets import with_overrides
    from scenefit.core.pipeline.run import RunConfig
    from scenefit.core.stages.light.depth import DepthConfig

    given = {"depth": DepthConfig(cache_dir="/hub", local_files_only=True), "scene_type": "auto"}
    merged = with_overrides(given, {"depth": {"model": "x/y"}, "scene_type": "indoor"})
    assert merged["depth"] == DepthConfig(model="x/y", cache_dir="/hub", local_files_only=True)
    assert merged["scene_type"] == "indoor" and given["depth"].model != "x/y"   # the given settings unchanged
    with pytest.raises(InputError, match="three points"):
        RunConfig(sun_shadow=("0.5,0.9", "0.5,0.5"))


def test_a_batch_convert_job_keeps_constant_channels_as_numbers(inputs):
    from scenefit.workers.job_worker import run_job_stages

    job = load_jobs(_jobs(inputs["root"], inputs["folder"], inputs["photo"], ["convert"])).jobs[0]
    out = inputs["root"] / "out"
    out.mkdir()
    convert = run_job_stages(job, out)["run"]["stages"]["convert"]["report"]
    assert convert["decisions"]["channels"]["roughness"]["value"] == 0.5
    assert convert["outputs"]["roughness"] == 0.5 and not (out / "convert" / "maps" / "roughness.png").exists()


def test_the_light_critic_scores_the_asset_itself(inputs, monkeypatch):
    """run_pipeline once gave the light stage no asset: its critic scored the default grey sphere."""
    import scenefit.core.stages.light.stage as lighting

    seen = {}

    class Stop(Exception):
        pass

    def estimate(photo, placement, config, **kwargs):
        seen.update(kwargs, critic_type=config.critic_type)
        raise Stop

    monkeypatch.setattr(run_module, "models_available", lambda *a, **k: (True, "pretended for the test"))
    monkeypatch.setattr(lighting, "estimate_light", estimate)
    mesh = uv_sphere(0.5, 12, 6)
    maps = PBRMaps(np.full((16, 16, 3), 0.5, np.float32), 0.5, 0.0)
    with pytest.raises(Stop):
        run_module.run_pipeline(mesh, maps, inputs["photo"], (0.5, 0.6), inputs["root"] / "run",
                                run_module.RunConfig(preset="draft"), cancel=threading.Event())
    assert seen["critic_type"] == "diffusion"
    assert seen["mesh"] is mesh and isinstance(seen["maps"], torch.Tensor) and seen["maps"].shape[-1] == 5


def test_a_batch_light_job_lights_the_photo_as_scenefit_light_does(inputs, monkeypatch):
    """A batch job's light stage once lit every photo through the default camera (60 deg, -10 deg pitch)
    while `scenefit light` estimated the photo's own (here EXIF's 90 deg). Both now read the photo, the
    placement and the camera through core/stages/light/stage.py and write the same report."""
    import scenefit.core.stages.light.stage as lighting
    from scenefit.workers.job_worker import run_job_stages

    from camera_scenes import jpeg_with_exif as _jpeg_with_exif

    # 18 mm (35 mm equivalent) on a 3:2 landscape photo, 36 mm of film across: 90 deg.
    photo = _jpeg_with_exif(inputs["root"] / "exif.jpg", (120, 80), **{"Exif:FocalLengthIn35mmFilm": 18})
    real, calls = lighting.estimate_light, []

    def recorded(photo_array, pixel, config, **kwargs):
        calls.append({"pixel": tuple(pixel), "camera": kwargs.get("photo_camera"), "scene": config.scene_type,
                      "height": config.map_height, "critic": config.critic_type})
        return real(photo_array, pixel, config, **kwargs)

    monkeypatch.setattr(lighting, "estimate_light", recorded)
    assert main(["light", "--photo", str(photo), "--at", "0.5,0.6", "--out", str(inputs["root"] / "cli"),
                 "--preset", "draft", "--critic", "none", "--depth", "geometric", "--quiet"]) == 0
    job = load_jobs(_jobs(inputs["root"], inputs["folder"], photo, ["light"])).jobs[0]
    out = inputs["root"] / "batch"
    out.mkdir()
    run_job_stages(job, out)
    cli_call, batch_call = calls
    assert cli_call == batch_call
    assert cli_call["camera"].fov_deg == pytest.approx(90.0, abs=0.1)
    reports = [json.loads((folder / "report.json").read_text()) for folder in (inputs["root"] / "cli", out / "light")]
    assert reports[0]["decisions"]["camera"] == reports[1]["decisions"]["camera"]
    assert reports[0]["photo"] == reports[1]["photo"]


def test_a_batch_light_job_chooses_the_critic_as_scenefit_light_does(inputs, monkeypatch):
    """With the SD2 weights on the machine `scenefit light` refines the scales with the diffusion critic;
    a batch light job always took none. Both now decide 'auto' in core/stages/light/stage.critic_choice."""
    import scenefit.core.guidance.models as models
    import scenefit.core.stages.light.stage as lighting
    from scenefit.workers.job_worker import run_job_stages

    class Stop(Exception):
        pass

    critics = []

    def recorded(photo_array, pixel, config, **kwargs):
        critics.append(config.critic_type)
        raise Stop   # the choice is what is compared; the tiny test has no weights to load

    monkeypatch.setattr(models, "models_available", lambda *a, **k: (True, "pretended for the test"))
    monkeypatch.setattr(lighting, "estimate_light", recorded)
    with pytest.raises(Stop):
        main(["light", "--photo", str(inputs["photo"]), "--out", str(inputs["root"] / "cli"), "--preset", "draft",
              "--quiet"])
    job = load_jobs(_jobs(inputs["root"], inputs["folder"], inputs["photo"], ["light"])).jobs[0]
    (inputs["root"] / "batch").mkdir()
    with pytest.raises(Stop):
        run_job_stages(job, inputs["root"] / "batch")
    assert critics == ["diffusion", "diffusion"]


def test_the_command_line_and_the_panel_share_one_set_of_defaults():
    """The panel once placed the asset at (0.5, 0.75) at 0.4 of the photo, the command line at (0.5, 0.6), 0.3."""
    import ast

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for command in ("adapt", "light"):
        assert tuple(sub[command].parse_known_args([])[0].at) == DEFAULT_AT
    for command in ("adapt", "compose"):
        defaults = {a.dest: a.default for a in sub[command]._actions}
        assert defaults["object_size"] == DEFAULT_OBJECT_SIZE
    # (`scenefit run`'s options leave what is not given to the run table, as a jobs file does)
    from scenefit.cli.run import run_config as run_options_config

    given = sub["run"].parse_args(["ball", "--photo", "p.png", "--at", "0.5,0.7", "--out", "o", "--offline"])
    assert run_options_config(given)[0].size == DEFAULT_OBJECT_SIZE
    # The panel's properties name the same constants (read from the source: registering them needs bpy).
    source = (Path(run_module.__file__).parents[2] / "operators" / "properties.py").read_text()
    classes = {node.name: node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ClassDef)}

    def default_of(class_name: str) -> dict:
        return {node.target.id: next((k.value for k in node.annotation.keywords if k.arg == "default"), None)
                for node in classes[class_name].body
                if isinstance(node, ast.AnnAssign) and isinstance(node.annotation, ast.Call)}

    # Each asset's own placement and size, and the scene's for a selection that is no asset yet.
    asset, scene = default_of("SceneFitAsset"), default_of("SceneFitSettings")
    for at, size in ((asset["placement"], asset["size"]), (scene["loose_placement"], scene["loose_size"])):
        assert ast.unparse(at) == "DEFAULT_AT"
        assert ast.unparse(size) == "DEFAULT_OBJECT_SIZE"


def test_every_stage_config_defaults_to_the_balanced_preset_or_says_why_not():
    """A config built with no arguments (a test, a script, a stage called directly) is the balanced
    preset's; texture, light and adapt keep the paper's values as defaults, and their docstrings say so.
    A stage config holds resolved values: convert's and adapt's texture is a NeuralTextureConfig."""
    from dataclasses import replace

    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.stages.adapt.config import AdaptConfig
    from scenefit.core.stages.compose import ComposeConfig
    from scenefit.core.stages.convert import ConvertConfig
    from scenefit.core.stages.light.config import LightConfig
    from scenefit.core.texture.texture_config import BALANCED_TEXTURE, NeuralTextureConfig

    assert ConvertConfig() == stage_config("convert", "balanced")
    assert ComposeConfig() == stage_config("compose", "balanced")
    assert BALANCED_TEXTURE == stage_config("texture", "balanced")
    assert AdaptConfig(prompt="moss").texture == BALANCED_TEXTURE
    assert stage_config("convert", "draft").texture == stage_config("texture", "draft") != BALANCED_TEXTURE
    for config in (NeuralTextureConfig(), LightConfig(), AdaptConfig(prompt="moss")):
        assert "paper" in type(config).__doc__
    assert NeuralTextureConfig() == stage_config("texture", "final")
    assert AdaptConfig(prompt="moss") == replace(stage_config("adapt", "final", prompt="moss"), texture=BALANCED_TEXTURE)
    assert LightConfig().optimise == stage_config("light", "final").optimise


def test_elevation_is_the_orbit_angle_and_pitch_the_photo_cameras():
    """`--elevation` once meant the orbit angle in render/export and the photo's down-tilt in
    light/compose; the photo's camera now takes --pitch (negative looks down) and the old spelling
    still reads as its opposite."""
    from scenefit.cli.options import photo_pitch

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    for command in ("render", "export", "adapt"):
        assert "elevation" in {a.dest for a in sub[command]._actions}
    required = ["asset", "--photo", "p.png", "--at", "0.5,0.5", "--light", "l.exr", "--out", "o"]
    assert photo_pitch(sub["compose"].parse_args(required + ["--pitch", "-12"])) == -12.0
    assert photo_pitch(sub["compose"].parse_args(required + ["--elevation", "12"])) == -12.0
    assert photo_pitch(sub["compose"].parse_args(required)) is None
    assert "--elevation" not in sub["compose"].format_help() and "--pitch" in sub["compose"].format_help()


def _panel_view(camera: dict | None = None) -> dict:
    """operators/photo.photo_view's answer for a panel at its defaults (the camera estimated in the job)."""
    return {"camera": camera, "camera_source": "user" if camera else "estimate", "scene_camera": "",
            "placement": DEFAULT_AT, "size": DEFAULT_OBJECT_SIZE, "turn_deg": 0.0, "notes": []}


def test_run_all_in_blender_and_the_command_line_give_the_pipeline_the_same_settings(inputs, monkeypatch):
    """Run All once sent a placeholder camera (60 deg, 1x1 pixels) where the command line estimated it."""
    from scenefit.core.guidance import ModelConfig
    from scenefit.workers.blender_jobs import view_config

    recorder = Recorder()
    monkeypatch.setattr(run_module, "run_pipeline", recorder)
    for camera in ([], ["--fov", "50", "--pitch", "-14", "--roll", "2"], ["--sun", "-30,45"]):
        assert main(["run", str(inputs["obj"]), "--photo", str(inputs["photo"]), "--at", "{},{}".format(*DEFAULT_AT),
                     "--out", str(inputs["root"] / f"cli{len(recorder.calls)}"), "--preset", "draft", "--guidance",
                     "none", "--quiet", *camera]) == 0
    estimated, given, sun = (call["config"] for call in recorder.calls)
    data = {"preset": "draft", "prompt": "", "guidance_type": "none", "models": ModelConfig()}   # (Run All's prepare())
    assert view_config(_panel_view(), **data) == estimated
    assert view_config(_panel_view({"fov_deg": 50.0, "pitch_deg": -14.0, "roll_deg": 2.0}), **data) == given
    # Pick Sun's (azimuth, elevation) reaches the pipeline as --sun's does.
    assert view_config({**_panel_view(), "sun_deg": (-30.0, 45.0)}, **data) == sun and sun.sun_deg
    assert recorder.calls[0]["placement"] == DEFAULT_AT


def test_a_remote_job_from_blender_runs_the_pipeline_as_a_batch_job_does(inputs, monkeypatch):
    """workers/remote.work_remotely packs the add-on's data into a Job; its worker runs the batch's path."""
    from scenefit.core.data.asset_io import load_asset_folder
    from scenefit.workers import remote
    from scenefit.workers.job_worker import run_pipeline_for_job

    jobs = []

    def run_remote(job, *args, **kwargs):   # what the worker receives: the job, its asset packed along
        kept = shutil.copytree(job.asset, inputs["root"] / "sent")
        jobs.append(dataclasses.replace(job, asset=kept))
        return inputs["root"], {}

    monkeypatch.setattr(remote, "run_remote", run_remote)
    mesh, maps = load_asset_folder(inputs["folder"])
    remote.work_remotely({"mesh": mesh, "maps": maps, "photo": str(inputs["photo"]), "at": (0.5, 0.6),
                          "worker": "auto", "out": str(inputs["root"] / "remote"), "preset": "draft",
                          "stages": ["convert", "light", "compose"]})
    recorder = Recorder()
    monkeypatch.setattr(run_module, "run_pipeline", recorder)
    local = load_jobs(_jobs(inputs["root"], inputs["folder"], inputs["photo"], ["convert", "light", "compose"])).jobs[0]
    run_pipeline_for_job(jobs[0], inputs["root"] / "from-blender")
    run_pipeline_for_job(local, inputs["root"] / "from-jobs-file")
    from_blender, from_file = recorder.calls
    assert from_blender == from_file


def test_quiet_keeps_the_asset_folders_file_to_itself(inputs, monkeypatch, capsys):
    """A folder holding one asset file is said once on stderr, and not at all under --quiet (it was)."""
    monkeypatch.setattr(run_module, "run_pipeline", Recorder())
    folder = inputs["obj"].parent
    common = ["run", str(folder), "--photo", str(inputs["photo"]), "--at", "0.5,0.6", "--preset", "draft",
              "--guidance", "none", "--no-bake"]
    assert main(common + ["--out", str(inputs["root"] / "said")]) == 0
    assert f"using {inputs['obj'].name}" in capsys.readouterr().err
    assert main(common + ["--out", str(inputs["root"] / "quiet"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
