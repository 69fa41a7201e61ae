"""Fuzz tests of the readers the `joins` helper restructures, through their public entry points only:
a jobs file (workers.jobs.load_jobs), an fSpy project (core.stages.camera.read_fspy), a photo's EXIF
(core.data.photo.load_photo). Random and mutated inputs give a result or one InputError
sentence, never another exception. Seeded and bounded: the same examples each run, seconds per reader."""
from __future__ import annotations

import json
import math
import struct

import numpy as np
from hypothesis import HealthCheck, Phase, given, settings, strategies as st

from scenefit.core.base.errors import InputError

FUZZ = settings(derandomize=True, max_examples=80, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
# (no shrinking while a test is marked as failing: the first failing example is proof enough)
FAILING = settings(FUZZ, phases=[Phase.explicit, Phase.reuse, Phase.generate])
ODD = st.one_of(st.integers(-2**70, 2**70), st.floats(), st.text(max_size=12), st.booleans(), st.none(),
                st.lists(st.floats(), max_size=5), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2))


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, (int, str)):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    return '""'


JOB_KEYS = ["name", "asset", "photo", "stages", "preset", "at", "seed", "object_size", "turn", "sun", "scene",
            "overrides", "camera", "sun_uncertainty", "num_cpus", "retries", "workers"]


def one_sentence(error: InputError) -> None:
    assert "\n" not in str(error) and "Traceback" not in str(error), str(error)


@FUZZ
@given(st.data())
def test_fuzz_jobs_files_give_jobs_or_one_sentence(tmp_path, data):
    from scenefit.workers.jobs import load_jobs

    (tmp_path / "ball").mkdir(exist_ok=True)
    lines = ['[[job]]', 'name = "a"', 'asset = "ball"', 'stages = ["convert"]']
    for _ in range(data.draw(st.integers(0, 4))):
        table = data.draw(st.sampled_from(["[[job]]", "[batch]", "[defaults]", "[models]", ""]))
        key, value = data.draw(st.sampled_from(JOB_KEYS)), data.draw(ODD)
        lines += [table, f"{key} = {toml_value(value)}"] if table else [f"{key} = {toml_value(value)}"]
    text = "\n".join(lines) + "\n"
    if data.draw(st.booleans()):
        at = data.draw(st.integers(0, len(text)))
        text = text[:at] + data.draw(st.sampled_from(["[" * 3000, "{", "\x00", "= =", '"'])) + text[at:]
    path = tmp_path / "jobs.toml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        load_jobs(path)
    except InputError as error:
        one_sentence(error)


def fspy_bytes(state) -> bytes:
    body = json.dumps(state).encode() if not isinstance(state, bytes) else state
    return struct.pack("<4sIII", b"fspy", 1, len(body), 0) + body


GOOD_STATE = {"cameraParameters": {"horizontalFieldOfView": 1.0, "imageWidth": 640, "imageHeight": 480,
                                   "principalPoint": {"x": 0.0, "y": 0.0},
                                   "cameraTransform": {"rows": np.eye(4).tolist()}}}


@FAILING
@given(st.data())
def test_fuzz_fspy_projects_give_a_camera_or_one_sentence(tmp_path, data):
    from scenefit.core.stages.camera import read_fspy

    state = json.loads(json.dumps(GOOD_STATE))
    params = state["cameraParameters"]
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from(["horizontalFieldOfView", "imageWidth", "imageHeight", "principalPoint",
                                         "cameraTransform", "x"]))
        params[key] = data.draw(ODD)
    raw = fspy_bytes(state)
    text = raw.decode("utf-8", "replace").replace("1e+400", "1e400")
    if data.draw(st.booleans()):
        raw = raw.replace(b"640", data.draw(st.sampled_from([b"1e400", b"-1", b"0", b"1e30", b"NaN", b"9" * 5000])))
        raw = struct.pack("<4sIII", b"fspy", 1, len(raw) - 16, 0) + raw[16:]
    path = tmp_path / "camera.fspy"
    path.write_bytes(raw if data.draw(st.booleans()) else text.encode())
    try:
        camera = read_fspy(path)
        assert 0 < camera["fov_deg"] < 180 and all(math.isfinite(v) for v in camera["image_size"])
    except InputError as error:
        one_sentence(error)


@FAILING
@given(st.sampled_from(["Exif:FocalLengthIn35mmFilm", "Exif:FocalLength", "FocalLength", "Model", "Orientation"]),
       st.one_of(st.integers(-2**31, 2**31 - 1), st.floats(width=32), st.text(max_size=10)))
def test_fuzz_exif_fields_give_a_photo_or_one_sentence(tmp_path, name, value):
    import OpenImageIO as oiio

    from scenefit.core.data.photo import load_photo

    path = tmp_path / "photo.jpg"
    spec = oiio.ImageSpec(32, 24, 3, oiio.UINT8)
    spec.attribute(name, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.full((24, 32, 3), 128, np.uint8))
    out.close()
    try:
        pixels, info = load_photo(path)
        assert np.isfinite(pixels).all()
        fov = info.get("fov_from_metadata_deg")
        assert fov is None or 0 < fov < 180, info
    except InputError as error:
        one_sentence(error)
