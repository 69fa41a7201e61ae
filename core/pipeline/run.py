"""The whole pipeline for one asset and one photo: convert -> light -> adapt -> compose -> bake.

    result = run_pipeline(mesh, maps, photo_path, placement, out_dir, RunConfig(...), progress, cancel)

Each stage writes into its own folder under out_dir and, last, a `stage.json` holding its key: a
digest of its settings, of the inputs it reads and of the keys of the stages it depends on. A later
run whose key for a stage matches a finished stage.json (and whose listed outputs still exist)
reuses that stage and says so; anything else runs it again, and with it every stage after it.
Stages hand data to each other only through their files, so a reused stage and a fresh one look
the same downstream. Plain data in (arrays, paths, a frozen config), a RunResult out (core/pipeline/result.py;
`to_report()` is report.json): the Ray batch runner calls this function as it is.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import threading
import time
from dataclasses import asdict, dataclass, is_dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..base.atomic import write_json_atomic
from ..base.errors import InputError
from ..base.progress import ProgressCallback, check_cancel, emit
from ..base.report import relative_paths, write_report
from ..base.untrusted import read_stage_record
from ..data.finite_maps import finite_outputs
from ..data.maps import PBRMaps
from ..data.materials import AssetMaterials
from ..data.mesh import Mesh, normalize_to_unit_sphere
from ..data.photo import load_photo
from ..guidance.models import GuidanceModels, ModelCache, ModelConfig, locate_models, models_available
from ..render.backend import environment_info
from ..scene.camera import PhotoCamera
from ..scene.placement import Placement
# GameBake: bake(texture.pt, stage folder, cancel) -> the started bake of the asset's own file; its wait()
# gives the report with "outputs". It needs Blender, which core/ never imports: bake_process runs it as a
# child process, so it runs while the run composes.
from ..stages.bake.process import GameBake
from ..stages.camera import photo_camera_estimate, read_fspy
from ..stages.camera_stage import read_camera
from ..stages.light.shadow_hint import shadow_pixels
from .layout import STAGE_FILE, RunLayout
from .presets import stage_config
from .registry import REGISTRY, Stage, names, stage
from .result import NOT_LISTED, RunResult, StageRecord
from .run_config import RunConfig, stage_subset


def _digest(*parts: Any) -> str:
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str((part.dtype, part.shape)).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, (bytes, bytearray)):
            h.update(part)
        else:
            h.update(json.dumps(part, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def asset_digest(mesh: Mesh, maps: PBRMaps | None) -> str:
    """The asset's mesh and maps (maps None: a run given its texture reads the mesh alone)."""
    stack = maps.stacked() if maps is not None else b""
    return _digest(mesh.positions, mesh.faces, mesh.uvs, mesh.normals if mesh.normals is not None else b"", stack)


@dataclass(frozen=True)
class GivenOutputs:
    """What a run of FROM_GIVEN_STAGES starts from, made before and elsewhere (Blender's Convert and Estimate
    Light): the neural texture (convert's weights; None: mode "generate" makes one) and the light map the
    local views are lit by (None: the adapt preset's light). Their bytes key the stage, as a stage's key
    holds the keys of the stages it reads."""

    texture: Path | None = None
    light: Path | None = None


