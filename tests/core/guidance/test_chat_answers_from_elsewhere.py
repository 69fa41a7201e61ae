"""A chat endpoint is a service from elsewhere: whatever it answers (HTML, JSON of another shape, HTTP
errors, an answer trickled for ever, a body of megabytes, the API key echoed back) ends in a prompt or in
one PromptServiceError sentence, within the time-out; a damaged cache entry is asked for again; the key
never reaches a report, a cache entry or a message. A real HTTP server on 127.0.0.1 answers."""
from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenefit.core.base.errors import PromptServiceError
from scenefit.core.guidance.prompting import MAX_ANSWER_BYTES, PromptRequest, ServiceConfig, write_prompt

GOOD = ("The leather sofa, partially submerged in the swamp, looks discolored and soggy, its once-polished "
        "surface marred by mud, moss, and the murky water of the swamp environment.")
KEY = "sk-test-0123456789abcdef"
REQUEST = PromptRequest("a leather sofa", "a swamp")


def completion(content) -> bytes:
    return json.dumps({"id": "c", "object": "chat.completion", "created": 0, "model": "m", "choices": [
        {"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}]}).encode()


class RawServer:
    """Answers each POST with the next scripted (status, content type, body, seconds between bytes);
    a body may name the Authorization header it was sent as {auth}."""

    def __init__(self) -> None:
        self.script: list[tuple] = []
        self.requests = 0
        self.stop_event = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args) -> None:
                pass

            def do_POST(self) -> None:
                self.rfile.read(int(self.headers.get("Content-Length", 0)))
                server.requests += 1
                status, kind, body, trickle = server.script.pop(0) if server.script else (500, "text/plain", b"none", 0)
                body = body.replace(b"{auth}", self.headers.get("Authorization", "").encode())
                self.send_response(status)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                try:
                    if not trickle:
                        self.wfile.write(body)
                        return
                    for byte in body:   # one byte at a time, each well inside the client's per-read time-out
                        if server.stop_event.wait(trickle):
                            return
                        self.wfile.write(bytes([byte]))
                        self.wfile.flush()
                except OSError:   # the client hung up
                    pass

        class Server(ThreadingHTTPServer):
            daemon_threads = True

        self.httpd = Server(("127.0.0.1", 0), Handler)
        threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/v1"

    def close(self) -> None:
        self.stop_event.set()
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture
def server():
    raw = RawServer()
    yield raw
    raw.close()


def ask(server, tmp_path, timeout_s=5.0, stream=False, **kw):
    service = ServiceConfig(base_url=server.url, model="m", api_key=KEY, key_source="arguments", timeout_s=timeout_s,
                            stream=stream)
    return write_prompt(REQUEST, service, cache_dir=tmp_path / "cache", **kw)


def one_sentence(error: Exception, *words: str) -> str:
    text = str(error)
    assert "\n" not in text and text.endswith(".") and KEY not in text, text
    for word in words:
        assert word in text, (word, text)
    return text


@pytest.mark.parametrize("status, kind, body, words", [
    (200, "text/html", b"<html><body>Welcome to nginx!</body></html>", ("not a chat completion", "not valid JSON")),
    (200, "application/json", b"[]", ("not a chat completion",)),
    (200, "application/json", b'{"choices": "none"}', ("'choices'",)),
    (200, "application/json", json.dumps({"choices": [{"message": {"content": 5}}]}).encode(), ("content",)),
    (200, "application/json", b'{"choices": []}', ("no choices",)),
    (502, "text/html", b"<html>Bad gateway</html>", ("HTTP 502",)),
    (401, "application/json", b'{"error": {"message": "bad key {auth}"}}', ("HTTP 401",)),
])
def test_an_answer_that_is_not_a_chat_completion_is_one_sentence(server, tmp_path, status, kind, body, words):
    server.script = [(status, kind, body, 0)]
    with pytest.raises(PromptServiceError) as caught:
        ask(server, tmp_path)
    one_sentence(caught.value, *words)
    assert not list((tmp_path / "cache").glob("*")) if (tmp_path / "cache").exists() else True


def test_a_trickled_answer_is_stopped_at_the_time_out(server, tmp_path):
    server.script = [(200, "application/json", completion(GOOD), 0.3)]   # 0.3 s a byte: minutes in all
    started = time.perf_counter()
    with pytest.raises(PromptServiceError) as caught:
        ask(server, tmp_path, timeout_s=1.5)
    seconds = time.perf_counter() - started
    one_sentence(caught.value, "within 1.5 s")
    assert seconds < 4, seconds


def test_a_huge_body_is_not_read_whole(server, tmp_path):
    server.script = [(200, "application/json", b" " * (MAX_ANSWER_BYTES + 10) + completion(GOOD), 0)]
    with pytest.raises(PromptServiceError) as caught:
        ask(server, tmp_path)
    one_sentence(caught.value, "over 4 MiB")


def test_a_streamed_answer_that_is_not_events_of_chunks_is_one_sentence(server, tmp_path):
    server.script = [(200, "text/event-stream", b"data: <html>\n\n", 0)]
    with pytest.raises(PromptServiceError) as caught:
        ask(server, tmp_path, stream=True)
    one_sentence(caught.value, "streamed piece")


@pytest.mark.parametrize("damage", [b"[]", b"{}", b'{"prompt": 3}', b"\xff", b"[" * 50_000])
def test_a_damaged_cache_entry_is_asked_for_again(server, tmp_path, damage):
    server.script = [(200, "application/json", completion(f"Analysis.\n\nDescription: {GOOD}"), 0)] * 2
    first = ask(server, tmp_path)
    [entry] = (tmp_path / "cache").glob("*.json")
    entry.write_bytes(damage)
    again = ask(server, tmp_path)
    assert server.requests == 2 and not again.cached and again.prompt == first.prompt == GOOD
    assert json.loads(entry.read_text())["prompt"] == GOOD   # written whole again
    assert ask(server, tmp_path).cached and server.requests == 2


def test_the_api_key_an_endpoint_echoes_is_kept_out_of_report_cache_and_messages(server, tmp_path):
    echoed = f"Analysis: your header was {{auth}}.\n\nDescription: {GOOD}".encode()
    server.script = [(200, "application/json", completion(echoed.decode()), 0)]
    result = ask(server, tmp_path)
    assert result.prompt == GOOD and "[API key]" in result.analysis
    assert KEY not in json.dumps(result.to_report())
    assert all(KEY not in p.read_text() for p in (tmp_path / "cache").glob("*"))
    server.script = [(200, "text/event-stream", b'data: {"choices": [{"delta": {"content": "{auth}"}}]}\n\n'
                      b"data: [DONE]\n\n", 0)]
    seen = []
    with pytest.raises(PromptServiceError) as caught:   # a 1-word answer is no prompt, and says what it was
        write_prompt(REQUEST, ServiceConfig(base_url=server.url, model="m", api_key=KEY, timeout_s=5, stream=True),
                     cache_dir=tmp_path / "other", on_text=seen.append)
    one_sentence(caught.value)
    assert KEY not in "".join(seen)


bodies = st.one_of(
    st.binary(max_size=200),
    st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=40),
                 lambda c: st.lists(c, max_size=3) | st.dictionaries(
                     st.sampled_from(["choices", "message", "content", "delta", "refusal", "finish_reason"]), c,
                     max_size=3), max_leaves=12).map(lambda v: json.dumps(v).encode()),
    st.builds(completion, st.one_of(st.text(max_size=300), st.none(), st.integers())),
)


@settings(derandomize=True, max_examples=50, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(body=bodies, stream=st.booleans(), status=st.sampled_from([200, 200, 200, 404, 500]))
def test_fuzz_any_answer_gives_a_prompt_or_one_sentence(server, tmp_path, body, stream, status):
    server.script = [(status, "text/event-stream" if stream else "application/json",
                      (b"data: " + body + b"\n\ndata: [DONE]\n\n") if stream else body, 0)] * 2
    try:
        result = ask(server, tmp_path, stream=stream, use_cache=False)
        assert result.prompt.strip() and result.source == "model"
    except PromptServiceError as error:
        one_sentence(error)


@pytest.mark.parametrize("text, words", [
    ('[prompting]\ntimeout_s = "soon"\n', ("'timeout_s'",)),
    ("[prompting]\ntimeout_s = inf\n", ("'timeout_s'", "finite")),
    ("a = " + "[" * 5000 + "]" * 5000 + "\n", ("nests too deep",)),
    ("[prompting]\nendpoint = 5\n", ("'endpoint'",)),
])
def test_a_config_file_of_another_shape_is_one_sentence(tmp_path, text, words):
    from scenefit.core.base.errors import InputError
    from scenefit.core.guidance.prompting import read_config_file, resolve_service

    path = tmp_path / "config.toml"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        resolve_service(config_path=path)
    one_sentence(caught.value, str(path), *words)
    path.write_text('[prompting]\nendpoint = "http://127.0.0.1:9/v1"\nmodel = "m"\ntimeout_s = 30\n')
    assert read_config_file(path)["timeout_s"] == 30 and resolve_service(config_path=path).timeout_s == 30.0
