"""The stage registry: one record per stage, as Mitsuba registers its integrators by name.

    stage("light").reads              # ("convert", "camera"): the stages whose keys its key holds
    names().STAGES                    # what a job lists, in the run's order
    with registered(Stage(...)): ...  # a stage added for a while (a test's throwaway stage)

Everything the run knows about a stage comes from its record: the name lists a job, the command line and
Blender speak (`names()`), its preset table and config (core/pipeline/presets.stage_config), its key (a
digest of its config, the keys of the stages it reads and the bytes of the inputs it reads, computed once
for every stage in core/pipeline/run.py), the files it writes (core/pipeline/layout.RunLayout), the time
the panel expects of it and the run/write shape its core module keeps. How it runs is its work module
(`work`, loaded by name when the stage runs, so reading the registry loads no torch): `configure(run)`
gives the stage's config for the run, `work(run, config, folder)` does it and returns its report, and
optionally `skipped(run)` says why it does not run.

Adding a stage is one module (its config, its work) and one entry in REGISTRY (docs/engineers/conventions.md
shows one).
"""
from __future__ import annotations

import importlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Callable, Iterator, Mapping

from ..base.errors import InputError
from ..stages.camera_stage import CAMERA_FILE
from .preset_tables import TABLES
from .resolve import resolve_adapt, resolve_compose, resolve_convert, resolve_light


@dataclass(frozen=True)
class StageShape:
    """Where a stage's core module keeps its run(inputs, config, progress, cancel) -> Result and its
    write(result, folder) -> report (tests/architecture/test_layout.py holds every stage to that shape)."""

    source: str
    run: str
    write: str


@dataclass(frozen=True)
class Stage:
    """One stage of the run: what it is called, configured by, reads, writes and how it runs."""

    name: str
    work: str                      # its work module: ".steps.x" is core/pipeline/steps/x.py, else a full module name
    config: Callable[[dict[str, Any], dict[str, Any]], Any] | None = None   # (its preset's values, overrides) -> config
    presets: Mapping[str, Mapping[str, Any]] | None = None  # preset name -> what it changes from the config's defaults
    reads: tuple[str, ...] = ()    # the stages whose outputs (and so keys) it reads, where the run has them
    inputs: tuple[str, ...] = ()   # the run's inputs its key holds ("asset", "photo", "placement", "turn", "sun_shadow")
    writes: Mapping[str, str] = field(default_factory=dict)   # output -> file in its folder (RunLayout)
    listed: bool = True            # a job lists it; False: it runs whenever the run reads the photo (the camera)
    needs_photo: bool = False      # it reads the photo (a run that lists it needs one)
    optional: bool = False         # the pipeline runs without it
    alone: bool = False            # it runs on its own (convert and/or light alone)
    photo_only: bool = False       # it runs on a photo without an asset
    from_given: bool = False       # it runs from outputs made before (Blender's Adapt after Convert and Light)
    later_stages_follow: bool = True   # False: its running alone makes no later stage run (their keys hold its key)
    background: bool = False       # started once the texture is final, waited for at the end (the bake's process)
    shape: StageShape | None = None
    # preset -> seconds for the bundled example in a 320x240 photo (`make bench`: benchmarks/results/trade_run.json)
    expected_seconds: Mapping[str, float | None] = field(default_factory=dict)

    @property
    def configured(self) -> bool:
        """Whether a preset resolves its config and a run's overrides reach it."""
        return self.presets is not None and self.config is not None

    def module(self) -> ModuleType:
        """The stage's work module, loaded when the stage runs (it may load torch)."""
        if self.work.startswith("."):
            return importlib.import_module(self.work, package=__package__)
        return importlib.import_module(self.work)