class StageRunner:
    """Runs or reuses one stage at a time, and keeps the run's report."""

    def __init__(self, out: Path, progress: ProgressCallback | None, cancel: threading.Event | None,
                 earlier: Path | None = None, before_work: Callable[[], None] | None = None) -> None:
        self.out, self.progress, self.cancel = out, progress, cancel
        self.earlier = earlier   # a finished run's folder: a stage of it with this run's key is copied in, not redone
        self.before_work = before_work   # called once, before the first stage that is not reused
        self.stages: dict[str, dict[str, Any]] = {}
        self.fresh = False   # once a stage runs, every later stage runs too

    def run(self, name: str, key: str, work: Callable[[Path], dict[str, Any]]) -> dict[str, Any]:
        """Reuse the stage, or do `work(folder) -> report` and record it."""
        def begin(folder: Path) -> Callable[[], dict[str, Any]]:
            report = work(folder)
            return lambda: report

        return self.start(name, key, begin)()

    def start(self, name: str, key: str, begin: Callable[[Path], Callable[[], dict[str, Any]]],
              later_stages_follow: bool = True) -> Callable[[], dict[str, Any]]:
        """Reuse the stage, or `begin(folder)` its work, which returns a function that waits for its report.
        Returns a function that waits, records the stage and gives its report. `later_stages_follow`
        False: a stage started ahead of others (the bake, while compose runs) does not make them run."""
        check_cancel(self.cancel)
        folder = self.out / name
        record = folder / STAGE_FILE
        run_order = names().RUN_ORDER
        index = run_order.index(name)
        report = None if self.fresh else _finished_stage(folder, key)
        source = ""
        if report is None and not self.fresh and self.earlier is not None and not folder.exists() \
                and _finished_stage(self.earlier / name, key) is not None:
            # The earlier run's stage, copied whole: this run's folder stays one unit of its own, and the
            # earlier run is left as it was. Copies, not hard links: Blender opens these images (the
            # result material's maps, the World's light.exr) and may save an edit into them in place.
            shutil.copytree(self.earlier / name, folder)
            report, source = _finished_stage(folder, key), f" from {self.earlier.name}"
        if report is not None:
            emit(self.progress, "run", index + 1, len(run_order), f"{name}: reused{source} (same settings and inputs)")
            self.stages[name] = {"status": "reused", "key": key, "seconds": 0.0, "report": report}
            if source:
                self.stages[name]["from"] = str(self.earlier)
            return lambda: report
        if self.before_work is not None:
            check, self.before_work = self.before_work, None
            check()
        self.fresh = self.fresh or later_stages_follow
        emit(self.progress, "run", index, len(run_order), f"{name}: running")
        t0 = time.perf_counter()
        if folder.is_symlink():   # a link in the run folder: the stage writes its own folder, never through it
            folder.unlink()
        record.unlink(missing_ok=True)  # a stage half redone is not a finished stage
        wait = begin(folder)

        def finish() -> dict[str, Any]:
            report = wait()
            seconds = time.perf_counter() - t0
            # Outputs are kept relative to the stage's folder: the run's folder may be moved (Blender swaps
            # it into place, a batch worker sends it home) and a later run must still find them.
            write_json_atomic(record, {"key": key, "report": dict(report, outputs=relative_paths(
                report.get("outputs", {}), folder))})
            self.stages[name] = {"status": "ran", "key": key, "seconds": round(seconds, 3), "report": report}
            emit(self.progress, "run", index + 1, len(run_order), f"{name}: done in {seconds:.1f} s")
            return report

        return finish

    def skip(self, name: str, status: str, why: str) -> None:
        self.stages[name] = {"status": status, "why": why}
        run_order = names().RUN_ORDER
        emit(self.progress, "run", run_order.index(name) + 1, len(run_order), f"{name}: {status}")


def _finished_stage(folder: Path, key: str) -> dict[str, Any] | None:
    """The report of the stage finished in `folder` with `key` whose outputs all exist, else None. A
    stage.json is data from wherever the folder came from (an earlier run, a worker, someone else's run
    folder): one that does not read as a stage record, an output that leads out of the stage's folder
    ('..', an absolute path, a link), or a float map that is not finite is not this stage's, so the
    stage is not taken as finished and runs again."""
    record = folder / STAGE_FILE
    if not record.is_file():
        return None
    try:
        saved = read_stage_record(record)
    except InputError:
        return None
    report = saved.report.model_dump()
    report["outputs"] = _absolute_outputs(report.get("outputs", {}), folder)
    inside = folder.parent.resolve() / folder.name   # (a stage folder that is itself a link out is not inside)
    outputs = _paths(report["outputs"])
    if saved.key != key or not all(Path(p).exists() and Path(p).resolve().is_relative_to(inside) for p in outputs):
        return None
    return report if finite_outputs(outputs) else None


def _absolute_outputs(outputs: Any, folder: Path) -> Any:
    """A stage.json's outputs (kept relative to the stage's folder) as paths from here."""
    if isinstance(outputs, dict):
        return {k: _absolute_outputs(v, folder) for k, v in outputs.items()}
    return str(folder / outputs) if isinstance(outputs, str) else outputs


def _paths(outputs: Any) -> list[str]:
    if isinstance(outputs, dict):
        return [p for v in outputs.values() for p in _paths(v)]
    return [outputs] if isinstance(outputs, str) else []


