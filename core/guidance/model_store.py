"""The model manager: for each model SceneFit uses (Stable Diffusion 2 base and inpainting, the depth
model) whether it is on this machine, how large, where; downloading it (bytes, speed, cancel, resumed
after a cancel or a lost connection); removing it; and, without a network, what to fetch and where.

Models live in the Hugging Face cache (`models.hub_cache`: HF_HUB_CACHE / HF_HOME, or the cache folder
asked for), in the hub's own layout, so weights another tool already fetched are used where they are and
never copied. A model given as a local folder is the artist's: it is reported, never removed.

huggingface_hub (2.x) deletes a file's partial download when the download fails, so a cancelled
multi-gigabyte file would start over. The bytes are therefore fetched here with the hub's own `http_get`
(its Range resume) into `blobs/<etag>.incomplete`, kept across cancels, and the hub's `snapshot_download`
then links the finished blobs into the snapshot and records the revision, as its own downloads do.
"""
from __future__ import annotations

import fnmatch
import math
import os
import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..base.errors import InputError, ModelMissingError, SceneFitError
from ..base.progress import ProgressCallback, ProgressEvent, check_cancel, emit
from .models import (ABOUT_DOWNLOAD, BASE_PARTS, DEFAULT_DEPTH_MODEL, IGNORE_PATTERNS,
                     DEPTH_PATTERNS, INPAINT_PARTS, ModelConfig, hub_cache, hub_offline, hub_patterns)

FOUND, PARTIAL, MISSING, FOLDER, FOLDER_INCOMPLETE = "found", "partial", "missing", "folder", "folder incomplete"
PARTIAL_SUFFIX = ".incomplete"
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
    files = _files(folder) if folder.is_dir() else []
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


def _quiet_bar():
    """The hub's own bar class, never drawn: the final linking step fetches nothing worth a bar on stderr."""
    from huggingface_hub.utils import tqdm  # lazy: huggingface_hub is needed only to find or fetch models

    class Quiet(tqdm):
        def __init__(self, *args, **kwargs) -> None:
            kwargs["disable"] = True
            super().__init__(*args, **kwargs)

    return Quiet


def format_bytes(count: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if abs(count) < 1000 or unit == "GB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000.0
    return f"{count:.1f} GB"


def _repo_files(api, spec: ModelSpec, revision: str) -> tuple[str, dict[str, int]]:
    """(commit, {file: size}) of the files `spec` needs at `revision`, from the hub's listing."""
    # lazy: huggingface_hub is needed only to find or fetch models
    from huggingface_hub.hf_api import RepoFile
    from huggingface_hub.utils import filter_repo_objects

    commit = api.repo_info(spec.model, revision=revision).sha
    tree = [f for f in api.list_repo_tree(spec.model, recursive=True, revision=commit) if isinstance(f, RepoFile)]
    wanted = set(filter_repo_objects([f.path for f in tree], allow_patterns=list(spec.allow),
                                     ignore_patterns=IGNORE_PATTERNS))
    return commit, {f.path: (f.lfs.size if f.lfs is not None else f.size) for f in tree if f.path in wanted}


def _fetch_blob(spec: ModelSpec, storage: Path, commit: str, name: str, endpoint: str | None,
                transfer: _Transfer) -> None:
    """One file's bytes into blobs/<etag>, resumed from blobs/<etag>.incomplete when an earlier try left one."""
    # lazy: huggingface_hub is needed only to find or fetch models
    from huggingface_hub import get_hf_file_metadata, hf_hub_url
    from huggingface_hub.file_download import http_get
    from huggingface_hub.utils import WeakFileLock, build_hf_headers

    meta = get_hf_file_metadata(hf_hub_url(spec.model, name, revision=commit, endpoint=endpoint))
    blob = storage / "blobs" / meta.etag
    # The hub's own lock for this blob: another download of it (SceneFit's or the hub's) waits, never appends.
    lock = storage.parent / ".locks" / storage.name / f"{meta.etag}.lock"
    lock.parent.mkdir(parents=True, exist_ok=True)
    with WeakFileLock(lock):
        if blob.is_file():   # fetched by an earlier, stopped download: only its link is missing
            transfer.done += blob.stat().st_size
            return
        blob.parent.mkdir(parents=True, exist_ok=True)
        partial = blob.with_name(blob.name + PARTIAL_SUFFIX)
        with partial.open("ab") as out:
            transfer.done += out.tell()
            http_get(meta.location, out, resume_size=out.tell(), headers=build_hf_headers(),
                     expected_size=meta.size, tqdm_class=transfer.bar_class())
        arrived = partial.stat().st_size
        if meta.size is not None and arrived != meta.size:
            partial.unlink()
            raise ModelMissingError(f"'{name}' of {spec.model} arrived with {arrived} bytes, not {meta.size}; "
                                    "the next download fetches it again.")
        os.replace(partial, blob)


def _already_there(storage: Path, commit: str, name: str) -> bool:
    return (storage / "snapshots" / commit / name).is_file()


def download_model(spec: ModelSpec, cache: Path, progress: ProgressCallback | None = None,
                   cancel: threading.Event | None = None, endpoint: str | None = None,
                   revision: str = "main", announce: Callable[[int, int], None] | None = None) -> ModelState:
    """Fetch the files of `spec` a run reads into the hub cache at `cache`: progress as bytes with speed,
    `cancel` honoured between chunks (the partial file is kept and the next call resumes it). `announce(total,
    here)` is told the download's size (the hub's listing) and the bytes already here before any is fetched."""
    from huggingface_hub import HfApi, snapshot_download  # lazy: huggingface_hub is needed only to find or fetch models

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
        for name in todo:
            check_cancel(cancel)
            transfer.file = name
            transfer.report()
            _fetch_blob(spec, storage, commit, name, endpoint, transfer)
        check_cancel(cancel)
        # Every blob is here: the hub links them into the snapshot and records the revision and its file list.
        snapshot_download(spec.model, revision=revision, cache_dir=cache, allow_patterns=list(spec.allow),
                          ignore_patterns=IGNORE_PATTERNS, endpoint=endpoint, tqdm_class=_quiet_bar())
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
