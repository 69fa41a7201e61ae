"""The layers (docs/architecture.md), read from the source: every import, at module or function level."""
from __future__ import annotations

import ast
from pathlib import Path

from scenefit.core.base.source_graph import PACKAGES, ROOT, module_imports as imports, project_modules as modules
from scenefit.core.pipeline.registry import REGISTRY

# What core/ may never import, at any level: Blender, what talks to Blender, and the layers above it.
ABOVE_CORE = ("bpy", "bmesh", "mathutils", "addon_utils", "blender_io", "operators", "panels", "cli", "workers")


def test_core_never_imports_blender_or_the_layers_above_it():
    known = modules()
    bad = sorted((name, target) for name, path in known.items() if name.startswith("core")
                 for target in imports(name, path, known) if target.split(".")[0] in ABOVE_CORE)
    assert bad == []


# core/'s layers, bottom up (docs/architecture.md): a module imports its own layer and those below it.
LAYERS = ("core.base", "core.data", "core.scene", "core.render", "core.texture", "core.guidance", "core.stages",
          "core.pipeline")


def layer_of(name: str) -> int | None:
    return next((i for i, layer in enumerate(LAYERS) if name == layer or name.startswith(layer + ".")), None)


def upward_imports(root: Path = ROOT) -> list[tuple[str, str]]:
    known = modules(root)
    return sorted((name, target) for name, path in known.items() if layer_of(name) is not None
                  for target in imports(name, path, known)
                  if target in known and (layer_of(target) or -1) > layer_of(name))


def test_each_layer_of_core_imports_only_the_layers_below_it():
    """No foundation reaches a stage, no stage reads the presets (a config holds resolved values)."""
    assert upward_imports() == []
    assert [name for name in modules() if name.startswith("core.") and layer_of(name) is None] == []


def test_the_layer_check_sees_an_upward_import(tmp_path):
    for name, text in {"core/__init__.py": "", "core/base/__init__.py": "", "core/stages/__init__.py": "",
                       "core/base/errors.py": "def f():\n    from ..stages.light import x\n",
                       "core/stages/light.py": "from ..base.errors import E\n"}.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert upward_imports(tmp_path) == [("core.base.errors", "core.stages.light")]


def test_the_import_graph_finds_known_edges():
    """So the tests above and below can fail: the graph sees a module-level and a function-level import."""
    known = modules()
    assert "core.base.output_folder" in imports("workers.batch", known["workers.batch"], known)
    assert "blender_io.asset_file" in imports("workers.job_worker", known["workers.job_worker"], known)   # in a function


def test_no_import_circle_anywhere():
    """core.stages.compose <-> lighting <-> guidance was one (the photo camera now lives in core/scene/), and
    core.pipeline.presets <-> convert / adapt.config another (the tables are data in core/pipeline/preset_tables.py)."""
    known = modules()
    graph = {name: {t for t in imports(name, path, known) if t in known and not name.startswith(t + ".")}
             for name, path in known.items()}

    def reaches(start: str, goal: str) -> bool:
        seen, todo = set(), [start]
        while todo:
            node = todo.pop()
            for nxt in graph.get(node, ()):
                if nxt == goal:
                    return True
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return False

    circles = sorted(name for name in graph if reaches(name, name))
    assert circles == []


# The bound on a function in core/: longer ones are split into named steps.
MAX_FUNCTION_LINES = 80


def long_functions(path: Path, limit: int) -> list[str]:
    return [f"{path.relative_to(ROOT)}:{node.name} ({node.end_lineno - node.lineno + 1} lines)"
            for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > limit]


def test_no_function_in_core_is_over_80_lines():
    assert [f for path in sorted((ROOT / "core").rglob("*.py")) for f in long_functions(path, MAX_FUNCTION_LINES)] == []


def test_the_length_check_sees_a_long_function():
    # run_pipeline is well over ten lines, so a limit of ten must flag it.
    assert any("run_pipeline" in f for f in long_functions(ROOT / "core" / "pipeline" / "run.py", 10))


# The scene's geometry (docs/architecture.md, core/scene/): every stage and blender_io read it, and it
# reads only core's foundations, so it can never pull a stage (or Blender) in.
SCENE_MAY_IMPORT = ("core.scene.", "core.base.errors", "core.data.mesh")


