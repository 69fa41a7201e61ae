"""A jobs file's job is RunConfig's table: every field has one key, every key reaches the run, and what the run
cannot take (unknown keys and overrides, wrong types, numbers out of range, stage subsets that do not run, files
nested or sized past reason) is one sentence naming the file, the job and the key when the file is read."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from scenefit.core.base.errors import InputError
from scenefit.core.data.asset_io import save_asset_folder
from scenefit.core.data.imageio import write_image
from scenefit.core.data.maps import PBRMaps
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.pipeline.run import RunConfig
from scenefit.core.pipeline.run_table import NOT_IN_A_TABLE, RUN_KEYS, run_config, run_table
from scenefit.workers.jobs import Job, load_jobs

# A value for each key that is not RunConfig's default (a test below checks that each differs).
GIVEN = {"preset": "final", "mode": "edit", "prompt": "a sofa", "negative_prompt": "blurry",
         "object_prompt": "a leather sofa", "instruction": "add mud", "seed": 7, "guidance_type": "sd2",
         "object_size": 0.5, "shadow_type": "none", "compose_spp": 8, "fspy": "/x/room.fspy",
         "camera": {"fov": 50.0, "pitch": -14.0, "roll": 2.0}, "camera_source": "blender", "camera_why": "the camera",
         "turn": 30.0, "sun": [-30.0, 45.0], "sun_shadow": None, "sun_uncertainty": 10.0, "scene": "indoor",
         "depth_model": "my/depth", "overrides": {"adapt": {"iterations": 3}}}


def test_every_run_field_has_one_key_and_every_key_reaches_the_run():
    fields = {f.name for f in dataclasses.fields(RunConfig)}
    given_fields = [k.field for k in RUN_KEYS]
    assert len(given_fields) == len(set(given_fields))                        # one key per field
    assert set(given_fields) | set(NOT_IN_A_TABLE) == fields                  # every field can be given
    assert not set(given_fields) & set(NOT_IN_A_TABLE)
    assert set(GIVEN) == {k.key for k in RUN_KEYS}
    default = run_table(RunConfig())
    for key, value in GIVEN.items():
        if value is None:   # sun_shadow: not beside sun (one or the other), given below
            continue
        needs = {"prompt": "a sofa"} if key == "mode" else {}   # (an edit needs its words)
        config = run_config({key: value, **needs}, "jobs.toml job 'a'")
        assert run_table(config)[key] == value != default[key], key       # it reached the run, as given
    shadow = run_config({"sun_shadow": ["0.4,0.8", "0.4,0.5", "0.6,0.85"]}, "w")
    assert shadow.sun_shadow == ("0.4,0.8", "0.4,0.5", "0.6,0.85")
    everything = run_config({k: v for k, v in GIVEN.items() if v is not None}, "w")
    assert run_config(run_table(everything), "w") == everything               # the table reads back the same


def make_inputs(folder: Path) -> None:
    maps = PBRMaps(base_color=np.full((16, 16, 3), 0.5, np.float32), roughness=0.5, metallic=0.0)
    save_asset_folder(uv_sphere(segments=16, rings=8), maps, folder / "ball")
    write_image(folder / "room.png", np.full((48, 64, 3), 0.5, np.float32))


def jobs_file(folder: Path, job: str, head: str = "") -> Path:
    path = folder / "jobs.toml"
    path.write_text(head + '[[job]]\nname = "a"\nasset = "ball"\nphoto = "room.png"\nat = [0.5, 0.7]\n' + job)
    return path


def test_a_jobs_file_job_is_the_run_and_travels_whole(tmp_path):
    make_inputs(tmp_path)
    job = load_jobs(jobs_file(tmp_path, 'mode = "edit"\nobject_prompt = "a ball"\ninstruction = "add moss"\n'
                                        'negative_prompt = "flat"\nseed = 3\nturn = 15\n')).jobs[0]
    assert (job.run.mode, job.run.object_prompt, job.run.instruction, job.run.negative_prompt, job.run.seed,
            job.run.turn_deg) == ("edit", "a ball", "add moss", "flat", 3, 15.0)
    assert job.run.guidance_type == "auto"   # adapt listed (every stage, by default)
    assert Job.from_dict(json.loads(json.dumps(job.to_dict()))) == job   # as it crosses to a worker


@pytest.mark.parametrize("line, says", [
    ("bogus = 1", "unknown key 'bogus'"),
    ("overrides = { convert = { bogus = 1 } }", "overrides.convert: ConvertConfig has no setting 'bogus'"),
    ("overrides = { convert = { iterations = \"many\" } }", "overrides.convert.iterations must be a whole number"),
    ("overrides = { light = { optimise = { iterations = 1.5 } } }", "overrides.light.optimise.iterations"),
    ("overrides = { compose = { noise_target = nan } }", "overrides.compose.noise_target must be a finite number"),
    ("overrides = { paint = { x = 1 } }", "unknown stage 'paint'"),
    ("mode = \"edit\"", "mode 'edit' needs a prompt"),
    ("mode = \"sculpt\"", "mode: mode must be one of scene, generate, edit"),
    ("camera = { pitch = 90 }", "camera: The camera's pitch must be within"),
    ("camera = { fov = inf }", "camera: The camera's angles and shift must be finite"),
    ("camera = { roll = nan }", "camera: The camera's angles and shift must be finite"),
    ("sun = [nan, 45]", "sun: The sun must be"),
    ("sun = [0, 90.5]", "sun: The sun must be"),
    ("turn = inf", "turn must be a finite number"),
    ("object_size = 0", "object_size: The object size"),
    ("sun_uncertainty = inf", "sun_uncertainty must be a finite number"),
    ("seed = -1", "seed: seed must be a whole number >= 0"),
    ("compose_spp = 0", "compose_spp"),
    ("guidance_type = \"sd2\"\nstages = [\"convert\", \"light\"]", "guidance_type 'sd2' is for stage adapt"),
    ("stages = [\"convert\", \"adapt\"]", "stages convert, adapt do not run together"),
    ("stages = [\"light\", \"compose\"]", "stages light, compose do not run together"),
    ("fspy = \"missing.fspy\"", "the fSpy project"),
    ("sun_shadow = [\"0.5,0.5\", \"0.5,0.4\"]", "sun_shadow must be the shadow's foot, top and tip"),
    ("sun_shadow = [\"500,40\", \"30,20\", \"40,45\"]", "sun_shadow: The shadow's foot (500, 40) lies outside the 64x48"),
    ("sun_shadow = [\"0.5,0.8\", \"nan,0.5\", \"0.6,0.85\"]", "sun_shadow: The shadow's top takes two finite"),
    # sizes against memory, ranges and choices of keys the stages used to take and fail on later
    ("overrides = { convert = { render_size = 200000 } }", "render_size 200000 is larger than"),
    ("overrides = { convert = { batch_texels = -5 } }", "batch_texels must be at least 1"),
    ("overrides = { convert = { max_resolution = 0 } }", "max_resolution must be between 8 and 8192"),
    ("stages = [\"light\"]\nshadow_type = \"soft\"", "shadow_type must be one of ratio, paper, none"),
    ("overrides = { adapt = { stages = [[1.0, 16.5, 2, [500, 990]]] } }", "a whole render_size"),
    ("overrides = { adapt = { stages = [[1.0, 1e9, 2, [500, 990]]] } }", "a whole render_size"),
    ("overrides = { adapt = { stages = [[1.0, 1000000000, 2, [500, 990]]] } }", "is larger than"),
    ("overrides = { adapt = { model_resolution = 1048576 } }", "model_resolution must be 0 (the model's own) or a multiple of 8 from 8"),
    ("overrides = { compose = { max_side = 10 } }", "compose: max_side"),
])
def test_what_the_run_cannot_take_is_one_sentence_naming_file_job_and_key(tmp_path, line, says):
    make_inputs(tmp_path)
    with pytest.raises(InputError) as error:
        load_jobs(jobs_file(tmp_path, line + "\n"))
    text = str(error.value)
    assert text.startswith("jobs.toml job 'a': ") and says in text and "\n" not in text.strip(), text


def test_a_depth_model_folder_is_taken_from_the_jobs_files_folder(tmp_path, monkeypatch):
    """`depth_model = "./depth"` resolved against the working folder: run from elsewhere, the job silently used
    the geometric room."""
    make_inputs(tmp_path)
    (tmp_path / "depth").mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    for given in ("./depth", "depth"):
        job = load_jobs(jobs_file(tmp_path, f'depth_model = "{given}"\n')).jobs[0]
        assert job.run.depth_model == str(tmp_path / "depth"), given
    hub = load_jobs(jobs_file(tmp_path, 'depth_model = "depth-anything/Depth-Anything-V2-Small-hf"\n')).jobs[0]
    assert hub.run.depth_model == "depth-anything/Depth-Anything-V2-Small-hf"


@pytest.mark.parametrize("head, says", [
    ("[batch]\nnum_cpus = inf\n", "num_cpus must be a number > 0"),
    ("[batch]\nnum_cpus = nan\n", "num_cpus must be a number > 0"),
    ("[batch]\nnum_gpus = inf\n", "num_gpus must be"),
    ("[batch]\nmemory_gb = \"8\"\n", "memory_gb must be"),
    ("[batch]\nworkers = 1e9\n", "workers must be"),
])
def test_batch_settings_are_finite_and_of_their_type(tmp_path, head, says):
    make_inputs(tmp_path)
    with pytest.raises(InputError, match=says):
        load_jobs(jobs_file(tmp_path, "", head))


def test_a_jobs_file_nested_or_sized_past_reason_is_one_sentence(tmp_path):
    make_inputs(tmp_path)
    for depth in (5000, 40):   # tomllib's recursion, and a depth it reads but no job has
        path = jobs_file(tmp_path, "overrides = { adapt = { stages = " + "[" * depth + "]" * depth + " } }\n")
        with pytest.raises(InputError, match="nests its arrays or tables") as error:
            load_jobs(path)
        assert "\n" not in str(error.value)
    path = tmp_path / "big.toml"
    with path.open("w") as f:
        f.write("# " + "x" * (17 * 1024 * 1024) + "\n")
    with pytest.raises(InputError, match="is over 16 MiB"):
        load_jobs(path)


def test_the_run_config_refuses_non_finite_numbers_from_any_entry_point():
    for values in ({"size": math.nan}, {"turn_deg": math.inf}, {"sun_deg": (0.0, math.nan)},
                   {"sun_deg": (0.0, -91.0)}, {"camera_overrides": {"pitch_deg": -90.0}},
                   {"camera_overrides": {"fov_deg": 171.0}}, {"sun_uncertainty_deg": -1.0}):
        with pytest.raises(InputError):
            RunConfig(**values)
    assert RunConfig(sun_deg=(10.0, 90.0), camera_overrides={"pitch_deg": -89.0, "fov_deg": 170.0}).sun_deg[1] == 90.0



@pytest.mark.parametrize("asset, says", [
    ("cut.glb", "cannot be read as glTF"), ("deep.gltf", "nests deeper"), ("damaged", "cannot be read as a mesh archive"),
])
def test_an_unreadable_asset_is_refused_when_the_jobs_file_is_read(tmp_path, asset, says):
    """An asset that cannot be read failed its convert job when it ran (and was retried); refused at read."""
    make_inputs(tmp_path)
    (tmp_path / "cut.glb").write_bytes(b"glTF\x02\x00\x00\x00\x20\x00\x00\x00")
    (tmp_path / "deep.gltf").write_text('{"asset": ' + "[" * 100 + "]" * 100 + "}")
    save_asset_folder(uv_sphere(segments=8, rings=4), PBRMaps(np.full((8, 8, 3), 0.5, np.float32), 0.5, 0.0),
                      tmp_path / "damaged")
    (tmp_path / "damaged" / "mesh.npz").write_bytes(b"not an archive")
    path = tmp_path / "jobs.toml"
    path.write_text(f'[[job]]\nname = "a"\nasset = "{asset}"\nstages = ["convert"]\n')
    with pytest.raises(InputError) as error:
        load_jobs(path)
    assert says in str(error.value) and str(error.value).startswith("jobs.toml job 'a': "), str(error.value)