def run_pipeline(mesh: Mesh | AssetMaterials | None, maps: PBRMaps | None, photo_path: str | Path | None, placement: Any,
                 out_dir: str | Path, config: RunConfig = RunConfig(), progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None, bake: GameBake | None = None,
                 bake_skipped_why: str = "no game bake was asked for", models: ModelCache | None = None,
                 reuse_from: str | Path | None = None, stages: tuple[str, ...] | None = None,
                 given: GivenOutputs | None = None) -> RunResult:
    """Convert the asset, estimate the photo's light, adapt the texture (when the SD2 weights exist),
    compose the asset into the photo, and bake (when `bake` is given); returns the run's RunResult (its
    to_report() is out_dir/report.json).

    mesh, maps: the asset, or (maps None) every material of it (core/data/materials.AssetMaterials), which
    convert fits each at its own cell's size, as `scenefit convert` does; both None for the light alone
    (PHOTO_ONLY_STAGES), which reads the photo only.
    placement: (x, y) as fractions of the photo's width and height (both <= 1) or pixels, or "X,Y".
    models: the loaded diffusion models to use (a ModelCache: a batch worker keeps one for its life,
    so its jobs load them once); default a cache for this run, so light and adapt share one load.
    reuse_from: a finished run's folder (Blender's Run All makes a new folder per run): each of its stages
    whose key this run shares is copied into out_dir and reused, as a stage already in out_dir is.
    stages: the subset to run (stage_subset: convert and/or light alone, or the pipeline, adapt and bake
    optional; default every listed stage); a run without light or compose reads no photo. With `given`
    (the texture and light map made before), FROM_GIVEN_STAGES alone: adapt, of the photo when a scene-mode
    run gives one.
    This is the one place the stages are strung together (each stage's record in core/pipeline/registry.py,
    run in the registry's order): the command line, batch jobs, remote workers, the Blender operators and
    the demo all call it.
    """
    stages = names().STAGES if stages is None else stages
    stages = stage_subset(stages) if given is None else from_given(stages)
    run = PipelineRun(mesh, maps, photo_path, placement, out_dir, config, progress, cancel, models,
                      reuse_from, stages, given, bake)
    run.run_stages(bake_skipped_why)
    return run.finish()


def from_given(stages: Sequence[str]) -> tuple[str, ...]:
    """`stages` when they are FROM_GIVEN_STAGES, else one sentence: the rest of a run makes its own inputs."""
    from_given_stages = names().FROM_GIVEN_STAGES
    if tuple(stages) != from_given_stages:
        raise InputError(f"A run from a given texture runs {', '.join(from_given_stages)} alone, not "
                         f"{', '.join(stages) or 'nothing'}.")
    return from_given_stages


def guidance_found(config: RunConfig) -> tuple[bool, str]:
    """Whether adapt (and the diffusion light critic) run, and why: the one place `--guidance-type` is decided."""
    if config.guidance_type == "sd2":
        locate_models(config.models, need_inpaint=True)   # missing weights: a clear error before any work
        return True, "asked for (--guidance-type sd2)"
    if config.guidance_type == "auto":
        return models_available(config.models)
    return False, "guidance none"