def test_the_scenes_geometry_imports_no_stage():
    known = modules()
    bad = sorted((name, target) for name, path in known.items() if name.startswith("core.scene.")
                 for target in imports(name, path, known)
                 if target.split(".")[0] in PACKAGES and not target.startswith(SCENE_MAY_IMPORT))
    assert bad == []
    assert "core.scene.camera" in imports("core.scene.floor", known["core.scene.floor"], known)   # the check sees edges


# Each of these is defined once, in core/scene/ (they were spread over photo, placement, camera, render,
# lighting/panorama, compose and blender_io/placement).
SCENE_CONCEPTS = ("PhotoCamera", "PHOTO_YAW_DEG", "DEFAULT_PITCH_DEG", "DEFAULT_FOV_DEG", "CAMERA_HEIGHT",
                  "camera_origin", "pixel_ray", "horizon_row", "camera_pose", "pitch_roll_from_camera_to_world",
                  "look_frame", "rotation_z", "ENVMAP_TO_WORLD", "blender_direction_to_equirect_uv",
                  "equirect_directions", "place_on_floor", "FloorPoint", "DEFAULT_AT", "DEFAULT_OBJECT_SIZE",
                  "Placement", "place_asset", "ObjectPlacement", "camera_for_placement", "asset_in_view",
                  "composite_linear", "paper_shadow_matte")


def test_the_scenes_concepts_are_defined_once_in_core_scene():
    where = {}
    for name, path in modules().items():
        for node in ast.parse(path.read_text()).body:
            targets = [node.name] if isinstance(node, (ast.FunctionDef, ast.ClassDef)) else \
                [t.id for t in getattr(node, "targets", []) if isinstance(t, ast.Name)]
            for target in set(targets) & set(SCENE_CONCEPTS):
                where.setdefault(target, []).append(name)
    assert {concept: modules_ for concept, modules_ in where.items()
            if len(modules_) != 1 or not modules_[0].startswith("core.scene.")} == {}
    assert set(where) == set(SCENE_CONCEPTS)


# Each stage: run(inputs, config, progress, cancel) -> Result and write(result, folder) -> report (the
# game bake is a child `scenefit bake` process, core/stages/bake/process.py, and keeps that process's shape).
# The shapes are the stage registry's (core/pipeline/registry.py: Stage.shape).
STAGE_SHAPES = {s.name: (s.shape.source, s.shape.run, s.shape.write) for s in REGISTRY if s.shape is not None}


def function_args(path: Path, name: str) -> list[tuple[str, str]]:
    """(name, annotation as written) of the module-level function `name`'s parameters."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            return [(a.arg, ast.unparse(a.annotation) if a.annotation else "") for a in node.args.args]
    raise AssertionError(f"{path.name} has no function {name}")


def test_every_stage_has_one_shape_run_then_write():
    for stage, (source, run, write) in STAGE_SHAPES.items():
        run_args = function_args(ROOT / source, run)
        assert [a for a, _ in run_args[:4]] == ["inputs", "config", "progress", "cancel"], stage
        assert run_args[0][1].endswith("Inputs") and run_args[1][1].endswith("Config"), stage
        write_args = function_args(ROOT / source, write)
        assert [a for a, _ in write_args[:2]] == ["result", "folder"] and write_args[0][1].endswith("Result"), stage


def test_the_pipeline_runs_each_stage_through_its_shape():
    """Each stage's work module (core/pipeline/steps/) runs it only through these (or the entry that is both)."""
    assert set(STAGE_SHAPES) == {"convert", "light", "adapt", "compose"}
    text = (ROOT / "core" / "pipeline" / "run.py").read_text()
    for stage, names in {"convert": ("convert_and_bake",), "light": ("run_light", "write_light"),
                         "adapt": ("adapt_and_bake",), "compose": ("compose_to_folder",)}.items():
        steps = (ROOT / "core" / "pipeline" / "steps" / f"{stage}.py").read_text()
        assert all(f"{name}(" in steps for name in names), stage
    for old in ("estimate_light(", "write_light_stage(", "write_compose_outputs("):
        assert old not in text

