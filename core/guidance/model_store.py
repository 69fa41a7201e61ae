"""The model manager: for each model SceneFit uses (Stable Diffusion 2 base and inpainting, the depth
model) whether it is on this machine, how large, where; downloading it (bytes, speed, cancel, resumed
after a cancel or a lost connection); removing it; and, without a network, what to fetch and where.

Models live in the Hugging Face cache (`models.hub_cache`: HF_HUB_CACHE / HF_HOME, or the cache folder
asked for), in the hub's own layout, so weights another tool already fetched are used where they are and
never copied. A model given as a local folder is the artist's: it is reported, never removed.

huggingface_hub (2.x) deletes a file's partial download when the download fails, so a cancelled
multi-gigabyte file would start over. The bytes are therefore fetched here with the hub's own `http_get`
(its Range resume) into `blobs/<etag>.incomplete`, kept across cancels, then linked into the snapshot
and the revision recorded with the hub's own helpers, as its downloads do. Everything the server names
is checked before it names a file (the commit and each ETag a hash, each file a relative path inside the
snapshot), and a blob is kept only when its bytes hash to its ETag: the hub's answers are data.
"""
from __future__ import annotations

import fnmatch
import hashlib
import math
import os
import re
import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..base.errors import InputError, ModelMissingError, SceneFitError
from ..base.progress import ProgressCallback, ProgressEvent, check_cancel, emit
from .models import (ABOUT_DOWNLOAD, BASE_PARTS, DEFAULT_DEPTH_MODEL, IGNORE_PATTERNS, DEPTH_PATTERNS, INPAINT_PARTS, ModelConfig, hub_cache, hub_offline, hub_patterns,
                     is_unread_copy)

FOUND, PARTIAL, MISSING, FOLDER, FOLDER_INCOMPLETE = "found", "partial", "missing", "folder", "folder incomplete"
PARTIAL_SUFFIX = ".incomplete"
_COMMIT = re.compile(r"[0-9a-f]{40}")
_ETAG = re.compile(r"[0-9a-f]{40}|[0-9a-f]{64}")   # a git blob's sha1 or an LFS file's sha256
DOWNLOAD_STAGE = "download"



@dataclass(frozen=True)
class ModelSpec:
    """One model: its role (`key`), the artist's name for it, the hub id or folder, and its files."""

    key: str
    label: str
    model: str
    allow: tuple[str, ...]       # the files of the repository a run reads
    required: tuple[str, ...]    # patterns each matching at least one file of a usable snapshot

    @property
    def is_folder(self) -> bool:
        return Path(self.model).expanduser().is_dir() or self.model.startswith((".", "/", "~")) or \
            self.model.count("/") > 1

    @property
    def about_bytes(self) -> int | None:
        return ABOUT_DOWNLOAD.get(self.model)


@dataclass(frozen=True)
class ModelState:
    """What the manager shows for one model; `where` is the folder a run reads (None while missing)."""

    key: str
    label: str
    model: str
    state: str
    bytes_on_disk: int
    about_bytes: int | None
    where: str | None
    cache: str
    removable: bool
    fetch: str   # one sentence: what to fetch and where to put it

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _required(parts: dict) -> tuple[str, ...]:
    return tuple(f"{sub}/{marker or '*'}" for sub, marker in parts.items()) + tuple(
        f"{sub}/*.safetensors" for sub in parts if sub not in ("tokenizer", "scheduler"))


def model_specs(config: ModelConfig = ModelConfig(), depth_model: str | None = None) -> tuple[ModelSpec, ...]:
    """The three models a run may need, as `config` (and the depth preference) name them."""
    return (
        ModelSpec("base", "Stable Diffusion 2 base", config.base_model, tuple(hub_patterns(BASE_PARTS)),
                  _required(BASE_PARTS)),
        ModelSpec("inpaint", "Stable Diffusion 2 inpainting", config.inpaint_model,
                  tuple(hub_patterns(INPAINT_PARTS)), _required(INPAINT_PARTS)),
        depth_spec(depth_model or DEFAULT_DEPTH_MODEL),
    )


