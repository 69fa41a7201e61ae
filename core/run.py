"""The whole pipeline for one asset and one photo: convert -> light -> adapt -> compose -> bake.

    report = run_pipeline(mesh, maps, photo_path, placement, out_dir, RunConfig(...), progress, cancel)

Each stage writes into its own folder under out_dir and, last, a `stage.json` holding its key: a
digest of its settings, of the inputs it reads and of the keys of the stages it depends on. A later
run whose key for a stage matches a finished stage.json (and whose listed outputs still exist)
reuses that stage and says so; anything else runs it again, and with it every stage after it.
Stages hand data to each other only through their files, so a reused stage and a fresh one look
the same downstream. Plain data in (arrays, paths, a frozen config), a report dict out: the Ray
batch runner calls this function as it is.
"""
from __future__ import annotations

import hashlib
import json
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from .atomic import write_json_atomic
from .errors import InputError
from .guidance.models import GuidanceModels, ModelCache, ModelConfig
from .maps import PBRMaps
from .mesh import Mesh
from .photo import PhotoCamera
from .placement import DEFAULT_OBJECT_SIZE
from .progress import ProgressCallback, check_cancel, emit

GUIDANCE_TYPES = ("auto", "sd2", "none")
STAGES = ("convert", "light", "adapt", "compose", "bake")
STAGE_FILE = "stage.json"


@dataclass(frozen=True)
class RunConfig:
    preset: str = "balanced"                  # draft | balanced | final, for every stage
    prompt: str = ""                          # adapt: what the asset should become in this scene
    guidance_type: str = "auto"               # adapt (and the light critic): sd2 | none | auto (sd2 when found)
    size: float = DEFAULT_OBJECT_SIZE         # compose: fraction of the photo's height the asset spans (--object-size)
    shadow_type: str = "ratio"
    compose_spp: int | None = None
    photo_camera: PhotoCamera | None = None   # None: the light stage's default camera for the photo
    models: ModelConfig = field(default_factory=ModelConfig)
    # Settings over the preset's, per stage ("convert", "light", "adapt", "compose"), as the stage's config takes them:
    # quick looks, tests and benchmarks (e.g. {"adapt": {"iterations": 4}}). Part of each stage's key.
    stage_overrides: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.preset not in ("draft", "balanced", "final"):
            raise InputError(f"preset must be draft, balanced or final, got {self.preset!r}.")
        if self.guidance_type not in GUIDANCE_TYPES:
            raise InputError(f"guidance_type must be one of {', '.join(GUIDANCE_TYPES)}, got {self.guidance_type!r}.")
        unknown = sorted(set(self.stage_overrides) - {"convert", "light", "adapt", "compose"})
        if unknown:
            raise InputError(f"stage_overrides names unknown stage {unknown[0]!r}; it takes convert, light, adapt "
                             f"and compose.")

    def overrides(self, stage: str) -> dict:
        return dict(self.stage_overrides.get(stage, {}))


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


def asset_digest(mesh: Mesh, maps: PBRMaps) -> str:
    stack = maps.stacked()
    return _digest(mesh.positions, mesh.faces, mesh.uvs, mesh.normals if mesh.normals is not None else b"", stack)


