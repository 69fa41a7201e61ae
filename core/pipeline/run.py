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
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ..base.atomic import write_json_atomic
from ..base.errors import InputError
from ..base.names import CAMERA_STAGE, FROM_GIVEN_STAGES, PHOTO_ONLY_STAGES, PHOTO_STAGES, RUN_ORDER, STAGES
from ..base.progress import ProgressCallback, check_cancel, emit
from ..base.report import relative_paths, write_report
from ..base.untrusted import read_stage_record
from ..data.finite_maps import finite_outputs
from ..data.maps import PBRMaps
from ..data.materials import AssetMaterials
from ..data.mesh import Mesh, normalize_to_unit_sphere
from ..data.photo import load_photo
from ..data.scene_needs import envmap_height_for, report as needs_report
from ..data.uv_raster import rasterize_uv
from ..guidance.models import GuidanceModels, ModelCache, ModelConfig, locate_models, models_available
from ..render.backend import environment_info
from ..render.environment import load_environment
from ..scene.asset_pose import place_asset
from ..scene.camera import PhotoCamera
from ..scene.placement import Placement
from ..stages.adapt import adapt_and_bake
from ..stages.adapt.global_views import placement_turns
from ..stages.adapt.sampling import view_azimuths
# GameBake: bake(texture.pt, stage folder, cancel) -> the started bake of the asset's own file; its wait()
# gives the report with "outputs". It needs Blender, which core/ never imports: bake_process runs it as a
# child process, so it runs while the run composes.
from ..stages.bake.process import GameBake
from ..stages.camera import photo_camera_estimate, read_fspy
from ..stages.camera_stage import CAMERA_FILE, read_camera, write_camera
from ..stages.compose import ComposeInputs, compose_to_folder
from ..stages.convert import convert_and_bake
from ..stages.light.shadow_hint import shadow_pixels, sun_from_shadow_points
from ..stages.light.stage import LightInputs, run_light, write_light
from ..texture.bake import WEIGHTS_FILE, load_neural_texture
from ..texture.surface_layout import texture_view
from . import stage_configs
from .presets import stage_config
from .result import NOT_LISTED, RunResult, StageRecord
from .run_config import RunConfig, stage_subset

STAGE_FILE = "stage.json"

def _digest(*parts) -> str:
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
        self.stages: dict[str, dict] = {}
        self.fresh = False   # once a stage runs, every later stage runs too

    def run(self, name: str, key: str, work: Callable[[Path], dict]) -> dict:
        """Reuse the stage, or do `work(folder) -> report` and record it."""
        def begin(folder: Path) -> Callable[[], dict]:
            report = work(folder)
            return lambda: report

        return self.start(name, key, begin)()

    def start(self, name: str, key: str, begin: Callable[[Path], Callable[[], dict]],
              later_stages_follow: bool = True) -> Callable[[], dict]:
        """Reuse the stage, or `begin(folder)` its work, which returns a function that waits for its report.
        Returns a function that waits, records the stage and gives its report. `later_stages_follow`
        False: a stage started ahead of others (the bake, while compose runs) does not make them run."""
        check_cancel(self.cancel)
        folder = self.out / name
        record = folder / STAGE_FILE
        index = RUN_ORDER.index(name)
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
            emit(self.progress, "run", index + 1, len(RUN_ORDER), f"{name}: reused{source} (same settings and inputs)")
            self.stages[name] = {"status": "reused", "key": key, "seconds": 0.0, "report": report}
            if source:
                self.stages[name]["from"] = str(self.earlier)
            return lambda: report
        if self.before_work is not None:
            check, self.before_work = self.before_work, None
            check()
        self.fresh = self.fresh or later_stages_follow
        emit(self.progress, "run", index, len(RUN_ORDER), f"{name}: running")
        t0 = time.perf_counter()
        if folder.is_symlink():   # a link in the run folder: the stage writes its own folder, never through it
            folder.unlink()
        record.unlink(missing_ok=True)  # a stage half redone is not a finished stage
        wait = begin(folder)

        def finish() -> dict:
            report = wait()
            seconds = time.perf_counter() - t0
            # Outputs are kept relative to the stage's folder: the run's folder may be moved (Blender swaps
            # it into place, a batch worker sends it home) and a later run must still find them.
            write_json_atomic(record, {"key": key, "report": dict(report, outputs=relative_paths(
                report.get("outputs", {}), folder))})
            self.stages[name] = {"status": "ran", "key": key, "seconds": round(seconds, 3), "report": report}
            emit(self.progress, "run", index + 1, len(RUN_ORDER), f"{name}: done in {seconds:.1f} s")
            return report

        return finish

    def skip(self, name: str, status: str, why: str) -> None:
        self.stages[name] = {"status": status, "why": why}
        emit(self.progress, "run", RUN_ORDER.index(name) + 1, len(RUN_ORDER), f"{name}: {status}")


