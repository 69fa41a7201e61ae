"""What a batch or worker job sends of its asset, and what its inputs were (to tell a job unchanged).

A job's asset travels with the files it names and nothing else of the user's: a .gltf's or .glb's
buffers and images and an .obj's material libraries and maps as Blender reads them, a .blend's images
that are not packed into it (Blender lists them), an .fbx's images beside it whose names it holds.
They go in the layout they have below the asset's folder, so every relative reference still holds on
the worker; a name that leads out of that folder (an absolute path, '..', a link to a file outside it)
is refused in one sentence: an asset from someone else could otherwise send any file of the user's to
a cluster. A link to a file inside the folder is sent as that file, under the link's name.

The digest of a job is its settings (not where its files are: a moved jobs folder is the same job) and
the contents of what it sends. Files are hashed in chunks, and a file's hash is kept while its size and
modification time stay; a batch lists each asset's files once (`listed`), so a batch of many jobs on
one asset reads and hashes the asset once.
"""
from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path

from ..core.base.errors import InputError
from ..core.base.untrusted import Record, read_json
from .jobs import Job

# Files an .fbx may name for Blender's importer to read beside it (its images).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tga", ".tif", ".tiff", ".exr", ".hdr", ".bmp", ".webp", ".dds")


def asset_references(asset: Path) -> list[Path]:
    """The asset file and the files it names that exist, absolute and normalised as named (links kept)."""
    from ..core.data.asset_files import as_named, asset_files

    suffix = asset.suffix.lower()
    if suffix in (".gltf", ".glb", ".obj"):
        return asset_files(asset, resolve=False)
    own = as_named(asset)
    if suffix == ".blend":
        from ..blender_io.asset_file import blend_external_files

        return [own] + [p for p in blend_external_files(own) if p.is_file()]
    if suffix == ".fbx":
        return [own] + _fbx_named_images(own)
    return [own]   # .ply, .usd*: read as the file alone


def _fbx_named_images(fbx: Path) -> list[Path]:
    """The images in the .fbx's folder and below whose whole file name the .fbx holds (binary and ASCII FBX
    keep a texture's file name as a string, after a separator, a quote or its length; Blender's importer
    also looks beside the file), SceneFit's own run folders aside."""
    from ..core.base.output_folder import MARKER
    from ..core.data.asset_files import as_named

    data = fbx.read_bytes()
    runs = [marker.parent for marker in fbx.parent.rglob(MARKER)]
    found = []
    for image in sorted(fbx.parent.rglob("*")):
        if image.suffix.lower() not in IMAGE_SUFFIXES or any(run in image.parents for run in runs):
            continue
        name = image.name.encode()
        at = data.find(name)
        while at >= 0 and not (at == 0 or data[at - 1:at] in (b"/", b"\\", b'"', b"\x00")):
            at = data.find(name, at + 1)
        if at >= 0 and image.is_file():
            found.append(as_named(image))
    return found


def job_files(job: Job, listed: dict[Path, dict[str, Path]] | None = None) -> dict[str, Path]:
    """{name in the payload: file or folder}: an asset folder as asset/<its name>; an asset file and the
    files it names below asset/, as they lie below its folder; the photo as photo/<its name>, an fSpy
    project as fspy/<its name>. One sentence
    for a named file outside the asset's folder. `listed`: a batch's assets listed so far (each once)."""
    listed = {} if listed is None else listed
    if job.asset not in listed:
        listed[job.asset] = _asset_files(job)
    files = dict(listed[job.asset])
    if job.photo is not None:
        files[f"photo/{job.photo.name}"] = job.photo
    if job.run.fspy is not None:
        files[f"fspy/{Path(job.run.fspy).name}"] = Path(job.run.fspy)
    return files


def _asset_files(job: Job) -> dict[str, Path]:
    from ..core.data.asset_files import as_named, folder_files

    if job.asset.is_dir():   # its files one by one: SceneFit's own output inside it neither travels nor counts
        try:
            files = folder_files(job.asset)
        except InputError as error:
            raise InputError(f"Job '{job.name}': {error}") from None
        inside = job.asset.resolve()
        for path in job.asset.rglob("*"):   # (a folder link could loop, or lead anywhere)
            if path.is_symlink() and (path.is_dir() or not path.resolve().is_relative_to(inside)):
                _outside(job, path, job.asset, f", a link to '{path.resolve()}'")
        return {f"asset/{job.asset.name}/{path.relative_to(job.asset).as_posix()}": path for path in files}
    folder, own = as_named(job.asset.parent), as_named(job.asset)   # (the file the jobs file names may be a link)
    named: dict[str, Path] = {}
    for path in asset_references(job.asset):
        try:
            named[f"asset/{path.relative_to(folder).as_posix()}"] = path
        except ValueError:
            _outside(job, path, folder)
        if path != own and path.resolve() != path and not path.resolve().is_relative_to(folder.resolve()):
            _outside(job, path, folder, f", a link to '{path.resolve()}'")
    return named


def _outside(job: Job, path: Path, folder: Path, link: str = "") -> None:
    raise InputError(f"Job '{job.name}': '{job.asset.name}' reads '{path}'{link}, outside its folder '{folder}'; a "
                     "job sends only what lies in the asset's folder and below, so copy the file in (and name it "
                     "from there), or run the asset with scenefit run.")


def job_digest(job: Job, files: dict[str, Path]) -> str:
    """The job's settings and the contents of `files` (job_files'), not where they lie."""
    settings = {k: v for k, v in job.to_dict().items() if k not in ("asset", "photo", "fspy")}
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    for name, path in sorted(files.items()):
        for file in sorted(path.rglob("*")) if path.is_dir() else [path]:
            if file.is_file():
                digest.update(f"{name}/{file.relative_to(path).as_posix() if path.is_dir() else ''}".encode())
                stat = file.stat()
                digest.update(_file_sha(str(file), stat.st_size, stat.st_mtime_ns))
    return digest.hexdigest()


@lru_cache(maxsize=4096)
def _file_sha(path: str, size: int, mtime_ns: int) -> bytes:
    """A file's SHA-256, read in chunks; kept while its size and modification time stay."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").digest()


def user_report(report, copy: Job, job: Job, folder: Path):
    """A worker's job report naming the user's files: the inputs unpacked below `folder` (the worker's
    temporary job folder) as the files the jobs file named (jobs.with_user_paths), the earlier run's
    stages it carried as that run, so no report names a temporary folder that is gone once the job ends."""
    from .jobs import with_user_paths

    if isinstance(report, dict):
        return {k: user_report(v, copy, job, folder) for k, v in report.items()}
    if isinstance(report, (list, tuple)):
        return [user_report(v, copy, job, folder) for v in report]
    if isinstance(report, str) and str(folder) in report:
        text = with_user_paths(report, copy, job)
        return text.replace(str(folder / "in" / "earlier"), f"the earlier run of job '{job.name}'")
    return report


class _RunStages(Record):
    stages: dict[str, dict] = {}


class _JobStages(Record):
    run: _RunStages = _RunStages()


class JobReport(Record):
    """What a later batch reads of DIR/<job>/report.json (data: the folder may come from anywhere)."""

    status: str
    digest: str = ""
    attempts: int = 0
    seconds: float = 0.0
    quality: dict[str, object] = {}
    stages: _JobStages = _JobStages()


def read_job_report(path: Path) -> dict | None:
    """The job report at `path` as a dict, or None where there is none or it does not read as one (the
    job then runs again, as a job never run does)."""
    if not path.is_file():
        return None
    try:
        return read_json(path, JobReport, "job report").model_dump()
    except InputError:
        return None
