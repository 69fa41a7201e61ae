"""Scene-conditional prompts from a language model, against a real chat-completions server on
127.0.0.1 (tests/chat_server.py): the appendix's instructions, streaming and plain answers,
checks, retry and repair, time-outs, HTTP errors, refusals, the disk cache, offline mode."""
from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from chat_server import ChatServer, Reply
from conftest import shared_tiny_pair

from scenefit.core.base.errors import InputError, PromptServiceError
from scenefit.core.guidance.prompting import (ANALYSIS_STEP, DESCRIBE_STEP, INSTRUCT_STEP, PromptRequest, ServiceConfig,
                                     count_words, problems, repair, resolve_service, shorten, split_answer,
                                     template_prompt, write_prompt)

SOFA = PromptRequest("a leather sofa", "a swamp")
ANALYSIS = "In a swamp the sofa would soak up water, grow mould and collect mud on its lower half."
# The paper's own example (27 words, every word of 'a leather sofa' but the article).
GOOD = ("The leather sofa, partially submerged in the swamp, looks discolored and soggy, its once-polished "
        "surface marred by mud, moss, and the murky water of the swamp environment.")
GOOD_INSTRUCTION = ("Soak the leather sofa, darken the leather with water stains, add mud to the legs, grow moss "
                    "on the seams, fade the color.")
LONG = ("The leather sofa, half sunk in the swamp, is soaked and dark, its seams split, its cushions sagging, "
        "its legs caked in thick grey mud, moss creeping over the arms, algae streaking the back, water pooling "
        "in the creases, and rust spreading over the old metal studs.")


@pytest.fixture
def server():
    chat = ChatServer().start()
    yield chat
    chat.stop()


@pytest.fixture
def cache(tmp_path):
    return tmp_path / "prompt-cache"


def answer(final: str, label: str = "Description") -> str:
    return f"{ANALYSIS}\n\n{label}: {final}"


def service(server, **kw) -> ServiceConfig:
    return ServiceConfig(base_url=server.url, model=kw.pop("model", "test-llm"), timeout_s=kw.pop("timeout_s", 10), **kw)


def user_text(request_body: dict, index: int = 0) -> str:
    content = request_body["messages"][index]["content"]
    return content if isinstance(content, str) else next(p["text"] for p in content if p["type"] == "text")


def test_describe_request_carries_the_appendix_instructions_and_inputs(server, cache):
    server.replies = [Reply(answer(GOOD))]
    result = write_prompt(SOFA, service(server), cache_dir=cache)
    assert result.prompt == GOOD and result.analysis == ANALYSIS
    assert result.model_written and result.requests == 1 and not result.repairs and not result.warnings
    assert len(server.requests) == 1
    request = server.requests[0]
    assert request["path"] == "/v1/chat/completions" and request["body"]["model"] == "test-llm"
    text = user_text(request["body"])
    assert "[the scene]: a swamp\n[the object]: a leather sofa" in text
    # The appendix's wording, verbatim, analysis first.
    assert ANALYSIS_STEP in text and DESCRIBE_STEP in text and text.index(ANALYSIS_STEP) < text.index(DESCRIBE_STEP)
    assert "approximately 25 to 35 words" in text and "Include all words provided in [the object]." in text
    assert INSTRUCT_STEP not in text
    report = result.to_report()
    assert report["analysis"] == ANALYSIS and report["answers"] == [answer(GOOD)] and report["model_written"] is True


def test_instruct_mode_asks_for_verb_first_instructions(server, cache):
    server.replies = [Reply(answer(GOOD_INSTRUCTION, "Instructions"))]
    result = write_prompt(PromptRequest("a leather sofa", "a swamp", mode_type="instruct"), service(server), cache_dir=cache)
    assert result.prompt == GOOD_INSTRUCTION and 20 <= count_words(result.prompt) <= 30
    text = user_text(server.requests[0]["body"])
    assert INSTRUCT_STEP in text and "approximately 20 to 30 words" in text and DESCRIBE_STEP not in text


def test_streamed_answer_gives_the_same_prompt(server, cache):
    server.replies = [Reply(answer(GOOD))]
    pieces = []
    result = write_prompt(SOFA, service(server, stream=True), cache_dir=cache, on_text=pieces.append)
    assert server.requests[0]["body"]["stream"] is True
    assert result.prompt == GOOD and result.analysis == ANALYSIS
    assert len(pieces) > 5 and "".join(pieces) == answer(GOOD)


