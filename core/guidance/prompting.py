"""Scene-conditional prompts written by a language model (paper §3 "GPT-prompted", appendix
"Prompting with GPT-4"), with the paper's "manually combined" template when offline.

The paper asks GPT-4 first to discuss how the scene physically changes the object, then to distil
that into a 25-35-word mechanistic description that contains every word of the object prompt
("describe" mode, for Stable Diffusion), or into 20-30 words of verb-first instructions
("instruct" mode, the InstructPix2Pix variant). The appendix's wording is kept verbatim in
DESCRIBE_STEP / INSTRUCT_STEP; SceneFit adds one line (ANSWER_FORMAT) so the final prompt can be
told apart from the analysis.

Any OpenAI-compatible chat endpoint works (hosted, llama.cpp, Ollama, vLLM) through the `openai`
client. The answer is checked (one line, length, required words); a failing answer is asked for
once more with the problem stated, then repaired locally (cut at a clause boundary, object phrase
put in front). Answers are cached on disk by everything that went into the request, so the same
inputs never cost a second call. Offline nothing touches the network.
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import re
import threading
import time
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, Callable

import numpy as np
from pydantic import Field

from ..base.atomic import write_json_atomic
from ..base.errors import InputError, PromptServiceError
from ..base.untrusted import Record, checked, parse_json, read_bytes, read_json
from ..data.imageio import linear_to_srgb, read_color_image

MODE_TYPES = ("describe", "instruct")
VISION_TYPES = ("auto", "yes", "no")

# The appendix's instructions, word for word (including its "[the environment]" in the
# instruction form, which means the scene).
ANALYSIS_STEP = (
    "Now, imagine a picture where [the object] is placed into [the scene]. First, detailedly discuss the "
    "environmental impacts of [the scene] imposes on the appearance of [the object]. Focus on the physical "
    "impacts instead of lighting impacts."
)
DESCRIBE_STEP = (
    "Then provide a succinct, purely descriptive, short, and mechanistic description of the appearance of "
    "[the object] inside [the scene] concatenated with \",\". Aim the description to be approximately 25 to 35 "
    "words in length. Use simple language. Include all words provided in [the object]."
)
INSTRUCT_STEP = (
    "Then provide a succinct instructions on how to change the appearance [the object] such that it looks "
    "realistic when placed in [the environment]. Start with each instruction with a verb and concatenate them "
    "with \",\". Aim the description to be approximately 20 to 30 words in length. Use simple language. "
    "Include all words provided in [the object]."
)
# SceneFit's addition: a label that separates the final prompt from the analysis.
ANSWER_FORMAT = "Write the discussion first. Then write the {what} alone on the last line, beginning with \"{label}:\"."


@dataclass(frozen=True)
class ModeSpec:
    step: str
    label: str
    what: str
    words: tuple[int, int]


MODES = {
    "describe": ModeSpec(DESCRIBE_STEP, "Description", "description", (25, 35)),
    "instruct": ModeSpec(INSTRUCT_STEP, "Instructions", "instructions", (20, 30)),
}

# Articles are not "words of the object" the answer must repeat: the paper's own example turns
# "a leather sofa" into "The leather sofa, partially submerged ...".
OPTIONAL_WORDS = frozenset({"a", "an", "the"})

# Model names that read images (matched as substrings, lower case); `vision_type` overrides.
VISION_MODEL_HINTS = ("gpt-4o", "gpt-4.1", "gpt-4-turbo", "gpt-4-vision", "gpt-5", "o3", "o4-", "vision",
                      "llava", "-vl", "vl-", "pixtral", "gemma3", "gemma-3", "minicpm-v", "moondream",
                      "qwen2.5vl", "llama4", "claude", "gemini")

REFUSAL_START = re.compile(r"^\W*(i'?m sorry|i am sorry|sorry,|i can(?:'|no)t|i will not|i won'?t|as an ai)", re.I)
WORD = re.compile(r"[\w'’-]+")
CACHE_VERSION = 1


@dataclass(frozen=True)
class PromptRequest:
    """What the prompt is about: the object, the scene in words and/or a photo, and the mode."""

    object_prompt: str
    scene_prompt: str = ""
    mode_type: str = "describe"
    photo: str = ""                   # path of the scene photo (sent only to a vision model)
    follow_up: str = ""               # a further turn, e.g. "Suppose it has stood there for decades."

    def __post_init__(self) -> None:
        if self.mode_type not in MODE_TYPES:
            raise InputError(f"Prompt mode must be one of {MODE_TYPES}, got {self.mode_type!r}.")
        if not self.object_prompt.strip():
            raise InputError("The object prompt is empty: say what the object is, e.g. --object 'a leather sofa'.")
        if not self.scene_prompt.strip() and not self.photo:
            raise InputError("Say what the scene is (e.g. --scene 'a swamp') or give its photo (--photo).")

    @property
    def required_words(self) -> tuple[str, ...]:
        words = [w.lower() for w in WORD.findall(self.object_prompt)]
        return tuple(dict.fromkeys(w for w in words if w not in OPTIONAL_WORDS))


@dataclass(frozen=True)
class ServiceConfig:
    """An OpenAI-compatible chat endpoint. `key_source` says where the key came from (never the key)."""

    base_url: str
    model: str
    api_key: str = field(default="", repr=False)
    key_source: str = "none"
    timeout_s: float = 60.0
    vision_type: str = "auto"
    stream: bool = False

    def __post_init__(self) -> None:
        if not self.base_url.startswith(("http://", "https://")):
            raise InputError(f"Prompt endpoint must be an http(s) URL such as http://127.0.0.1:8080/v1, got {self.base_url!r}.")
        if not self.model.strip():
            raise InputError(f"Name the chat model to use at {self.base_url} (--model, or 'model' in the config file).")
        if self.vision_type not in VISION_TYPES:
            raise InputError(f"vision must be one of {VISION_TYPES}, got {self.vision_type!r}.")
        if not self.timeout_s > 0:
            raise InputError(f"The prompt time-out must be positive, got {self.timeout_s}.")

    @property
    def reads_images(self) -> bool:
        if self.vision_type != "auto":
            return self.vision_type == "yes"
        name = self.model.lower()
        return any(hint in name for hint in VISION_MODEL_HINTS)


@dataclass(frozen=True)
class PromptResult:
    """The prompt and how it was made; `to_report()` is what goes into report.json."""

    prompt: str
    mode_type: str
    source: str                       # "model" or "template"
    reason: str = ""                  # why the template was used
    analysis: str = ""
    answers: tuple[str, ...] = ()     # the model's raw answers, in order
    repairs: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    model: str = ""
    endpoint: str = ""
    photo_sent: bool = False
    cached: bool = False
    requests: int = 0                 # chat requests made by this call (0 when cached or offline)
    seconds: float = 0.0

    @property
    def model_written(self) -> bool:
        return self.source == "model"

    def to_report(self) -> dict:
        report = asdict(self)
        report["model_written"] = self.model_written
        report["answers"] = list(self.answers)
        report["repairs"] = list(self.repairs)
        report["warnings"] = list(self.warnings)
        return report


# --------------------------------------------------------------------------------------------
# Settings: endpoint, model and key from arguments, the environment and a config file.

def default_config_path() -> Path:
    env = os.environ.get("SCENEFIT_CONFIG")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "scenefit" / "config.toml"


def default_cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "scenefit" / "prompts"


class PromptingTable(Record):
    """The config file's [prompting] table: each setting of the type it is used as."""

    endpoint: str = ""
    model: str = ""
    api_key: str = ""
    timeout_s: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 60.0
    vision: str = "auto"