def depth_spec(model: str) -> ModelSpec:
    return ModelSpec("depth", "Depth model", model, tuple(DEPTH_PATTERNS),
                     ("config.json", "preprocessor_config.json", "*.safetensors"))


def spec_named(specs: tuple[ModelSpec, ...], key: str) -> ModelSpec:
    for spec in specs:
        if spec.key == key:
            return spec
    raise InputError(f"There is no model '{key}'; the models are {', '.join(s.key for s in specs)}.")


def storage_folder(cache: Path, repo_id: str) -> Path:
    """The hub cache's folder of one model repository (blobs/, snapshots/, refs/)."""
    return cache / f"models--{repo_id.replace('/', '--')}"


def _files(folder: Path) -> list[str]:
    return [p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()]


def _complete(folder: Path, required: tuple[str, ...]) -> bool:
    """Whether `folder` holds a file for each pattern, counting only files the loader reads: a snapshot of
    half-precision copies alone (IGNORE_PATTERNS) is not found, the loader would ask for the full ones."""
    files = [f for f in _files(folder) if not is_unread_copy(f)] if folder.is_dir() else []
    return all(any(fnmatch.fnmatch(f, pattern) for f in files) for pattern in required)


def _size(folder: Path) -> int:
    """Bytes the folder takes (a snapshot's links are not counted twice: only real files)."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) \
        if folder.is_dir() else 0


def _snapshot(storage: Path, spec: ModelSpec) -> Path | None:
    """The snapshot of the revision 'main' points at, when it holds every required file: the folder the
    loaders' own lookup (the hub's, by that ref) resolves to."""
    ref = storage / "refs" / "main"
    if not ref.is_file():
        return None
    head = storage / "snapshots" / ref.read_text().strip()
    return head if head.is_dir() and _complete(head, spec.required) else None


def model_state(spec: ModelSpec, cache: Path) -> ModelState:
    """Where `spec` is on this machine and how large, read from the file system alone (no network)."""
    def state(name, size, where, removable):
        return ModelState(spec.key, spec.label, spec.model, name, size, spec.about_bytes,
                          str(where) if where is not None else None, str(cache), removable,
                          fetch_sentence(spec, cache))

    if spec.is_folder:
        folder = Path(spec.model).expanduser()
        found = _complete(folder, spec.required)
        return state(FOLDER if found else FOLDER_INCOMPLETE, _size(folder), folder if folder.is_dir() else None, False)
    storage = storage_folder(cache, spec.model)
    snapshot = _snapshot(storage, spec)
    # the files and partial downloads (in snapshots/ themselves where the file system has no links), without
    # the hub's bookkeeping
    weights = _size(storage / "blobs") + _size(storage / "snapshots")
    if snapshot is not None:
        return state(FOUND, weights, snapshot, True)
    if storage.is_dir():
        return state(PARTIAL, weights, storage, True)
    return state(MISSING, 0, None, False)


def model_states(config: ModelConfig = ModelConfig(), depth_model: str | None = None) -> list[ModelState]:
    cache = hub_cache(config.cache_dir)
    return [model_state(spec, cache) for spec in model_specs(config, depth_model)]


def fetch_sentence(spec: ModelSpec, cache: Path) -> str:
    """What to fetch and where to put it, for a machine that cannot download it itself."""
    if spec.is_folder:
        return f"The {spec.label} is the folder '{spec.model}', which must hold {', '.join(spec.required)}."
    include = " ".join(f"--include '{p}'" for p in spec.allow)
    exclude = " ".join(f"--exclude '{p}'" for p in IGNORE_PATTERNS)
    return (f"{spec.label}: on a connected machine run `hf download {spec.model} {include} {exclude} "
            f"--cache-dir CACHE`, then copy CACHE/{storage_folder(Path('.'), spec.model).name} into '{cache}'.")


def remove_model(spec: ModelSpec, cache: Path) -> int:
    """Delete a hub model's folder from the cache (its blobs, partial downloads, snapshots); the bytes freed.
    A model given as a folder is the artist's and is never deleted."""
    if spec.is_folder:
        raise InputError(f"The {spec.label} is your folder '{spec.model}'; SceneFit does not delete it.")
    storage = storage_folder(cache, spec.model)
    if storage.is_symlink():   # the cache's folder is a link (to the user's folder): never deleted through
        raise InputError(f"'{storage}' is a link to '{os.path.realpath(storage)}', not a folder of the cache; "
                         "SceneFit deletes nothing through it (remove the link yourself).")
    if not storage.is_dir():
        return 0
    freed = _size(storage)
    shutil.rmtree(storage)
    return freed