def test_over_long_answer_is_asked_again_with_the_error_stated(server, cache):
    server.replies = [Reply(answer(LONG)), Reply(f"Description: {GOOD}")]
    result = write_prompt(SOFA, service(server), cache_dir=cache)
    assert result.prompt == GOOD and result.requests == 2 and len(server.requests) == 2
    assert result.analysis == ANALYSIS                      # the analysis of the first answer is kept
    retry = server.requests[1]["body"]["messages"]
    assert [m["role"] for m in retry] == ["user", "assistant", "user"] and retry[1]["content"] == answer(LONG)
    assert f"it has {count_words(LONG)} words but must have 25 to 35" in retry[2]["content"]


def test_over_long_twice_is_cut_at_a_clause_boundary(server, cache):
    server.replies = [Reply(answer(LONG)), Reply(answer(LONG))]
    result = write_prompt(SOFA, service(server), cache_dir=cache)
    assert 25 <= count_words(result.prompt) <= 35 and LONG.startswith(result.prompt.rstrip("."))
    assert any("cut from" in r for r in result.repairs) and not result.warnings


def test_missing_object_word_is_asked_again_then_repaired(server, cache):
    no_leather = GOOD.replace("leather ", "")
    server.replies = [Reply(answer(no_leather)), Reply(answer(no_leather))]
    result = write_prompt(SOFA, service(server), cache_dir=cache)
    assert "'leather'" in server.requests[1]["body"]["messages"][2]["content"]
    assert "'sofa'" not in server.requests[1]["body"]["messages"][2]["content"].split("cannot be used:")[1].split(".")[0]
    assert result.prompt.startswith("a leather sofa, the sofa") and problems(result.prompt, SOFA) == []
    assert any("put 'a leather sofa' in front" in r for r in result.repairs)


def test_multi_line_and_quoted_answers_become_one_line(server, cache):
    broken = GOOD.replace(", looks", ",\nlooks").replace("moss,", "moss,\n")
    server.replies = [Reply(f"{ANALYSIS}\n\nThe mechanistic description would be:\n\n\"{broken}\"")]
    result = write_prompt(SOFA, service(server), cache_dir=cache)
    assert result.prompt == GOOD and "\n" not in result.prompt and result.requests == 1
    assert any("joined" in r for r in result.repairs)


def test_follow_up_turn_continues_the_conversation(server, cache):
    """The appendix's follow-up ("... placed in the painting studio for decades ...") is a third message
    after the model's first answer; its answer is checked the same way and becomes the prompt."""
    decades = ("A leather sofa, surface cracked and color faded, sits under a veil of dust and dried paint "
               "splatters, a silent witness to the studio's years of creative toil.")
    follow = "Let's suppose the leather sofa has been placed in the painting studio for decades."
    request = PromptRequest("a leather sofa", "a chaotic painting studio", follow_up=follow)
    server.replies = [Reply(answer(GOOD)), Reply(f"Decades of dust would settle.\n\nDescription: {decades}")]
    result = write_prompt(request, service(server), cache_dir=cache)
    assert result.prompt == decades and result.requests == 2
    messages = server.requests[1]["body"]["messages"]
    assert [m["role"] for m in messages] == ["user", "assistant", "user"]
    assert messages[1]["content"] == answer(GOOD) and messages[2]["content"].startswith(follow)
    assert "Decades of dust would settle." in result.analysis and ANALYSIS in result.analysis
    # The follow-up is part of the cache key; offline it is not used and the report says so.
    assert write_prompt(request, service(server), cache_dir=cache).cached
    assert write_prompt(request, None, cache_dir=cache).warnings == ("the follow-up needs a language model and was not used",)


def test_missing_openai_package_is_one_sentence(server, cache, monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "openai", None)      # `import openai` now fails
    with pytest.raises(PromptServiceError, match="'openai' Python package is missing"):
        write_prompt(SOFA, service(server), cache_dir=cache)
    assert server.connections == 0
    assert write_prompt(SOFA, service(server), offline=True, cache_dir=cache).prompt == "a leather sofa in a swamp"