class StageRunner:
    """Runs or reuses one stage at a time, and keeps the run's report."""

    def __init__(self, out: Path, progress: ProgressCallback | None, cancel: threading.Event | None) -> None:
        self.out, self.progress, self.cancel = out, progress, cancel
        self.stages: dict[str, dict] = {}
        self.fresh = False   # once a stage runs, every later stage runs too

    def run(self, name: str, key: str, work: Callable[[Path], dict]) -> dict:
        check_cancel(self.cancel)
        folder = self.out / name
        record = folder / STAGE_FILE
        index = STAGES.index(name)
        if not self.fresh and record.is_file():
            try:
                saved = json.loads(record.read_text())
            except json.JSONDecodeError:
                saved = {}
            report = dict(saved.get("report") or {})
            report["outputs"] = _absolute_outputs(report.get("outputs", {}), folder)
            if saved.get("key") == key and all(Path(p).exists() for p in _paths(report["outputs"])):
                emit(self.progress, "run", index + 1, len(STAGES), f"{name}: reused (same settings and inputs)")
                self.stages[name] = {"status": "reused", "key": key, "seconds": 0.0, "report": report}
                return report
        self.fresh = True
        emit(self.progress, "run", index, len(STAGES), f"{name}: running")
        t0 = time.perf_counter()
        record.unlink(missing_ok=True)  # a stage half redone is not a finished stage
        report = work(folder)
        seconds = time.perf_counter() - t0
        # Outputs are kept relative to the stage's folder: the run's folder may be moved (Blender swaps
        # it into place, a batch worker sends it home) and a later run must still find them.
        from .pipeline import relative_paths

        write_json_atomic(record, {"key": key, "report": dict(report, outputs=relative_paths(report.get("outputs", {}),
                                                                                            folder))})
        self.stages[name] = {"status": "ran", "key": key, "seconds": round(seconds, 3), "report": report}
        emit(self.progress, "run", index + 1, len(STAGES), f"{name}: done in {seconds:.1f} s")
        return report

    def skip(self, name: str, status: str, why: str) -> None:
        self.stages[name] = {"status": status, "why": why}
        emit(self.progress, "run", STAGES.index(name) + 1, len(STAGES), f"{name}: {status}")


def _absolute_outputs(outputs, folder: Path):
    """A stage.json's outputs (kept relative to the stage's folder) as paths from here."""
    if isinstance(outputs, dict):
        return {k: _absolute_outputs(v, folder) for k, v in outputs.items()}
    return str(folder / outputs) if isinstance(outputs, str) else outputs


def _paths(outputs) -> list[str]:
    if isinstance(outputs, dict):
        return [p for v in outputs.values() for p in _paths(v)]
    return [outputs] if isinstance(outputs, str) else []


# bake(texture.pt, stage folder) -> the bake's report with "outputs": the game asset written from the
# asset's own file. It needs Blender, which core/ never imports: core/bake_process.py runs it as a child.
from .bake_process import GameBake  # noqa: E402