# -- downloading -----------------------------------------------------------------------------------

class _Transfer:
    """Bytes fetched so far, their speed, progress events and the cancel check, shared by each file's
    download (the hub's downloader calls `update` for every chunk it receives, before writing it)."""

    def __init__(self, spec: ModelSpec, total: int, done: int, progress: ProgressCallback | None,
                 cancel: threading.Event | None) -> None:
        self.spec, self.total, self.done, self.progress, self.cancel = spec, total, done, progress, cancel
        self.fetched, self.started, self.file = 0, time.perf_counter(), ""

    @property
    def speed(self) -> float:
        return self.fetched / max(time.perf_counter() - self.started, 1e-6)

    def report(self) -> None:
        message = (f"{self.spec.label}: {self.file}, {format_bytes(self.done)} of {format_bytes(self.total)} "
                   f"at {format_bytes(self.speed)}/s")
        emit(self.progress, DOWNLOAD_STAGE, self.done, max(self.total, 1), message,
             {"bytes": self.done, "total_bytes": self.total, "bytes_per_s": round(self.speed, 1)})

    def update(self, n: int) -> None:
        check_cancel(self.cancel)
        self.done += int(n or 0)
        self.fetched += int(n or 0)
        self.report()

    def bar_class(self):
        """A progress-bar class for the hub's `http_get`: each chunk goes to `update`."""
        transfer = self

        class Bar:
            def __init__(self, *args, **kwargs) -> None:
                pass

            def __enter__(self):
                return self

            def __exit__(self, *exc) -> None:
                pass

            def update(self, n: int = 1) -> None:
                transfer.update(n)

            def close(self) -> None:
                pass

        return Bar


def in_megabytes(progress: ProgressCallback) -> ProgressCallback:
    """A download's progress counted in megabytes, its bytes and speed said in the message: what a progress bar
    shows (the stage's name is the unit: "MB 10/25")."""
    def forward(event: ProgressEvent) -> None:
        total = max(1, math.ceil(event.total / 1_000_000))
        progress(ProgressEvent("MB", total if event.step >= event.total else event.step // 1_000_000, total,
                               event.message))

    return forward