def test_time_out_is_one_clear_sentence(server, cache):
    server.replies = [Reply(answer(GOOD), delay_s=5)]
    with pytest.raises(PromptServiceError, match=r"did not answer within 0.5 s") as error:
        write_prompt(SOFA, service(server, timeout_s=0.5), cache_dir=cache)
    assert "\n" not in str(error.value) and len(server.requests) == 1
    assert not cache.exists() or not any(cache.iterdir())   # nothing cached from a failure


def test_http_500_is_reported_without_automatic_retries(server, cache):
    server.replies = [Reply(status=500, text="model crashed"), Reply(answer(GOOD))]
    with pytest.raises(PromptServiceError, match="answered HTTP 500"):
        write_prompt(SOFA, service(server), cache_dir=cache)
    assert len(server.requests) == 1


@pytest.mark.parametrize("reply", [Reply(refusal="I can't help with that."), Reply("I'm sorry, but I cannot help with this request.")])
def test_refusal_is_reported(server, cache, reply):
    server.replies = [reply]
    with pytest.raises(PromptServiceError, match="refused"):
        write_prompt(SOFA, service(server), cache_dir=cache)


def test_cache_avoids_a_second_call(server, cache):
    server.replies = [Reply(answer(GOOD)), Reply(answer(GOOD.replace("swamp", "marsh")))]
    first = write_prompt(SOFA, service(server), cache_dir=cache)
    again = write_prompt(SOFA, service(server), cache_dir=cache)
    assert len(server.requests) == 1 and server.connections == 1
    assert again.cached and again.requests == 0 and again.prompt == first.prompt and again.analysis == ANALYSIS
    # Other inputs, another model, or no cache: asked again.
    write_prompt(PromptRequest("a leather sofa", "a marsh"), service(server), cache_dir=cache)
    assert len(server.requests) == 2
    server.replies = [Reply(answer(GOOD))]
    assert not write_prompt(SOFA, service(server), cache_dir=cache, use_cache=False).cached
    assert len(server.requests) == 3


@pytest.mark.parametrize("how", ["offline", "blender_offline", "no_endpoint"])
def test_offline_makes_no_connection_and_uses_the_template(server, cache, how, monkeypatch):
    monkeypatch.setenv("OPENAI_BASE_URL", "")
    monkeypatch.setenv("SCENEFIT_CONFIG", str(cache / "none.toml"))
    server.replies = [Reply(answer(GOOD))]
    svc = None if how == "no_endpoint" else service(server)
    result = write_prompt(SOFA, svc, offline=how == "offline", online_access=how != "blender_offline", cache_dir=cache)
    assert result.prompt == "a leather sofa in a swamp" and result.source == "template"
    assert not result.model_written and result.to_report()["model_written"] is False and result.reason
    assert server.connections == 0 and server.requests == []
    instruct = write_prompt(PromptRequest("a leather sofa", "a swamp", "instruct"), svc, offline=True, cache_dir=cache)
    assert instruct.prompt == "place the leather sofa in the swamp" and server.connections == 0