REGISTRY: list[Stage] = [
    Stage("convert", ".steps.convert", resolve_convert, TABLES["convert"], inputs=("asset",),
          writes={"texture": "maps/texture.pt", "base_color": "maps/base_color.png"}, alone=True,
          shape=StageShape("core/stages/convert.py", "run_convert", "write_convert"),
          expected_seconds={"draft": 0.082, "balanced": 0.112, "final": 0.24}),
    Stage("camera", ".steps.camera", inputs=("photo",), writes={"camera": CAMERA_FILE}, listed=False,
          needs_photo=True, later_stages_follow=False),
    Stage("light", ".steps.light", resolve_light, TABLES["light"], reads=("convert", "camera"),
          inputs=("photo", "placement", "sun_shadow"), writes={"light": "light.exr", "preview": "light_preview.png"}, needs_photo=True,
          alone=True, photo_only=True, shape=StageShape("core/stages/light/stage.py", "run_light", "write_light"),
          expected_seconds={"draft": 0.031, "balanced": 0.032, "final": 0.03}),
    Stage("adapt", ".steps.adapt", resolve_adapt, TABLES["adapt"], reads=("convert", "camera", "light"),
          inputs=("photo", "placement"), writes={"texture": "maps/texture.pt"}, optional=True,
          from_given=True, shape=StageShape("core/stages/adapt/stage.py", "adapt_texture", "write_adapt")),
    Stage("compose", ".steps.compose", resolve_compose, TABLES["compose"], reads=("convert", "adapt", "camera", "light"),
          inputs=("photo", "placement", "turn"), writes={"composite": "composite.png"}, needs_photo=True,
          shape=StageShape("core/stages/compose.py", "compose", "write_compose"),
          expected_seconds={"draft": 3.248, "balanced": 3.609, "final": 4.144}),
    # The game bake: a child `scenefit bake` process (core/stages/bake/process.py) begun once the texture is final.
    Stage("bake", ".steps.bake", reads=("convert", "adapt"), inputs=("asset",), optional=True, background=True),
]


@dataclass(frozen=True)
class StageNames:
    """The names a run's stages are spoken in, each list read off the registry."""

    RUN_ORDER: tuple[str, ...]          # every stage, in the order they run
    STAGES: tuple[str, ...]             # those a job lists
    CAMERA_STAGE: str                   # the one a job does not list: it runs whenever the photo is read
    CONFIG_STAGES: tuple[str, ...]      # those a preset configures and a run's overrides reach
    PHOTO_STAGES: tuple[str, ...]       # listed stages that read the photo
    ALONE_STAGES: tuple[str, ...]       # those that run on their own
    OPTIONAL_STAGES: tuple[str, ...]    # those the pipeline runs without
    PIPELINE_STAGES: tuple[str, ...]    # those the pipeline always runs
    PHOTO_ONLY_STAGES: tuple[str, ...]  # those that run on a photo without an asset
    FROM_GIVEN_STAGES: tuple[str, ...]  # those that run from outputs made before


def names() -> StageNames:
    """The stage names as the registry has them now (a stage registered for a while included)."""
    listed = [s for s in REGISTRY if s.listed]
    return StageNames(
        RUN_ORDER=tuple(s.name for s in REGISTRY), STAGES=tuple(s.name for s in listed),
        CAMERA_STAGE=next(s.name for s in REGISTRY if not s.listed),
        CONFIG_STAGES=tuple(s.name for s in REGISTRY if s.configured),
        PHOTO_STAGES=tuple(s.name for s in listed if s.needs_photo),
        ALONE_STAGES=tuple(s.name for s in listed if s.alone),
        OPTIONAL_STAGES=tuple(s.name for s in listed if s.optional),
        PIPELINE_STAGES=tuple(s.name for s in listed if not s.optional),
        PHOTO_ONLY_STAGES=tuple(s.name for s in listed if s.photo_only),
        FROM_GIVEN_STAGES=tuple(s.name for s in listed if s.from_given))


def stage(name: str) -> Stage:
    """The record of stage `name`; an unknown name is one sentence."""
    for record in REGISTRY:
        if record.name == name:
            return record
    raise InputError(f"unknown stage '{name}'; the stages are {', '.join(s.name for s in REGISTRY)}.")


def expected_seconds() -> dict[str, dict[str, float | None]]:
    """stage -> preset -> seconds the bench measured (the stages it measured)."""
    return {s.name: dict(s.expected_seconds) for s in REGISTRY if s.expected_seconds}


@contextmanager
def registered(record: Stage, after: str | None = None) -> Iterator[Stage]:
    """`record` in the registry for the block (after stage `after`, else last): a plug-in's or a test's stage."""
    if any(s.name == record.name for s in REGISTRY):
        raise InputError(f"A stage named '{record.name}' is registered already.")
    index = len(REGISTRY) if after is None else REGISTRY.index(stage(after)) + 1
    REGISTRY.insert(index, record)
    try:
        yield record
    finally:
        REGISTRY.remove(record)


# The built-in stages' names, for the modules that speak them (a stage registered later is in names()).
BUILT_IN = names()
RUN_ORDER, STAGES, CAMERA_STAGE, PHOTO_STAGES = BUILT_IN.RUN_ORDER, BUILT_IN.STAGES, BUILT_IN.CAMERA_STAGE, \
    BUILT_IN.PHOTO_STAGES