def format_bytes(count: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if abs(count) < 1000 or unit == "GB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000.0
    return f"{count:.1f} GB"


def _hub_refused(spec: ModelSpec, what: str) -> ModelMissingError:
    return ModelMissingError(f"The hub's answer for {spec.model} is not usable: {what}; nothing was written "
                             "outside the cache.")


def _checked_name(spec: ModelSpec, name: object) -> str:
    """A file name from the hub's listing: a relative path of plain parts, as a repository holds."""
    if not isinstance(name, str) or not name or len(name) > 500 or "\\" in name or "\x00" in name or \
            any(part in ("", ".", "..") for part in name.split("/")):
        raise _hub_refused(spec, f"it lists a file named {str(name)[:80]!r}")
    return name


def _repo_files(api, spec: ModelSpec, revision: str) -> tuple[str, dict[str, int]]:
    """(commit, {file: size}) of the files `spec` needs at `revision`, from the hub's listing."""
    # lazy: huggingface_hub is needed only to find or fetch models
    from huggingface_hub.hf_api import RepoFile
    from huggingface_hub.utils import filter_repo_objects

    commit = api.repo_info(spec.model, revision=revision).sha
    if not isinstance(commit, str) or not _COMMIT.fullmatch(commit):
        raise _hub_refused(spec, f"its commit {str(commit)[:80]!r} is not a commit hash")
    tree = [f for f in api.list_repo_tree(spec.model, recursive=True, revision=commit) if isinstance(f, RepoFile)]
    wanted = set(filter_repo_objects([f.path for f in tree], allow_patterns=list(spec.allow),
                                     ignore_patterns=IGNORE_PATTERNS))
    sizes = {_checked_name(spec, f.path): (f.lfs.size if f.lfs is not None else f.size) for f in tree
             if f.path in wanted}
    if not all(isinstance(n, int) and 0 <= n < 2**45 for n in sizes.values()):
        raise _hub_refused(spec, "it lists a file size that is not a byte count")
    return commit, sizes


def _hashes_to(path: Path, etag: str) -> bool:
    """Whether the file's bytes are those `etag` names: an LFS file's sha256, or a git blob's sha1."""
    digest = hashlib.sha256() if len(etag) == 64 else hashlib.sha1(b"blob %d\0" % path.stat().st_size)
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest() == etag


def _fetch_blob(spec: ModelSpec, storage: Path, commit: str, name: str, endpoint: str | None,
                transfer: _Transfer) -> str:
    """One file's bytes into blobs/<etag>, resumed from blobs/<etag>.incomplete when an earlier try left one;
    the file's ETag."""
    # lazy: huggingface_hub is needed only to find or fetch models
    from huggingface_hub import get_hf_file_metadata, hf_hub_url
    from huggingface_hub.utils import WeakFileLock

    meta = get_hf_file_metadata(hf_hub_url(spec.model, name, revision=commit, endpoint=endpoint))
    if not isinstance(meta.etag, str) or not _ETAG.fullmatch(meta.etag):
        raise _hub_refused(spec, f"'{name}' comes with the ETag {str(meta.etag)[:80]!r}, which is not a file hash")
    blob = storage / "blobs" / meta.etag
    # The hub's own lock for this blob: another download of it (SceneFit's or the hub's) waits, never appends.
    lock = storage.parent / ".locks" / storage.name / f"{meta.etag}.lock"
    lock.parent.mkdir(parents=True, exist_ok=True)
    with WeakFileLock(lock):
        if blob.is_file() and not blob.is_symlink():   # fetched by an earlier, stopped download: only its link is missing
            transfer.done += blob.stat().st_size
            return meta.etag
        blob.parent.mkdir(parents=True, exist_ok=True)
        partial = blob.with_name(blob.name + PARTIAL_SUFFIX)
        resumed = _fetch_into(partial, meta, transfer)
        matches = _hashes_to(partial, meta.etag)   # (each read hashes gigabytes: once a fetch)
        if not matches and resumed:
            # the kept part was not the start of this file (damaged or planted): fetched once more, whole
            partial.unlink()
            _fetch_into(partial, meta, transfer)
            matches = _hashes_to(partial, meta.etag)
        if not matches:
            partial.unlink()
            raise ModelMissingError(f"'{name}' of {spec.model} arrived with bytes that do not match its hash "
                                    f"{meta.etag}; nothing was kept, the next download fetches it again.")
        os.replace(partial, blob)
    return meta.etag


def _fetch_into(partial: Path, meta, transfer: _Transfer) -> bool:
    """The rest of the file into `partial` (the hub's Range resume); whether a kept part was resumed."""
    from huggingface_hub.file_download import http_get   # lazy: needed only to fetch models
    from huggingface_hub.utils import build_hf_headers   # lazy: needed only to fetch models

    if partial.is_symlink() or (partial.exists() and not partial.is_file()):
        partial.unlink()   # a partial is SceneFit's own plain file; anything else is not appended to
    with partial.open("ab") as out:
        kept = out.tell()
        if meta.size is not None and kept > meta.size:   # longer than the file: not a part of it
            out.truncate(0)
            kept = 0
        transfer.done += kept
        http_get(meta.location, out, resume_size=kept, headers=build_hf_headers(),
                 expected_size=meta.size, tqdm_class=transfer.bar_class())
    arrived = partial.stat().st_size
    if meta.size is not None and arrived != meta.size:
        partial.unlink()
        raise ModelMissingError(f"'{partial.name}' arrived with {arrived} bytes, not {meta.size}; "
                                "the next download fetches it again.")
    return kept > 0


def _link_snapshot(storage: Path, commit: str, revision: str, blobs: dict[str, str]) -> None:
    """Each fetched file linked into snapshots/<commit>/ from its checked blob, and the revision recorded, by the
    hub's own helpers (relative links, or copies where the file system has none)."""
    from huggingface_hub.file_download import _cache_commit_hash_for_specific_revision, _create_symlink  # lazy: fetching only

    snapshot = storage / "snapshots" / commit
    for name, etag in blobs.items():
        pointer = snapshot / name
        pointer.parent.mkdir(parents=True, exist_ok=True)
        _create_symlink(str(storage / "blobs" / etag), str(pointer), new_blob=False)
    _cache_commit_hash_for_specific_revision(str(storage), revision, commit)


def _already_there(storage: Path, commit: str, name: str) -> bool:
    return (storage / "snapshots" / commit / name).is_file()


def download_model(spec: ModelSpec, cache: Path, progress: ProgressCallback | None = None,
                   cancel: threading.Event | None = None, endpoint: str | None = None,
                   revision: str = "main", announce: Callable[[int, int], None] | None = None) -> ModelState:
    """Fetch the files of `spec` a run reads into the hub cache at `cache`: progress as bytes with speed,
    `cancel` honoured between chunks (the partial file is kept and the next call resumes it). `announce(total,
    here)` is told the download's size (the hub's listing) and the bytes already here before any is fetched."""
    from huggingface_hub import HfApi  # lazy: huggingface_hub is needed only to find or fetch models

    if spec.is_folder:
        raise InputError(f"The {spec.label} is the folder '{spec.model}'; there is nothing to download.")
    if hub_offline():
        raise ModelMissingError(f"Downloading is off (HF_HUB_OFFLINE is set). {fetch_sentence(spec, cache)}")
    storage = storage_folder(cache, spec.model)
    try:
        commit, sizes = _repo_files(HfApi(endpoint=endpoint), spec, revision)
        todo = [n for n in sorted(sizes) if not _already_there(storage, commit, n)]
        transfer = _Transfer(spec, sum(sizes.values()), sum(sizes[n] for n in sizes if n not in todo), progress, cancel)
        if announce is not None:
            announce(transfer.total, transfer.done)
        blobs = {}
        for name in todo:
            check_cancel(cancel)
            transfer.file = name
            transfer.report()
            blobs[name] = _fetch_blob(spec, storage, commit, name, endpoint, transfer)
        check_cancel(cancel)
        _link_snapshot(storage, commit, revision, blobs)
    except SceneFitError:   # a cancel
        raise
    except Exception as error:
        if isinstance(error, OSError) and error.errno is not None:   # the disk (full, read-only): said as it is
            raise
        # the network or the hub (whose errors are OSErrors without an errno): what went wrong, what to do instead
        raise ModelMissingError(f"The {spec.label} could not be downloaded ({type(error).__name__}: "
                                f"{_first_line(error)}); the part fetched so far is kept for the next try. "
                                f"{fetch_sentence(spec, cache)}") from None
    return model_state(spec, cache)


def _first_line(error: Exception) -> str:
    lines = str(error).strip().splitlines()
    return lines[0][:200] if lines else "no detail"


def download_missing(config: ModelConfig, keys: tuple[str, ...], progress: ProgressCallback | None = None,
                     cancel: threading.Event | None = None, depth_model: str | None = None,
                     endpoint: str | None = None) -> list[ModelState]:
    """A run's download step (its job thread calls it): each of `keys` not yet here is fetched, with
    progress and cancel; offline, one sentence per missing model says what to fetch and where."""
    cache = hub_cache(config.cache_dir)
    specs = [spec_named(model_specs(config, depth_model), key) for key in keys]
    missing = [s for s in specs if model_state(s, cache).state not in (FOUND, FOLDER)]
    if missing and (config.offline or hub_offline()):
        raise ModelMissingError(" ".join(fetch_sentence(s, cache) for s in missing))
    return [download_model(s, cache, progress, cancel, endpoint) for s in missing]