def read_config_file(path: Path | None = None) -> dict:
    """The [prompting] table of the config file ({} when there is none)."""
    path = Path(path) if path else default_config_path()
    if not path.is_file():
        return {}
    try:
        data = tomllib.loads(read_bytes(path, 2**20, "config file").decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as error:
        reason = "it nests too deep" if isinstance(error, RecursionError) else str(error)
        raise InputError(f"The config file '{path}' is not valid TOML: {reason}.") from None
    table = data.get("prompting", {})
    if not isinstance(table, dict):
        raise InputError(f"In '{path}', 'prompting' must be a table ([prompting]).")
    checked(table, PromptingTable, f"the config file '{path}'s [prompting] table")
    return table


def resolve_service(endpoint: str = "", model: str = "", api_key: str = "", *, key_source: str = "arguments",
                    timeout_s: float | None = None, vision_type: str = "", stream: bool = False,
                    config_path: Path | None = None) -> ServiceConfig | None:
    """The chat service from explicit values (command line, add-on preferences), else the config
    file, else OPENAI_BASE_URL / OPENAI_API_KEY. None when no endpoint is configured anywhere."""
    file = read_config_file(config_path)
    base_url = endpoint or str(file.get("endpoint", "")) or os.environ.get("OPENAI_BASE_URL", "")
    if not base_url:
        return None
    if api_key:
        source = key_source
    elif os.environ.get("OPENAI_API_KEY"):
        api_key, source = os.environ["OPENAI_API_KEY"], "OPENAI_API_KEY"
    elif file.get("api_key"):
        api_key, source = str(file["api_key"]), "config file"
    else:
        source = "none"
    return ServiceConfig(base_url=base_url.rstrip("/"), model=model or str(file.get("model", "")), api_key=api_key,
                         key_source=source, timeout_s=float(timeout_s or file.get("timeout_s", 60.0)),
                         vision_type=vision_type or str(file.get("vision", "auto")), stream=stream)


def offline_reason(service: ServiceConfig | None, offline: bool = False, online_access: bool = True) -> str:
    """Why no language model may be asked ("" when one may)."""
    if offline:
        return "offline mode was asked for"
    if not online_access:
        return "Blender's online access is off (Preferences > System > Network)"
    if service is None:
        return "no chat endpoint is configured (--endpoint, the config file or OPENAI_BASE_URL)"
    return ""


# --------------------------------------------------------------------------------------------
# The request, and the checks and repairs of the answer.

def template_prompt(request: PromptRequest) -> str:
    """The paper's manual forms: "a leather sofa in a swamp" / "place the leather sofa in the swamp"."""
    obj = request.object_prompt.strip().rstrip(".")
    scene = request.scene_prompt.strip().rstrip(".")
    if not scene:
        raise InputError("Without a language model the scene must be described in words: give --scene "
                         "(the photo can only be read by a vision model).")
    if request.mode_type == "describe":
        return f"{obj} in {scene}"
    return f"place {definite(obj)} in {definite(scene)}"


def definite(phrase: str) -> str:
    """'a leather sofa' -> 'the leather sofa' (the paper's manually instructed form)."""
    return re.sub(r"^(a|an)\s+", "the ", phrase, flags=re.I)


def instruction_text(request: PromptRequest, photo_sent: bool) -> str:
    """The user message: the inputs, the appendix's two steps, the answer format."""
    spec = MODES[request.mode_type]
    scene = request.scene_prompt.strip()
    if photo_sent:
        scene = f"the given image ({scene})" if scene else "the given image"
    return "\n\n".join((
        f"[the scene]: {scene}\n[the object]: {request.object_prompt.strip()}",
        ANALYSIS_STEP,
        spec.step,
        ANSWER_FORMAT.format(what=spec.what, label=spec.label),
    ))


def split_answer(answer: str) -> tuple[str, str]:
    """(analysis, final prompt) from the model's answer: the labelled last line, else the last
    quoted sentence, else the last paragraph."""
    found = None
    for found in re.finditer(r"(?im)^[\s>*_#-]*(?:final\s+)?(?:description|instructions?)[\s*_]*:[\s*_]*", answer):
        pass
    if found is not None:
        return answer[:found.start()].strip(), answer[found.end():].strip()
    quoted = list(re.finditer(r"[\"“]([^\"“”]{20,})[\"”]", answer))
    if quoted:
        last = quoted[-1]
        line_start = answer.rfind("\n", 0, last.start()) + 1
        return answer[:line_start].strip(), last.group(1).strip()
    paragraphs = [p.strip() for p in re.split(r"\n\s*\n", answer.strip()) if p.strip()]
    if len(paragraphs) <= 1:
        return "", answer.strip()
    return "\n\n".join(paragraphs[:-1]), paragraphs[-1]


def one_line(text: str) -> tuple[str, list[str]]:
    """Whitespace folded to one line; wrapping quotes and markdown removed. Returns (text, repairs)."""
    repairs = []
    if "\n" in text.strip():
        repairs.append(f"joined {len(text.strip().splitlines())} lines into one")
    line = " ".join(text.split())
    stripped = line.strip(" *_`\"“”'")
    if stripped != line:
        repairs.append("removed quotes/markup around the prompt")
    return stripped, repairs


def count_words(text: str) -> int:
    return len(WORD.findall(text))


def missing_words(text: str, request: PromptRequest) -> list[str]:
    present = {w.lower() for w in WORD.findall(text)}
    return [w for w in request.required_words
            if w not in present and f"{w}s" not in present and f"{w}es" not in present]


def problems(text: str, request: PromptRequest) -> list[str]:
    """What is wrong with a candidate prompt, in words the model (and the user) can act on."""
    lo, hi = MODES[request.mode_type].words
    found = []
    n = count_words(text)
    if not lo <= n <= hi:
        found.append(f"it has {n} words but must have {lo} to {hi}")
    missing = missing_words(text, request)
    if missing:
        found.append("it leaves out the word(s) " + ", ".join(f"'{w}'" for w in missing)
                     + f" of the object '{request.object_prompt.strip()}'")
    return found


def shorten(text: str, max_words: int) -> str:
    """Keep whole comma-separated clauses from the start while they fit; cut words if even the
    first clause is too long."""
    clauses = [c.strip() for c in text.rstrip(". ").split(",") if c.strip()]
    kept: list[str] = []
    for clause in clauses:
        if count_words(", ".join(kept + [clause])) > max_words:
            break
        kept.append(clause)
    if not kept:
        return " ".join(text.split()[:max_words]).rstrip(",;:") + "."
    return ", ".join(kept) + "."


def repair(text: str, request: PromptRequest) -> tuple[str, list[str]]:
    """Local repairs after the retry: the object phrase put in front when words are missing, then
    clauses dropped from the end while it is too long."""
    repairs = []
    if missing_words(text, request):
        obj = request.object_prompt.strip().rstrip(".")
        text = f"{obj}, {text[0].lower() + text[1:] if text else text}"
        repairs.append(f"put '{obj}' in front (the model left out object words)")
    hi = MODES[request.mode_type].words[1]
    if count_words(text) > hi:
        n = count_words(text)
        text = shorten(text, hi)
        repairs.append(f"cut from {n} to {count_words(text)} words at a clause boundary")
    return text, repairs


# --------------------------------------------------------------------------------------------
# Talking to the service.

def encode_photo(path: str, max_side: int = 1024) -> bytes:
    """The photo as JPEG bytes (sRGB, longest side at most max_side) for a data URL."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    rgb = linear_to_srgb(read_color_image(path, upright=True))
    scale = max_side / max(rgb.shape[:2])
    if scale < 1:
        rgb = cv2.resize(rgb, (round(rgb.shape[1] * scale), round(rgb.shape[0] * scale)), interpolation=cv2.INTER_AREA)
    bgr = cv2.cvtColor((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2BGR)
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])
    if not ok:
        raise InputError(f"The photo '{path}' could not be encoded as JPEG to send it.")
    return data.tobytes()


def first_message(request: PromptRequest, photo: bytes | None) -> dict:
    text = instruction_text(request, photo_sent=photo is not None)
    if photo is None:
        return {"role": "user", "content": text}
    url = "data:image/jpeg;base64," + base64.b64encode(photo).decode("ascii")
    return {"role": "user", "content": [{"type": "text", "text": text}, {"type": "image_url", "image_url": {"url": url}}]}


def retry_message(request: PromptRequest, found: list[str]) -> dict:
    spec = MODES[request.mode_type]
    lo, hi = spec.words
    words = ", ".join(f"'{w}'" for w in request.required_words)
    return {"role": "user", "content": (
        f"Your {spec.what} cannot be used: {'; '.join(found)}. Write it again in {lo} to {hi} words on one line, "
        f"including the words {words}. Reply with only that line, beginning with \"{spec.label}:\".")}


def cache_key(service: ServiceConfig, request: PromptRequest, photo: bytes | None) -> str:
    """Everything that shapes the answer: the endpoint, the model, the exact message, the photo."""
    parts = {"v": CACHE_VERSION, "endpoint": service.base_url, "model": service.model, "mode": request.mode_type,
             "message": instruction_text(request, photo is not None), "follow_up": request.follow_up.strip(),
             "photo": hashlib.sha256(photo).hexdigest() if photo is not None else ""}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode("utf-8")).hexdigest()


# What an answer may be: a chat answer is a few kilobytes; a body larger than this is not read on.
MAX_ANSWER_BYTES = 4 * 2**20


class ChatMessage(Record):
    content: str | None = None
    refusal: str | None = None


class ChatChoice(Record):
    message: ChatMessage
    finish_reason: str | None = None


class ChatReply(Record):
    """The part of a chat-completions answer SceneFit reads (the endpoint's body is data from elsewhere)."""

    choices: list[ChatChoice]


class ChunkDelta(Record):
    content: str | None = None
    refusal: str | None = None


class ChunkChoice(Record):
    delta: ChunkDelta = ChunkDelta()
    finish_reason: str | None = None


class ChatChunk(Record):
    choices: list[ChunkChoice] = []


class ChatClient:
    """One chat-completions conversation with an OpenAI-compatible endpoint (no automatic retries:
    SceneFit retries once itself, with the problem stated). The `openai` client sends the request and
    turns HTTP errors into its exceptions; the body is read here, bounded in size and, with the
    request, in total time (a server trickling its answer a byte at a time is stopped at timeout_s)."""

    def __init__(self, service: ServiceConfig, on_text: Callable[[str], None] | None = None):
        try:
            from openai import OpenAI  # lazy: openai may be missing; only asking a language model needs it
        except ImportError as error:
            raise PromptServiceError("The 'openai' Python package is missing, so no language model can be asked; "
                                     "install SceneFit's build for your platform (it bundles it) or use --offline.") from error

        self.service = service
        self.on_text = on_text
        # Local servers need no key, but the client insists on one.
        self.client = OpenAI(base_url=service.base_url, api_key=service.api_key or "no-key",
                             timeout=service.timeout_s, max_retries=0)
        self.requests = 0

    def ask(self, messages: list[dict]) -> str:
        import openai  # lazy: openai may be missing; only asking a language model needs it

        where = f"The language model '{self.service.model}' at {self.service.base_url}"
        self.requests += 1
        answer = self._streamed if self.service.stream else self._plain
        try:
            text, refusal, finish = within_seconds(self.service.timeout_s, lambda: answer(messages), self.client.close)
        except (openai.APITimeoutError, TimeoutError) as error:
            raise PromptServiceError(f"{where} did not answer within {self.service.timeout_s:g} s; raise the "
                                     "time-out (--timeout), check the server, or write the prompt with --prompt.") from error
        except openai.APIStatusError as error:
            raise PromptServiceError(self.secret_free(
                f"{where} answered HTTP {error.status_code} ({short(error.message)}); check the "
                "endpoint, model name and API key, or use --offline.")) from None
        except openai.APIConnectionError as error:
            why = short(str(error.__cause__ or error))
            raise PromptServiceError(self.secret_free(
                f"{where} cannot be reached ({why}); check --endpoint or use --offline.")) from None
        except InputError as error:   # the body: not JSON, not a chat answer, too large
            raise PromptServiceError(self.secret_free(
                f"{where} sent an answer that is not a chat completion ({short(str(error).rstrip('.'), 200)}); "
                "check --endpoint (it must be an OpenAI-compatible /v1 URL) or use --offline.")) from None
        text, refusal = self.secret_free(text), self.secret_free(refusal)
        if refusal or finish == "content_filter" or (REFUSAL_START.match(text) and ":" not in text):
            raise PromptServiceError(f"{where} refused to write the prompt ({short(refusal or text or finish)}); "
                                     "rephrase the object or scene, or write the prompt with --prompt.")
        if not text.strip():
            raise PromptServiceError(f"{where} sent an empty answer; try another model or --offline.")
        return text

    def secret_free(self, text: str) -> str:
        """`text` with the API key blanked: an endpoint may echo it, and answers go to reports and caches."""
        key = self.service.api_key
        return text.replace(key, "[API key]") if key and len(key) >= 4 else text

    def _plain(self, messages: list[dict]) -> tuple[str, str, str | None]:
        with self.client.chat.completions.with_streaming_response.create(
                model=self.service.model, messages=messages) as response:
            body = bounded_body(response.iter_bytes(), MAX_ANSWER_BYTES)
        reply = checked(parse_json(body, "the answer", MAX_ANSWER_BYTES), ChatReply, "the answer")
        if not reply.choices:
            raise InputError("The answer has no choices.")
        choice = reply.choices[0]
        return choice.message.content or "", choice.message.refusal or "", choice.finish_reason

    def _streamed(self, messages: list[dict]) -> tuple[str, str, str | None]:
        text, refusal, finish, size = [], [], None, 0
        with self.client.chat.completions.with_streaming_response.create(
                model=self.service.model, messages=messages, stream=True) as response:
            for data in event_data(response.iter_lines()):
                size += len(data)
                if size > MAX_ANSWER_BYTES:
                    raise InputError(f"The answer is over {MAX_ANSWER_BYTES // 2**20} MiB.")
                for choice in checked(parse_json(data, "a streamed piece of the answer"), ChatChunk,
                                      "a streamed piece of the answer").choices[:1]:
                    if choice.delta.content:
                        text.append(choice.delta.content)
                        if self.on_text:
                            self.on_text(self.secret_free(choice.delta.content))
                    if choice.delta.refusal:
                        refusal.append(choice.delta.refusal)
                    finish = choice.finish_reason or finish
        return "".join(text), "".join(refusal), finish


def bounded_body(chunks, max_bytes: int) -> bytes:
    """A response body read in chunks, refused once it passes `max_bytes` (never held whole)."""
    body = bytearray()
    for chunk in chunks:
        body += chunk
        if len(body) > max_bytes:
            raise InputError(f"The answer is over {max_bytes // 2**20} MiB.")
    return bytes(body)


def event_data(lines):
    """The `data:` payloads of a server-sent event stream, up to `[DONE]` (comments, event names skipped)."""
    for line in lines:
        if line.startswith("data:"):
            data = line[5:].strip()
            if data == "[DONE]":
                return
            if data:
                yield data


def within_seconds(seconds: float, work: Callable, stop: Callable[[], None]):
    """work() in a helper thread, given `seconds` in all (the HTTP client's time-out is per read, so a
    trickling answer would never end); past them, stop() (closing the connection) and TimeoutError."""
    box: dict = {}

    def run() -> None:
        try:
            box["value"] = work()
        except BaseException as error:   # handed to the caller's thread as it is
            box["error"] = error

    thread = threading.Thread(target=run, name="scenefit-chat", daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        stop()
        raise TimeoutError(f"no whole answer within {seconds:g} s")
    if "error" in box:
        raise box["error"]
    return box["value"]


def short(text: str, limit: int = 120) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit - 1] + "…"


def checked_turn(client: ChatClient, messages: list[dict], request: PromptRequest) -> tuple[str, str, list[str], list[str]]:
    """One turn of the conversation: ask, check, ask once more with the problem stated, repair.
    Returns (analysis, prompt, answers, repairs); `messages` ends with the last answer."""
    answers = [client.ask(messages)]
    analysis, final = split_answer(answers[0])
    prompt, repairs = one_line(final)
    found = problems(prompt, request)
    if found:
        repairs.append("asked again: " + "; ".join(found))
        messages += [{"role": "assistant", "content": answers[0]}, retry_message(request, found)]
        answers.append(client.ask(messages))
        prompt, fixes = one_line(split_answer(answers[1])[1])
        repairs += fixes
        prompt, fixes = repair(prompt, request)
        repairs += fixes
    messages.append({"role": "assistant", "content": answers[-1]})
    if count_words(prompt) < 3:
        raise PromptServiceError(f"The language model '{client.service.model}' gave no usable prompt "
                                 f"({short(answers[-1])!r}); write one with --prompt or use --offline.")
    return analysis, prompt, answers, repairs


def follow_up_message(request: PromptRequest) -> dict:
    """The appendix's follow-up turn ("Let's suppose the leather sofa has been placed ... for decades.
    Consider the consequences and give me another description."), with the answer format again."""
    spec = MODES[request.mode_type]
    return {"role": "user", "content": f"{request.follow_up.strip()}\n\n"
                                       f"Write the new {spec.what} alone on the last line, beginning with \"{spec.label}:\"."}


def ask_model(request: PromptRequest, service: ServiceConfig, photo: bytes | None,
              on_text: Callable[[str], None] | None = None) -> dict:
    """The two-step request (and the user's follow-up, if any), each answer checked. Returns the
    cacheable record."""
    client = ChatClient(service, on_text)
    messages = [first_message(request, photo)]
    analysis, prompt, answers, repairs = checked_turn(client, messages, request)
    if request.follow_up.strip():
        messages.append(follow_up_message(request))
        more, prompt, later, fixes = checked_turn(client, messages, request)
        analysis = "\n\n".join(a for a in (analysis, more) if a)
        answers, repairs = answers + later, repairs + [f"follow-up: {f}" for f in fixes]
    return {"prompt": prompt, "analysis": analysis, "answers": answers, "repairs": repairs,
            "warnings": problems(prompt, request), "requests": client.requests}


def write_prompt(request: PromptRequest, service: ServiceConfig | None, *, offline: bool = False,
                 online_access: bool = True, cache_dir: Path | None = None, use_cache: bool = True,
                 on_text: Callable[[str], None] | None = None) -> PromptResult:
    """The scene-conditional prompt: from the language model (or its cached answer) when one may be
    asked, else the paper's manually combined template. Offline, nothing touches the network."""
    start = time.perf_counter()
    reason = offline_reason(service, offline, online_access)
    if reason:
        ignored = ("the follow-up needs a language model and was not used",) if request.follow_up.strip() else ()
        return PromptResult(prompt=template_prompt(request), mode_type=request.mode_type, source="template",
                            reason=reason, warnings=ignored, seconds=time.perf_counter() - start)
    assert service is not None
    photo_sent = bool(request.photo) and service.reads_images
    warnings = []
    if request.photo and not photo_sent:
        if not request.scene_prompt.strip():
            raise InputError(f"The model '{service.model}' is not known to read images, so the photo cannot describe "
                             "the scene: give --scene, or --vision if the model does read images.")
        warnings.append(f"photo not sent: '{service.model}' is not known to read images (--vision to send it)")
    photo = encode_photo(request.photo) if photo_sent else None
    path = Path(cache_dir or default_cache_dir()) / f"{cache_key(service, request, photo)}.json"
    record = read_cached(path) if use_cache else None   # a damaged entry is asked for again
    cached = record is not None
    if record is None:
        record = CachedPrompt.model_validate(ask_model(request, service, photo, on_text))
        if use_cache:
            write_json_atomic(path, record.model_dump())
    return PromptResult(prompt=record.prompt, mode_type=request.mode_type, source="model",
                        analysis=record.analysis, answers=tuple(record.answers),
                        repairs=tuple(record.repairs), warnings=tuple(warnings + list(record.warnings)),
                        model=service.model, endpoint=service.base_url, photo_sent=photo_sent, cached=cached,
                        requests=0 if cached else record.requests, seconds=time.perf_counter() - start)


class CachedPrompt(Record):
    """A prompt cache entry: what ask_model returned."""

    prompt: str
    analysis: str
    answers: list[str]
    repairs: list[str]
    warnings: list[str]
    requests: int


def read_cached(path: Path) -> CachedPrompt | None:
    """The cache entry at `path`, or None where there is none or it does not read as one (damaged,
    or written by something else): that prompt is asked for again."""
    if not path.is_file():
        return None
    try:
        return read_json(path, CachedPrompt, "prompt cache entry", max_bytes=MAX_ANSWER_BYTES)
    except InputError:
        return None