def run_pipeline(mesh: Mesh, maps: PBRMaps, photo_path: str | Path, placement, out_dir: str | Path,
                 config: RunConfig = RunConfig(), progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None, bake: GameBake | None = None,
                 bake_skipped_why: str = "no game bake was asked for", models: ModelCache | None = None) -> dict:
    """Convert the asset, estimate the photo's light, adapt the texture (when the SD2 weights exist),
    compose the asset into the photo, and bake (when `bake` is given); returns the run's report (also
    out_dir/report.json).

    placement: (x, y) as fractions of the photo's width and height (both <= 1) or pixels, or "X,Y".
    models: the loaded diffusion models to use (a ModelCache: a batch worker keeps one for its life,
    so its jobs load them once); default a cache for this run, so light and adapt share one load.
    """
    from dataclasses import replace

    from .compose import COMPOSE_MAX_SIDE, ComposeInputs, compose_to_folder, light_camera
    from .presets import stage_config
    from .guidance.models import models_available
    from .lighting import estimate_light, light_report, load_photo, write_light_outputs
    from .mesh import normalize_to_unit_sphere
    from .pipeline import convert_and_bake, environment_info, load_environment
    from .placement import Placement
    from .texture.bake import WEIGHTS_FILE, load_neural_texture, texture_maps_for_mesh

    started = time.perf_counter()
    out = Path(out_dir).resolve()   # stage.json lists absolute outputs, whatever the working folder
    photo_path = Path(photo_path)
    # Everything that can be wrong with the inputs is found before any work.
    photo, photo_info = load_photo(photo_path)
    h, w = photo.shape[:2]
    placement = Placement.parse(placement, tuple(photo_info["size"]))   # pixels of the photo as stored
    placement_px = placement.pixel((h, w))                               # ... in the light stage's copy
    compose_config = stage_config("compose", config.preset, **{
        "size": config.size, "shadow_type": config.shadow_type, "spp": config.compose_spp, **config.overrides("compose")})
    if config.guidance_type == "sd2":
        found, where = True, "asked for (--guidance sd2)"
        from .guidance.models import locate_models

        locate_models(config.models, need_inpaint=True)
    elif config.guidance_type == "auto":
        found, where = models_available(config.models)
    else:
        found, where = False, "guidance none"
    cache = models if models is not None else ModelCache()
    asset_key = asset_digest(mesh, maps)
    photo_key = _digest(photo_path.read_bytes())
    runner = StageRunner(out, progress, cancel)

    # convert: the asset's maps -> neural texture (baked maps + texture.pt)
    # Only what the scene needs: no more texels than the composite shows of the asset (the photo's
    # stored height, not the light stage's working copy, is what the composite is made at).
    screen_px = max(1, round(config.size * photo_info["size"][1]))
    convert_config = stage_config("convert", config.preset, **{"screen_px": screen_px, **config.overrides("convert")})
    convert_key = _digest("convert", asdict(convert_config), asset_key)

    def convert(folder: Path) -> dict:
        _, report = convert_and_bake(mesh, maps, folder / "maps", convert_config, progress=progress, cancel=cancel)
        return report

    runner.run("convert", convert_key, convert)
    texture_path = out / "convert" / "maps" / WEIGHTS_FILE

    # light: photo + placement -> light.exr (+ its report, which carries the photo camera)
    # Only what the scene needs: the map is as sharp as the asset's glossiest reflections.
    from .scene_needs import envmap_height_for, report as needs_report
    from .texture.uv_raster import rasterize_uv

    normalized, _ = normalize_to_unit_sphere(mesh)
    # (the coverage mask only picks which roughness texels count: 1024² is plenty, never the
    # texture's long side squared, which for a 16384x16 map is 16384²)
    envmap_height = envmap_height_for(maps, rasterize_uv(normalized, min(max(maps.resolution), 1024)).mask)
    # The preset's map height is a cap, as its texture resolution is (a glossy asset gets 64 rows in draft).
    preset_height = stage_config("light", config.preset).map_height
    if envmap_height.choice > preset_height:
        envmap_height = replace(envmap_height, choice=preset_height,
                                reason=f"{envmap_height.reason}; capped at the {config.preset} preset's {preset_height} rows")
    light_config = stage_config("light", config.preset, **{
        "critic_type": "diffusion" if found else "none", "models": config.models, "map_height": envmap_height.choice,
        **config.overrides("light")})
    if config.guidance_type == "none":  # no diffusion model at all: the sky/ground prior completes an outdoor map
        light_config = replace(light_config, outpaint=replace(light_config.outpaint, completion_type="prior"))
    # The diffusion critic scores renders of the asset itself (as converted), not a stand-in sphere.
    critic_sees_asset = light_config.critic_type == "diffusion"
    light_key = _digest("light", asdict(light_config), photo_key, placement_px,
                        asdict(config.photo_camera) if config.photo_camera else None,
                        convert_key if critic_sees_asset else None)

    def light(folder: Path) -> dict:
        asset = {}
        if critic_sees_asset:
            stack = texture_maps_for_mesh(load_neural_texture(texture_path), normalized)
            asset = {"mesh": mesh, "maps": torch.as_tensor(stack)}
        result = estimate_light(photo, placement_px, light_config, photo_camera=config.photo_camera,
                                photo_info=photo_info, progress=progress, cancel=cancel,
                                models=_WithInpaint(cache) if found else cache, **asset)
        outputs = write_light_outputs(result, folder)
        report = light_report(result, light_config, outputs)
        report["decisions"]["envmap_height"] = needs_report(envmap_height)
        write_json_atomic(folder / "report.json", report)
        return report

    runner.run("light", light_key, light)
    light_path = out / "light" / "light.exr"

    # adapt: only with the SD2 weights
    if found:
        from .adapt import adapt_and_bake

        prompt = config.prompt or f"a {mesh.name} in this scene, photo"
        adapt_config = stage_config("adapt", config.preset, **{"mode_type": "scene", "prompt": prompt,
                                                               "models": config.models, **config.overrides("adapt")})
        # The global views are the compose stage's composite: same point, size and camera as compose below.
        guidance_placement = Placement((placement_px[0] / w, placement_px[1] / h), min(1.0, config.size))
        adapt_key = _digest("adapt", adapt_config.to_dict(), convert_key, photo_key, asdict(guidance_placement),
                            light_key)

        def adapt(folder: Path) -> dict:
            camera, _ = light_camera(light_path, photo_info, w, h)
            _, report = adapt_and_bake(mesh, load_neural_texture(texture_path), adapt_config, folder, photo=photo,
                                       placement=guidance_placement, photo_camera=camera, progress=progress,
                                       cancel=cancel, models=cache.get(adapt_config.models, True))
            return report

        runner.run("adapt", adapt_key, adapt)
        texture_path, upstream = out / "adapt" / "maps" / WEIGHTS_FILE, adapt_key
    else:
        runner.skip("adapt", "skipped", f"Stable Diffusion 2 weights are not on this machine, so the converted "
                    f"texture is composed as it is ({where})" if config.guidance_type == "auto" else where)
        upstream = convert_key

    # compose: the (adapted) texture in the photo under the estimated light
    compose_key = _digest("compose", asdict(compose_config), upstream, light_key, photo_key, placement_px)

    def compose(folder: Path) -> dict:
        stack = texture_maps_for_mesh(load_neural_texture(texture_path), normalized)
        full, _ = load_photo(photo_path, max_side=COMPOSE_MAX_SIDE)   # the composite is at the photo's size
        fh, fw = full.shape[:2]
        camera, camera_from = light_camera(light_path, photo_info, fw, fh)
        return compose_to_folder(ComposeInputs(mesh, stack, full, placement.pixel((fh, fw)),
                                               load_environment(light_path), camera),
                                 compose_config, folder, {"inputs": {"texture": str(texture_path), "light": str(light_path),
                                                                     "camera_from": camera_from}},
                                 progress=progress, cancel=cancel)

    runner.run("compose", compose_key, compose)

    # bake: the (adapted) texture written into the asset's own file as a game asset (glTF)
    if bake is None:
        runner.skip("bake", "skipped", bake_skipped_why)
    else:
        bake_texture = texture_path
        runner.run("bake", _digest("bake", upstream, asset_key), lambda folder: bake(bake_texture, folder))

    report = {
        "stage": "run",
        "config": _plain(replace(config, models=config.models)),
        "inputs": {"asset": mesh.name, "asset_digest": asset_key, "photo": photo_info, "photo_digest": photo_key,
                   "placement_px": list(placement_px)},
        "stages": runner.stages,
        "composite": str(out / "compose" / "composite.png"),
        "reused": [name for name, s in runner.stages.items() if s["status"] == "reused"],
        "environment": environment_info(),
        "seconds_total": round(time.perf_counter() - started, 3),
    }
    from .pipeline import write_report

    write_report(out / "report.json", report)   # paths relative to the run's folder, which is swapped into place
    return report


class _WithInpaint:
    """The cache as the light stage sees it when adapt follows: it asks for the inpainting UNet too,
    so light and adapt share one loaded model set."""

    def __init__(self, cache: ModelCache) -> None:
        self.cache = cache

    def get(self, config: ModelConfig, need_inpaint: bool) -> GuidanceModels:
        return self.cache.get(config, True)


def _plain(config: RunConfig) -> dict:
    return json.loads(json.dumps(asdict(config), default=str))