def test_cli_prompt_online_offline_and_errors(server, tmp_path, capsys):
    from scenefit.cli import main

    base = ["prompt", "--object", "a leather sofa", "--scene", "a swamp", "--prompt-cache", str(tmp_path / "c"),
            "--config", str(tmp_path / "none.toml")]
    server.replies = [Reply(answer(GOOD))]
    assert main(base + ["--endpoint", server.url, "--model", "m", "--stream", "--report", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == GOOD and ANALYSIS in err and "written by 'm'" in err
    assert json.loads((tmp_path / "r.json").read_text())["analysis"] == ANALYSIS
    assert main(base + ["--endpoint", server.url, "--model", "m", "--offline"]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == "a leather sofa in a swamp" and "not model-written" in err and len(server.requests) == 1
    server.replies = [Reply(status=500, text="down")]
    assert main(base + ["--endpoint", server.url, "--model", "m", "--no-prompt-cache"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "HTTP 500" in err and "Traceback" not in err


def test_photo_is_sent_to_a_vision_model_only(server, cache, tmp_path):
    from scenefit.core.data.imageio import write_image

    photo = tmp_path / "swamp.png"
    write_image(photo, np.random.default_rng(0).uniform(0, 1, (40, 60, 3)).astype(np.float32))
    server.replies = [Reply(answer(GOOD)), Reply(answer(GOOD))]
    request = PromptRequest("a leather sofa", "", photo=str(photo))
    result = write_prompt(request, service(server, model="llava-13b"), cache_dir=cache)
    assert result.photo_sent
    parts = server.requests[0]["body"]["messages"][0]["content"]
    assert "[the scene]: the given image\n" in parts[0]["text"]
    url = parts[1]["image_url"]["url"]
    assert url.startswith("data:image/jpeg;base64,") and base64.b64decode(url.split(",", 1)[1])[:2] == b"\xff\xd8"
    # A text-only model gets the words, not the photo; without words it cannot know the scene.
    with pytest.raises(InputError, match="not known to read images"):
        write_prompt(request, service(server, model="plain-llm"), cache_dir=cache)
    text_only = write_prompt(PromptRequest("a leather sofa", "a swamp", photo=str(photo)), service(server, model="plain-llm"),
                             cache_dir=cache)
    assert not text_only.photo_sent and isinstance(server.requests[1]["body"]["messages"][0]["content"], str)
    assert any("photo not sent" in w for w in text_only.warnings)


def test_settings_from_config_file_and_environment(server, tmp_path, monkeypatch, cache):
    config = tmp_path / "config.toml"
    config.write_text(f'[prompting]\nendpoint = "{server.url}"\nmodel = "from-file"\napi_key = "file-key"\ntimeout_s = 7\n')
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    monkeypatch.delenv("OPENAI_BASE_URL", raising=False)
    svc = resolve_service(config_path=config)
    assert (svc.base_url, svc.model, svc.key_source, svc.timeout_s) == (server.url, "from-file", "config file", 7.0)
    assert "file-key" not in repr(svc)
    monkeypatch.setenv("OPENAI_API_KEY", "env-key")
    svc = resolve_service(model="arg-model", config_path=config)
    assert svc.model == "arg-model" and svc.key_source == "OPENAI_API_KEY"
    server.replies = [Reply(answer(GOOD))]
    write_prompt(SOFA, svc, cache_dir=cache)
    headers = {k.lower(): v for k, v in server.requests[0]["headers"].items()}
    assert headers["authorization"] == "Bearer env-key"
    assert resolve_service(config_path=tmp_path / "missing.toml") is None
    with pytest.raises(InputError, match="Name the chat model"):
        resolve_service(endpoint=server.url, config_path=tmp_path / "missing.toml")
    (tmp_path / "bad.toml").write_text("[prompting\n")
    with pytest.raises(InputError, match="not valid TOML"):
        resolve_service(config_path=tmp_path / "bad.toml")


def test_answer_parsing_checks_and_repairs_at_extremes():
    assert split_answer(answer(GOOD)) == (ANALYSIS, GOOD)
    assert split_answer(GOOD) == ("", GOOD)
    assert split_answer(f"{ANALYSIS}\n\n**Description:** {GOOD}")[1] == GOOD
    assert split_answer(f"{ANALYSIS}\n\n{GOOD}") == (ANALYSIS, GOOD)
    assert problems(GOOD, SOFA) == []
    assert problems("a leather sofa", SOFA) == ["it has 3 words but must have 25 to 35"]
    assert problems(GOOD.replace("sofa", "couch"), SOFA)[0].startswith("it leaves out the word(s) 'sofa'")
    assert problems(GOOD.replace("sofa", "sofas"), SOFA) == []          # plurals count
    assert PromptRequest("A Leather   sofa", "x").required_words == ("leather", "sofa")
    # A first clause longer than the limit is cut by words.
    assert count_words(shorten(" ".join(["word"] * 50), 35)) == 35
    fixed, notes = repair(LONG.replace("leather ", ""), SOFA)
    assert problems(fixed, SOFA) == [] and len(notes) == 2
    assert template_prompt(PromptRequest("an old chair", "the beach.", "instruct")) == "place the old chair in the beach"
    with pytest.raises(InputError, match="scene must be described in words"):
        template_prompt(PromptRequest("a chair", "", photo="x.png"))
    with pytest.raises(InputError):
        PromptRequest("", "a swamp")
    with pytest.raises(InputError):
        PromptRequest("a sofa", "a swamp", mode_type="poem")


def test_adapt_writes_its_prompt_from_object_and_scene(server, tmp_path, capsys):
    """`scenefit adapt --object-prompt --scene-prompt` without --prompt: the model's description is
    the prompt the critics get (edit mode: its instruction), and the report keeps the analysis."""
    from scenefit.cli import build_parser, main
    from scenefit.cli.options import scene_conditional_prompt
    from scenefit.core.data.asset_io import save_asset_folder
    from scenefit.core.data.maps import PBRMaps
    from scenefit.core.data.primitives import uv_sphere
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.texture import NeuralTexture, save_neural_texture

    common = ["--prompt-cache", str(tmp_path / "c"), "--config", str(tmp_path / "none.toml"),
              "--prompt-endpoint", server.url, "--prompt-model", "m"]
    parse = build_parser().parse_args
    server.replies = [Reply(answer(GOOD))]
    args = parse(["adapt", "x", "--out", "o", "--object-prompt", "a leather sofa", "--scene-prompt", "a swamp"] + common)
    prompt, instruction, written = scene_conditional_prompt(args, "scene")
    assert prompt == GOOD and instruction == "" and written.analysis == ANALYSIS
    args = parse(["adapt", "x", "--out", "o", "--prompt", "mine", "--object-prompt", "a", "--scene-prompt", "b"] + common)
    assert scene_conditional_prompt(args, "scene") == ("mine", "", None) and len(server.requests) == 1
    # --offline (adapt's own: no downloads) also means template prompts, with no connection.
    args = parse(["adapt", "x", "--out", "o", "--object-prompt", "a leather sofa", "--scene-prompt", "a bog",
                  "--offline"] + common)
    assert scene_conditional_prompt(args, "scene")[0] == "a leather sofa in a bog" and server.connections == 1

    mesh = uv_sphere(segments=12, rings=6)
    save_asset_folder(mesh, PBRMaps(base_color=np.full((16, 16, 3), 0.5, np.float32), roughness=0.5, metallic=0.0),
                      tmp_path / "asset")
    save_neural_texture(NeuralTexture(stage_config("texture", "draft", resolution=16, log2_table=10), seed=0), tmp_path / "texture.pt")
    base, inpaint = shared_tiny_pair()
    server.replies = [Reply(answer(GOOD_INSTRUCTION, "Instructions"))]
    out = tmp_path / "out"
    assert main(["adapt", str(tmp_path / "asset"), "--mode", "edit", "--texture", str(tmp_path / "texture.pt"),
                 "--object-prompt", "a leather sofa", "--scene-prompt", "a swamp", "--preset", "draft",
                 "--iterations", "1", "--model-resolution", "32", "--render-size", "16", "--base-model", str(base),
                 "--inpaint-model", str(inpaint), "--out", str(out), "--quiet"] + common) == 0
    assert INSTRUCT_STEP in user_text(server.requests[-1]["body"])
    report = json.loads((out / "report.json").read_text())
    assert report["prompt_writing"]["prompt"] == GOOD_INSTRUCTION and report["prompt_writing"]["analysis"] == ANALYSIS
    # The critics' prompt is the object and the model's instruction combined (adapt's edit mode).
    assert report["decisions"]["prompt"]["choice"].startswith("a leather sofa, Soak the leather sofa, darken the leather")


def test_run_takes_its_prompt_from_object_and_scene(server, tmp_path):
    """`scenefit run --object-prompt --scene-prompt` without --prompt: the written description is the
    RunConfig's prompt (adapt's); with --prompt nothing is asked."""
    from scenefit.cli import build_parser
    from scenefit.cli.run import run_config

    base = ["run", "asset", "--photo", str(tmp_path / "photo.png"), "--at", "0.5,0.8", "--out", str(tmp_path / "o"),
            "--prompt-cache", str(tmp_path / "c"), "--config", str(tmp_path / "none.toml"),
            "--prompt-endpoint", server.url, "--prompt-model", "text-llm"]
    server.replies = [Reply(answer(GOOD))]
    config, written = run_config(build_parser().parse_args(base + ["--object-prompt", "a leather sofa",
                                                                   "--scene-prompt", "a swamp"]))
    assert config.prompt == GOOD and written.analysis == ANALYSIS and not written.photo_sent
    assert "[the scene]: a swamp" in user_text(server.requests[0]["body"])
    config, written = run_config(build_parser().parse_args(base + ["--prompt", "mine", "--object-prompt", "a sofa",
                                                                   "--scene-prompt", "a bog"]))
    assert (config.prompt, written, len(server.requests)) == ("mine", None, 1)