class PipelineRun:
    """One run's shared state: the checked inputs, each stage's key, the runner that reuses stages. Every
    stage runs through `run_stage` from its registry record: its config from its work module, its key from
    what the record says it reads."""

    def __init__(self, mesh: Mesh | AssetMaterials | None, maps: PBRMaps | None, photo_path: str | Path | None,
                 placement: Any, out_dir: str | Path, config: RunConfig, progress: ProgressCallback | None,
                 cancel: threading.Event | None, models: ModelCache | None, reuse_from: str | Path | None = None,
                 stages: tuple[str, ...] | None = None, given: GivenOutputs | None = None,
                 bake: GameBake | None = None) -> None:
        self.started = time.perf_counter()
        stage_names = names()
        stages = stage_names.STAGES if stages is None else stages
        self.stages, self.given, self.bake = stages, given, bake
        if mesh is None and not set(stages) <= set(stage_names.PHOTO_ONLY_STAGES):
            raise InputError(f"The stages {', '.join(stages)} need an asset; only "
                             f"{', '.join(stage_names.PHOTO_ONLY_STAGES)} runs on a photo alone.")
        self.asset = mesh   # what convert fits: a mesh with its maps, or every material of an asset
        if isinstance(mesh, AssetMaterials):
            mesh, maps = mesh.fitting_view()   # (the one mesh and maps the other stages see)
        assert mesh is None or maps is not None or given is not None
        self._mesh, self._maps, self.config, self.progress, self.cancel = mesh, maps, config, progress, cancel
        self.out = Path(out_dir).resolve()   # stage.json lists absolute outputs, whatever the working folder
        self.layout = RunLayout(self.out)
        # Everything that can be wrong with the inputs is found before any work.
        # (adapt from a given texture reads the photo a scene-mode run gives; without one it sees local views)
        reads_photo = any(stage in stages for stage in stage_names.PHOTO_STAGES) or \
            (given is not None and photo_path is not None and config.mode == "scene")
        if reads_photo and photo_path is None:
            raise InputError(f"The stages {', '.join(stages)} read a photo, and none was given.")
        self.photo_path = Path(photo_path) if reads_photo and photo_path is not None else None
        if self.photo_path is not None:
            self.read_photo(placement)
        # Guidance is adapt's, and the light critic's beside it; light alone chooses its critic as `scenefit light`.
        self.found, self.where = guidance_found(config) if "compose" in stages else \
            (True, "asked for (adapt from a given texture)") if given is not None else (False, "light alone")
        self.cache = models if models is not None else ModelCache()
        self.asset_key = None if mesh is None else asset_digest(mesh, maps)
        self._normalized = None if mesh is None else normalize_to_unit_sphere(mesh)[0]
        self.runner = StageRunner(self.out, progress, cancel, Path(reuse_from).resolve() if reuse_from else None,
                                  before_work=self.check_the_view)
        self.camera: tuple[PhotoCamera, dict[str, Any]] | None = None   # the photo's camera, once estimated
        self.keys: dict[str, str] = {}   # each stage's key, once it is known
        self.done: list[str] = []        # the stages whose outputs are there (ran or reused), in order
        self.background: list[Any] = []  # the background stages' processes (the bake), once begun
        self.given_outputs: dict[str, Path] = {}
        if given is not None:   # what the given files hold stands for the stages that made them
            for output, path, made_by in (("texture", given.texture, "convert"), ("light", given.light, "light")):
                self.keys[made_by] = _digest(f"given {output}", _file_bytes(path))
                if path is not None:
                    self.given_outputs[output] = Path(path)

    # The asset as the stages that need one see it (the constructor refused a run without one that needs one).
    @property
    def mesh(self) -> Mesh:
        assert self._mesh is not None
        return self._mesh

    @property
    def maps(self) -> PBRMaps:
        assert self._maps is not None
        return self._maps

    @property
    def normalized(self) -> Mesh:
        assert self._normalized is not None
        return self._normalized

    def read_photo(self, placement: Any) -> None:
        """The photo (the light stage's working copy), where the asset stands in it, the shadow's points and the
        fSpy project, each one sentence when wrong."""
        config = self.config
        assert self.photo_path is not None
        self.photo, self.photo_info = load_photo(self.photo_path)
        h, w = self.photo.shape[:2]
        self.placement = Placement.parse(placement, tuple(self.photo_info["size"]))   # pixels of the photo as stored
        self.placement_px = self.placement.pixel((h, w))                              # ... in the light stage's copy
        if config.sun_shadow is not None:   # a malformed point is one sentence before any work
            shadow_pixels(config.sun_shadow, tuple(self.photo_info["size"]), (h, w))
        if config.fspy is not None and config.photo_camera is None:
            read_fspy(config.fspy)   # a broken fSpy file is one sentence before any work
        self.photo_key = _digest(self.photo_path.read_bytes())

    # -- the stages, from the registry ------------------------------------------------------------------------

    def plan(self, bake_skipped_why: str = "no game bake was asked for") -> list[tuple[Stage, str | None]]:
        """(record, why it is skipped or None) of each stage this run runs or records, in the registry's order:
        the listed stages the run was given, the stage a job does not list (the camera) when the photo is
        read, and, in a pipeline, each optional stage not listed (or, a background one, given no process) as
        skipped."""
        pipeline = self.given is None and set(names().PIPELINE_STAGES) <= set(self.stages)
        planned: list[tuple[Stage, str | None]] = []
        for record in REGISTRY:
            if not record.listed:
                if self.photo_path is not None:
                    planned.append((record, None))
            elif record.background:
                if pipeline:
                    ready = record.name in self.stages and self.bake is not None
                    planned.append((record, None if ready else bake_skipped_why))
            elif record.name in self.stages:
                skipped = getattr(record.module(), "skipped", None)
                planned.append((record, skipped(self) if skipped is not None else None))
            elif pipeline and record.optional:
                planned.append((record, f"the run's stages do not list {record.name}"))
        return planned

    def run_stages(self, bake_skipped_why: str = "no game bake was asked for") -> None:
        """Each planned stage in order; a background stage (the bake) begun once no stage still to run
        writes the texture, waited for at the end, and stopped if a stage fails (a cancel, a refusal)."""
        self.planned = self.plan(bake_skipped_why)
        to_run = [record for record, why in self.planned if why is None]
        waits: list[Callable[[], dict[str, Any]]] = []
        waiting = [record for record in to_run if record.background]
        try:
            for record, why in self.planned:
                if why is not None:   # a stage the run was not asked for is "not listed", not a skip to be said
                    self.runner.skip(record.name, "skipped" if record.name in self.stages else NOT_LISTED, why)
                elif not record.background:
                    self.begin_background(waiting, to_run[to_run.index(record):], waits)
                    self.run_stage(record)
            self.begin_background(waiting, [], waits)
        except BaseException:
            for process in self.background:
                process.stop()
            raise
        for wait in waits:
            wait()

    def begin_background(self, waiting: list[Stage], still_to_run: list[Stage],
                         waits: list[Callable[[], dict[str, Any]]]) -> None:
        """Begin the waiting background stages once none of `still_to_run` writes the texture."""
        if waiting and not any("texture" in r.writes for r in still_to_run if not r.background):
            for record in list(waiting):
                waiting.remove(record)
                waits.append(self.start_stage(record))

    def run_stage(self, record: Stage) -> None:
        """Run or reuse one stage: its work module's config for this run, its key, its work."""
        self.start_stage(record)()

    def start_stage(self, record: Stage) -> Callable[[], dict[str, Any]]:
        steps = record.module()
        config = steps.configure(self)
        key_of = getattr(steps, "key_of", None)
        self.keys[record.name] = self.stage_key(record, key_of(config) if key_of is not None else config)

        def begin(folder: Path) -> Callable[[], dict[str, Any]]:
            if record.background:
                return steps.begin(self, config, folder)
            report = steps.work(self, config, folder)
            return lambda: report

        wait = self.runner.start(record.name, self.keys[record.name], begin,
                                 later_stages_follow=record.later_stages_follow and not record.background)

        def finish() -> dict[str, Any]:
            report = wait()
            self.done.append(record.name)
            return report

        return finish

    def stage_key(self, record: Stage, config: Any) -> str:
        """The digest of the stage's config, of the keys of the stages it reads that this run has, and of the
        run's inputs it reads: a stage whose key matches a finished one is reused."""
        reads = {name: self.keys[name] for name in record.reads if name in self.keys}
        return _digest(record.name, _settings(config), reads, {name: self.input_value(name) for name in record.inputs})

    def input_value(self, name: str) -> Any:
        """What a stage's key holds of the run's input `name` (None: the run has none)."""
        photo = self.photo_path is not None
        values = {"asset": [self.asset_key, isinstance(self.asset, AssetMaterials)],
                  "photo": self.photo_key if photo else None,
                  "placement": [list(self.placement_px), self.config.size] if photo else None,
                  "turn": self.config.turn_deg, "sun_shadow": self.config.sun_shadow}
        if name not in values:
            raise InputError(f"No run input is called '{name}'; a stage reads {', '.join(values)}.")
        return values[name]

    def output(self, name: str) -> Path | None:
        """The file `name` ("texture", "light", "camera", ...) as the run has it now: the latest stage's that
        writes it and whose outputs are there, else the one given (None: neither)."""
        for stage_name in reversed(self.done):
            if name in stage(stage_name).writes:
                return self.layout.file(stage_name, name)
        return self.given_outputs.get(name)

    def config_of(self, name: str) -> Any:
        """Stage `name`'s config at the run's preset with the run's overrides for it (a stage whose config the
        run's other settings do not reach)."""
        return stage_config(name, self.config.preset, **self.config.overrides(name))

    def file_digest(self, path: str | Path | None) -> str | None:
        return None if path is None else _digest(_file_bytes(Path(path)))

    def light_models(self) -> Any:
        """The models the light stage loads: with the inpainting UNet when adapt follows, so both share one load."""
        return _WithInpaint(self.cache) if self.found else self.cache

    # -- the photo's camera ------------------------------------------------------------------------------------

    def stage_camera(self, width: int, height: int) -> tuple[PhotoCamera, dict[str, Any]]:
        """The camera stage's camera at an image of `width` x `height`, and its estimate's record."""
        path = self.output("camera")
        assert path is not None   # (the camera stage ran)
        return read_camera(path, width, height)

    def photo_camera(self) -> tuple[PhotoCamera, dict[str, Any]]:
        """The photo's camera (at the light stage's working size) and where it came from: the camera stage's
        once it is written (or reused), else the caller's, else the estimate (fSpy, EXIF, the photo's lines, or
        the defaults, each field saying which) with the user's values over it. Estimated once a run."""
        if self.camera is None:
            h, w = self.photo.shape[:2]
            path = self.output("camera")
            if path is not None and path.is_file():
                self.camera = self.stage_camera(w, h)
            elif self.config.photo_camera is not None:
                self.camera = replace(self.config.photo_camera, width=w, height=h), {"source": "given by the caller"}
            else:
                assert self.photo_path is not None   # (only a run that reads the photo asks for its camera)
                estimate = photo_camera_estimate(self.photo_path, self.config.fspy, self.config.camera_overrides,
                                                 self.config.camera_source, self.config.camera_why)
                self.camera = estimate.photo_camera(width=w, height=h), estimate.to_dict()
        return self.camera

    def check_the_view(self) -> None:
        """What only the photo's camera shows wrong with the inputs, before the run's first work (the
        StageRunner calls it once, when a stage is about to run; a run that reuses every stage passed it
        before): each stage to run checks its own (`check` in its work module): a shadow point in the sky,
        an asset that cannot stand where it was put (a ground plane reaching behind the camera) at compose's
        turn or at adapt's. They find what the stages would find after convert (and light) had run, with the
        same camera."""
        if self.photo_path is None:   # (convert alone)
            return
        self.photo_camera()   # (the camera stage's, once it ran: estimated once a run)
        for record, why in self.planned:
            check = getattr(record.module(), "check", None)
            if why is None and check is not None:
                check(self)

    def finish(self) -> RunResult:
        recorded = self.runner.stages
        camera_stage = names().CAMERA_STAGE
        inputs: dict[str, Any] = {"asset": None if self._mesh is None else self._mesh.name,
                                  "asset_digest": self.asset_key}
        if self.photo_path is not None:
            inputs.update(photo=self.photo_info, photo_digest=self.photo_key, placement_px=list(self.placement_px))
        result = RunResult(
            folder=self.out, config=_plain(replace(self.config, models=self.config.models)), inputs=inputs,
            stages={name: StageRecord.from_runner(name, recorded[name]) for name in names().STAGES
                    if name in recorded},
            camera=StageRecord.from_runner(camera_stage, recorded[camera_stage]) if camera_stage in recorded else None,
            seconds=round(time.perf_counter() - self.started, 3), environment=environment_info())
        write_report(self.layout.report, result.to_report())   # paths relative to the run's folder
        return result


def _settings(config: Any) -> Any:
    """A stage's config as plain data for its key."""
    if is_dataclass(config) and not isinstance(config, type):
        return asdict(config)
    return config


class _WithInpaint:
    """The cache as the light stage sees it when adapt follows: it asks for the inpainting UNet too,
    so light and adapt share one loaded model set."""

    def __init__(self, cache: ModelCache) -> None:
        self.cache = cache

    def get(self, config: ModelConfig, need_inpaint: bool) -> GuidanceModels:
        return self.cache.get(config, True)


def _file_bytes(path: Path | None) -> bytes:
    """A given file's bytes for its key (b"": none given); a missing one is one sentence."""
    if path is None:
        return b""
    try:
        return Path(path).read_bytes()
    except OSError as error:
        raise InputError(f"Cannot read '{path}' ({error.strerror or error}); run the stage that makes it again.") \
            from None


def _plain(config: RunConfig) -> dict[str, Any]:
    return json.loads(json.dumps(asdict(config), default=str))