def _finished_stage(folder: Path, key: str) -> dict | None:
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


def _absolute_outputs(outputs, folder: Path):
    """A stage.json's outputs (kept relative to the stage's folder) as paths from here."""
    if isinstance(outputs, dict):
        return {k: _absolute_outputs(v, folder) for k, v in outputs.items()}
    return str(folder / outputs) if isinstance(outputs, str) else outputs


def _paths(outputs) -> list[str]:
    if isinstance(outputs, dict):
        return [p for v in outputs.values() for p in _paths(v)]
    return [outputs] if isinstance(outputs, str) else []


def run_pipeline(mesh: Mesh | AssetMaterials | None, maps: PBRMaps | None, photo_path: str | Path | None, placement,
                 out_dir: str | Path, config: RunConfig = RunConfig(), progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None, bake: GameBake | None = None,
                 bake_skipped_why: str = "no game bake was asked for", models: ModelCache | None = None,
                 reuse_from: str | Path | None = None, stages: tuple[str, ...] = STAGES,
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
    optional); a run without light or compose reads no photo. With `given` (the texture and light map made
    before), FROM_GIVEN_STAGES alone: adapt, of the photo when a scene-mode run gives one.
    This is the one place the stages are strung together: the command line, batch jobs, remote
    workers, the Blender operators and the demo all call it.
    """
    stages = stage_subset(stages) if given is None else from_given(stages)
    run = PipelineRun(mesh, maps, photo_path, placement, out_dir, config, progress, cancel, models,  # 1. inputs
                      reuse_from, stages, given)
    if given is not None:                 # adapt alone, from the texture and light made before
        if run.photo_path is not None:
            run.camera_stage()
        run.adapt()
        return run.finish()
    if "convert" in stages:
        run.convert()                     # 2. the asset's maps -> neural texture
    if run.photo_path is not None:
        run.camera_stage()                # 2b. the photo's camera -> camera/camera.json (light, adapt, compose)
    if "compose" not in stages:           # convert and/or light alone
        if "light" in stages:
            run.light()
        return run.finish()
    with run.baking(bake if "bake" in stages else None, bake_skipped_why):  # 6. the texture written into the
        run.light()                       # 3. asset's own file (glTF): a process of its own, from when the
        run.adapt()                       # 4. texture is final (after 2, or after 4); adapt only with SD2
        run.compose()                     # 5. the texture in the photo under the estimated light
    return run.finish()                   # 7. report.json


def from_given(stages) -> tuple[str, ...]:
    """`stages` when they are FROM_GIVEN_STAGES, else one sentence: the rest of a run makes its own inputs."""
    if tuple(stages) != FROM_GIVEN_STAGES:
        raise InputError(f"A run from a given texture runs {', '.join(FROM_GIVEN_STAGES)} alone, not "
                         f"{', '.join(stages) or 'nothing'}.")
    return FROM_GIVEN_STAGES


def guidance_found(config: RunConfig) -> tuple[bool, str]:
    """Whether adapt (and the diffusion light critic) run, and why: the one place `--guidance` is decided."""
    if config.guidance_type == "sd2":
        locate_models(config.models, need_inpaint=True)   # missing weights: a clear error before any work
        return True, "asked for (--guidance sd2)"
    if config.guidance_type == "auto":
        return models_available(config.models)
    return False, "guidance none"


class PipelineRun:
    """One run's shared state: the checked inputs, each stage's key, the runner that reuses stages."""

    def __init__(self, mesh: Mesh | AssetMaterials | None, maps: PBRMaps | None, photo_path: str | Path | None,
                 placement, out_dir: str | Path, config: RunConfig, progress: ProgressCallback | None,
                 cancel: threading.Event | None, models: ModelCache | None, reuse_from: str | Path | None = None,
                 stages: tuple[str, ...] = STAGES, given: GivenOutputs | None = None) -> None:
        self.started = time.perf_counter()
        self.stages, self.given = stages, given
        if mesh is None and not set(stages) <= set(PHOTO_ONLY_STAGES):
            raise InputError(f"The stages {', '.join(stages)} need an asset; only {', '.join(PHOTO_ONLY_STAGES)} "
                             "runs on a photo alone.")
        self.asset = mesh   # what convert fits: a mesh with its maps, or every material of an asset
        if isinstance(mesh, AssetMaterials):
            mesh, maps = mesh.fitting_view()   # (the one mesh and maps the other stages see)
        assert mesh is None or maps is not None or given is not None
        self._mesh, self._maps, self.config, self.progress, self.cancel = mesh, maps, config, progress, cancel
        self.out = Path(out_dir).resolve()   # stage.json lists absolute outputs, whatever the working folder
        # Everything that can be wrong with the inputs is found before any work.
        # (adapt from a given texture reads the photo a scene-mode run gives; without one it sees local views)
        reads_photo = any(stage in stages for stage in PHOTO_STAGES) or \
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
        # (each set once the stage that writes it ran, or from `given`)
        self.texture_path: Path | None = None
        self.light_path: Path | None = None
        self.camera_path: Path | None = None
        self.camera: tuple[PhotoCamera, dict] | None = None   # the photo's camera, once estimated
        self.keys: dict[str, str] = {}
        if given is not None:   # what the given files hold stands for the stages that made them
            self.texture_path, self.light_path = given.texture, given.light
            self.keys["convert"] = self.upstream = _digest("given texture", _file_bytes(given.texture))
            self.given_light_key = _digest("given light", _file_bytes(given.light))
        self.texture_final: Callable[[], None] = lambda: None   # what waits for the final texture (the bake)

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

    def read_photo(self, placement) -> None:
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

    def camera_stage(self) -> None:
        """The photo's camera, written as camera/camera.json: keyed by the photo and what was given about its
        camera, and never making the stages after it run by itself (the keys of light, adapt (through light's)
        and compose hold its key)."""
        given = self.config.photo_camera
        camera_key = asdict(given) if given else ["estimated", _digest(Path(self.config.fspy).read_bytes())
                                                  if self.config.fspy else None, self.config.camera_overrides,
                                                  self.config.camera_source, self.config.camera_why]
        self.keys[CAMERA_STAGE] = _digest(CAMERA_STAGE, camera_key, self.photo_key)

        def begin(folder: Path) -> Callable[[], dict]:
            report = write_camera(*self.photo_camera(), folder)
            return lambda: report

        self.runner.start(CAMERA_STAGE, self.keys[CAMERA_STAGE], begin, later_stages_follow=False)()
        self.camera_path = self.out / CAMERA_STAGE / CAMERA_FILE

    def stage_camera(self, width: int, height: int) -> tuple[PhotoCamera, dict]:
        """The camera stage's camera at an image of `width` x `height`, and its estimate's record."""
        assert self.camera_path is not None   # (camera_stage ran)
        return read_camera(self.camera_path, width, height)

    def convert(self) -> None:
        # Only what the scene needs: no more texels than the composite shows of the asset (the photo's
        # stored height, not the light stage's working copy, is what the composite is made at).
        screen_px = None if self.photo_path is None else max(1, round(self.config.size * self.photo_info["size"][1]))
        config = stage_configs.convert_config(self.config, screen_px)
        per_material = isinstance(self.asset, AssetMaterials)
        self.keys["convert"] = _digest("convert", asdict(config), self.asset_key,
                                       *(["per material"] if per_material else []))

        asset = self.asset
        assert asset is not None   # (the constructor refused convert without an asset)

        def convert(folder: Path) -> dict:
            return convert_and_bake(asset, None if per_material else self.maps, folder / "maps", config,
                                    progress=self.progress, cancel=self.cancel)[1]

        self.runner.run("convert", self.keys["convert"], convert)
        self.texture_path = self.out / "convert" / "maps" / WEIGHTS_FILE
        self.upstream = self.keys["convert"]

    def light_config(self):
        """The light stage's config (core/pipeline/stage_configs.light_config), with what this run decides: the
        critic (the run's guidance; light alone as `scenefit light`), and, for a run that converts the asset,
        the map as sharp as its glossiest reflections, capped by the preset. Returns the config, the critic's
        decision and the height's (None: the preset's)."""
        guidance = (self.found, self.where) if "compose" in self.stages else None
        critic = stage_configs.light_critic(self.config, guidance)
        height = None
        if "convert" in self.stages:
            # (the coverage mask only picks which roughness texels count: 1024² is plenty, never the
            # texture's long side squared, which for a 16384x16 map is 16384²)
            raster = rasterize_uv(self.normalized, min(max(self.maps.resolution), 1024))
            height = envmap_height_for(self.maps, raster.mask)
            preset_height = stage_config("light", self.config.preset).map_height
            if height.choice > preset_height:
                height = replace(height, choice=preset_height, reason=f"{height.reason}; capped at the "
                                 f"{self.config.preset} preset's {preset_height} rows")
        without_diffusion = "compose" in self.stages and self.config.guidance_type == "none"
        config = stage_configs.light_config(self.config, critic.choice, None if height is None else height.choice,
                                            without_diffusion=without_diffusion)
        return config, critic, height

    def light(self) -> None:
        config, critic, envmap_height = self.light_config()
        # The diffusion critic scores renders of the asset itself (as converted), not a stand-in sphere.
        critic_sees_asset = config.critic_type == "diffusion" and "convert" in self.keys
        self.keys["light"] = _digest("light", asdict(config), self.photo_key, self.placement_px,
                                     self.keys[CAMERA_STAGE],
                                     self.keys["convert"] if critic_sees_asset else None,
                                     *([self.config.sun_shadow] if self.config.sun_shadow else []))

        def light(folder: Path) -> dict:
            camera, estimate = self.stage_camera(self.photo.shape[1], self.photo.shape[0])
            # (the shadow's points need the camera)
            with_sun = stage_configs.with_shadow_sun(config, self.config, camera, tuple(self.photo_info["size"]),
                                                     (self.photo.shape[0], self.photo.shape[1]))
            asset = {}
            if critic_sees_asset:
                assert self.texture_path is not None   # (convert ran)
                texture = load_neural_texture(self.texture_path)
                stack = texture_view(texture, self.normalized).stack(texture)   # convert's: the own UVs
                asset = {"mesh": self.mesh, "maps": torch.as_tensor(stack)}
            inputs = LightInputs(self.photo, self.photo_info, self.placement_px, camera, estimate)
            result = run_light(inputs, with_sun, self.progress, self.cancel,
                               models=_WithInpaint(self.cache) if self.found else self.cache, asset=asset)
            if envmap_height is not None:
                result.decisions["envmap_height"] = needs_report(envmap_height)
            result.decisions.setdefault("critic", {})["choice"] = {"chosen": critic.choice, "why": critic.reason}
            if self.config.sun_shadow is not None:
                result.decisions["sun"]["from"] = "the shadow's foot, top and tip given (" + \
                    ", ".join(self.config.sun_shadow) + ")"
            return write_light(result, folder)

        self.runner.run("light", self.keys["light"], light)
        self.light_path = self.out / "light" / "light.exr"

    def photo_camera(self) -> tuple[PhotoCamera, dict]:
        """The photo's camera (at the light stage's working size) and where it came from: the camera stage's
        once it is written (or reused), else the caller's, else the estimate (fSpy, EXIF, the photo's lines, or
        the defaults, each field saying which) with the user's values over it. Estimated once a run."""
        if self.camera is None:
            h, w = self.photo.shape[:2]
            if self.camera_path is not None and self.camera_path.is_file():
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
        before): a shadow point in the sky, an asset that cannot stand where it was put (a ground plane
        reaching behind the camera) at compose's turn or at adapt's. The light stage, adapt and compose
        found them after convert (and light) had run; they find the same, with the same camera."""
        if self.photo_path is None:   # (convert alone)
            return
        h, w = self.photo.shape[:2]
        camera = self.photo_camera()[0]   # (the camera stage's, once it ran: estimated once a run)
        if self.config.sun_shadow is not None:
            sun_from_shadow_points(self.config.sun_shadow, camera, tuple(self.photo_info["size"]), (h, w))
        if "compose" in self.stages:
            place_asset(self.normalized, camera, self.placement_px, self.compose_config().size, self.config.turn_deg)
        if self.found and "adapt" in self.stages:   # adapt's global views place it at each of its azimuths' turns
            size = self.adapt_placement().size
            for turn in placement_turns(view_azimuths(self.adapt_config().views)):
                place_asset(self.normalized, camera, self.placement_px, size, turn)

    def adapt_config(self):
        """Adapt's config: of the photo when the run reads one; its local views lit by the given light map."""
        has_envmap = self.given is not None and self.given.light is not None
        return stage_configs.adapt_config(self.config, self.mesh.name, has_photo=self.photo_path is not None,
                                          has_envmap=has_envmap)

    def adapt_placement(self):
        """Where adapt's global views place the asset: compose's point, at most the photo's height."""
        h, w = self.photo.shape[:2]
        return Placement((self.placement_px[0] / w, self.placement_px[1] / h), min(1.0, self.config.size))

    def compose_config(self):
        return stage_configs.compose_config(self.config)

    def adapt(self) -> None:
        if "adapt" not in self.stages:
            self.runner.skip("adapt", NOT_LISTED, "the run's stages do not list adapt")
            return
        if not self.found:
            self.runner.skip("adapt", "skipped", f"no weights: Stable Diffusion 2's weights are not on this machine, "
                             f"so the converted texture is composed as it is ({self.where})"
                             if self.config.guidance_type == "auto" else self.where)
            return
        config = self.adapt_config()
        if self.given is not None:   # the given map stands for the light stage, whose key holds the camera's
            self.keys["light"] = _digest(self.given_light_key, self.keys.get(CAMERA_STAGE))
        # The global views are the compose stage's composite: same point, size and camera as compose below.
        placement = self.adapt_placement() if self.photo_path is not None else None
        self.keys["adapt"] = _digest("adapt", config.to_dict(), self.keys["convert"],
                                     self.photo_key if placement is not None else None,
                                     asdict(placement) if placement is not None else None, self.keys.get("light"))
        texture_path, light_path = self.texture_path, self.light_path
        # (the light stage shares the loaded models when it ran beside; alone, adapt loads what its views need)
        need_inpaint = self.given is None or config.views_type == "local+global"

        def adapt(folder: Path) -> dict:
            camera = None if placement is None else self.stage_camera(self.photo.shape[1], self.photo.shape[0])[0]
            envmap = load_environment(light_path) if config.light_type == "envmap" and light_path else None
            return adapt_and_bake(self.mesh, load_neural_texture(texture_path) if texture_path else None, config,
                                  folder, photo=self.photo if placement is not None else None,
                                  placement=placement, envmap=envmap, photo_camera=camera, progress=self.progress,
                                  cancel=self.cancel, models=self.cache.get(config.models, need_inpaint))[1]

        self.runner.run("adapt", self.keys["adapt"], adapt)
        self.texture_path, self.upstream = self.out / "adapt" / "maps" / WEIGHTS_FILE, self.keys["adapt"]
        self.texture_final()

    def compose(self) -> None:
        config = self.compose_config()
        self.keys["compose"] = _digest("compose", asdict(config), self.upstream, self.keys["light"], self.photo_key,
                                       self.placement_px, self.config.turn_deg, self.keys[CAMERA_STAGE])
        texture_path, light_path, photo_path = self.texture_path, self.light_path, self.photo_path
        assert texture_path is not None and light_path is not None and photo_path is not None   # (compose is last)

        def compose(folder: Path) -> dict:
            texture = load_neural_texture(texture_path)
            view = texture_view(texture, self.mesh)   # adaptation's new UV layout, when it made one
            full, _ = load_photo(photo_path, max_side=config.max_side)   # at the photo's size, up to max_side
            fh, fw = full.shape[:2]
            camera, camera_from = self.stage_camera(fw, fh)[0], "the camera stage (camera/camera.json)"
            inputs = ComposeInputs(view.mesh, view.stack(texture), full, self.placement.pixel((fh, fw)),
                                   load_environment(light_path), camera, turn_deg=self.config.turn_deg)
            extra = {"inputs": {"texture": str(texture_path), "light": str(light_path), "camera_from": camera_from,
                                "uv_layout": view.report["uv_layout"]}}
            return compose_to_folder(inputs, config, folder, extra, progress=self.progress, cancel=self.cancel)

        self.runner.run("compose", self.keys["compose"], compose)

    @contextmanager
    def baking(self, bake: GameBake | None, skipped_why: str):
        """The game bake around the stages after convert: started once the texture is final (at once
        without adaptation, else when adapt calls texture_final), waited for after the block, and
        stopped if the block fails (a cancel, a refusal), so no bake outlives its run."""
        if bake is None:
            self.runner.skip("bake", "skipped" if "bake" in self.stages else NOT_LISTED, skipped_why)
            yield
            return
        started: list = []   # the bake's process, once begun
        finishes: list = []  # the runner's wait for it

        def start() -> None:
            if finishes:
                return
            texture = self.texture_path
            assert texture is not None   # (started once the texture is final)

            def begin(folder: Path) -> Callable[[], dict]:
                started.append(bake(texture, folder, self.cancel))
                return started[0].wait

            finishes.append(self.runner.start("bake", _digest("bake", self.upstream, self.asset_key), begin,
                                              later_stages_follow=False))

        self.texture_final = start
        try:
            if not self.found:
                start()
            yield
            start()
        except BaseException:
            for process in started:
                process.stop()
            raise
        finally:
            self.texture_final = lambda: None
        finishes[0]()

    def finish(self) -> RunResult:
        recorded = self.runner.stages
        inputs: dict = {"asset": None if self._mesh is None else self._mesh.name, "asset_digest": self.asset_key}
        if self.photo_path is not None:
            inputs.update(photo=self.photo_info, photo_digest=self.photo_key, placement_px=list(self.placement_px))
        result = RunResult(
            folder=self.out, config=_plain(replace(self.config, models=self.config.models)), inputs=inputs,
            stages={name: StageRecord.from_runner(name, recorded[name]) for name in STAGES if name in recorded},
            camera=StageRecord.from_runner(CAMERA_STAGE, recorded[CAMERA_STAGE]) if CAMERA_STAGE in recorded else None,
            seconds=round(time.perf_counter() - self.started, 3), environment=environment_info())
        write_report(self.out / "report.json", result.to_report())   # paths relative to the run's folder
        return result


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


def _plain(config: RunConfig) -> dict:
    return json.loads(json.dumps(asdict(config), default=str))
