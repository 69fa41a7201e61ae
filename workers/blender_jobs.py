"""What each Blender operator's job runs in its worker thread: plain data in, plain data (paths, numbers) out.

These functions run in a job's worker thread (or inline under `blender -b`), so they never import
bpy: the operators gather Blender data into the `data` dicts on the main thread, and write the
results back on the main thread once the job ends. Each writes only into its own run folder.
"""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Mapping

from ..core.base.progress import ProgressCallback
from .job_seam import TEXTURE_KEYS, RunInputs, RunOutcome, TextureOutcome, read_run_outcome, write_request


def written_whole(out: str, write, resume: bool = False) -> dict:
    """Run `write(folder)` into the hidden sibling of `out` and swap it in whole when it returns
    (core.output_folder: a cancelled or failed run leaves nothing, except with `resume`: a cancel keeps the
    sibling, and so does any stop with a finished stage in it (a failure, a quit), which the same `out`
    continues from, its finished stages reused); the paths it returns are moved along to `out`."""
    from ..core.base.output_folder import output_folder

    with output_folder(out, resume=resume, reuse=resume) as staging:
        result = write(staging)
    target = str(Path(out).absolute())
    return _moved(_moved(result, str(staging.resolve()), target), str(staging), target)


def _moved(value, old: str, new: str):
    if isinstance(value, dict):
        return {k: _moved(v, old, new) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_moved(v, old, new) for v in value)
    if isinstance(value, str) and (value == old or value.startswith(old + "/") or value.startswith(old + "\\")):
        return new + value[len(old):]
    return value


def convert(data: dict, progress: ProgressCallback, cancel: threading.Event) -> TextureOutcome:
    """Fit the neural texture to the asset's maps and bake base colour, roughness, metallic: the pipeline's
    convert stage alone (run_pipeline, stages ("convert",)) into data['out'], with data['config'], the
    RunConfig Convert's prepare() built (an iteration count in its overrides asks for the fit; else the
    asset's maps are the exact start). A roughness or metallic that holds one value stays that value."""
    from ..core.base.report import write_report
    from ..core.data.map_plan import resolved_asset
    from ..core.pipeline.run import run_pipeline

    if data.get("asset") is not None:
        asset = resolved_asset(data["asset"])   # the maps decoded here, off Blender's main thread
        several = len(asset.materials) > 1   # fitted as their atlas; one material: its mesh and maps
        mesh, maps = (asset, None) if several else asset.fitting_view()
    else:
        mesh, maps = data["mesh"], data["maps"]   # (a script's own mesh and maps)

    def write(folder: Path) -> dict:
        result = run_pipeline(mesh, maps, None, None, folder, data["config"], progress=progress, cancel=cancel,
                              stages=("convert",))
        report, outputs = result.to_report(), result.outputs("convert")
        per_material = material_results(data["materials"], outputs["weights"], folder / "materials") \
            if data.get("materials") else []
        if per_material:
            report["materials_in_blender"] = per_material
        write_report(folder / "report.json", report)  # paths relative to the run folder, which moves
        return {"maps": {k: outputs[k] for k in TEXTURE_KEYS}, "texture": outputs["weights"],
                "report": str(folder / "report.json"), "material_maps": per_material,
                "numbers": {"psnr_db": result.stages["convert"].report["psnr_covered_texels_db"]}}

    return texture_outcome(data["out"], written_whole(data["out"], write))


def texture_outcome(out: str, written: dict) -> TextureOutcome:
    """A Convert's or Adapt's written folder (its paths moved to `out`) as what Blender applies."""
    return TextureOutcome(folder=str(Path(out).absolute()), report=written["report"], texture=written["texture"],
                          maps=written["maps"], material_maps=tuple(written["material_maps"]),
                          numbers=written["numbers"])


def camera_source(view: dict) -> tuple[str, str]:
    """(source, why) of a view's camera values for the camera's record (core/stages/camera.py)."""
    if view["camera_source"] == "blender":
        return "blender", "; ".join(view["notes"])
    return "user", "given by the user"   # the panel's values, as the command line's --fov/--pitch/--roll


def camera_values(camera) -> dict:
    """What the Cycles set-up takes from a run's camera stage (a StageRecord): the camera light and compose used."""
    if camera is None:   # (a run that reads the photo runs the camera stage always)
        raise RuntimeError("the run returned no camera stage")
    return {k: camera.report["photo_camera"][k] for k in ("fov_deg", "pitch_deg", "roll_deg")}


def estimate_light(data: dict, progress: ProgressCallback, cancel: threading.Event) -> dict:
    """Photo + placement -> the pipeline's camera and light stages alone (run_pipeline, stages ("light",), no
    asset) into data['out']: light/light.exr in Blender's equirectangular convention, with data['config'],
    the RunConfig Estimate Light's prepare() built (view_config). A stage of data['reuse_from'] (the last
    Estimate Light of this photo) with the same settings and inputs is copied in, not redone."""
    from ..core.pipeline.run import run_pipeline
    from ..core.stages.light.scene_type import is_blended, scene_type_words
    from ..core.stages.light.stage import sun_words

    def write(folder: Path) -> dict:
        result = run_pipeline(None, None, data["photo"], tuple(data["placement"]), folder, data["config"],
                              progress=progress, cancel=cancel, reuse_from=data.get("reuse_from"), stages=("light",))
        light = result.stages["light"]
        decisions = light.report["decisions"]
        scene = decisions.get("scene_type", {})
        outputs = result.outputs("light")
        return {"hdr": outputs["hdr_exr"], "preview": outputs["preview_png"], "report": str(folder / "report.json"),
                "scene_type": scene_type_words(scene, "Scene type"), "scene_type_blended": is_blended(scene),
                "sun": sun_words(decisions, "Pick Sun or Sun from Light"), "reused": light.status == "reused",
                "camera": camera_values(result.camera)}

    return written_whole(data["out"], write)


def adapt(data: dict, progress: ProgressCallback, cancel: threading.Event) -> TextureOutcome:
    """Restyle the converted texture (or make one, mode 'generate') and bake the maps: the pipeline's adapt
    stage from the texture Convert made and the light Estimate Light made (run_pipeline, `given`), of the
    photo in scene mode, into data['out'] with data['config'], the RunConfig Adapt's prepare() built
    (view_config). A cancelled adaptation keeps its checkpoint, which the same folder resumes from."""
    from ..core.pipeline.run import GivenOutputs, run_pipeline

    given = GivenOutputs(texture=Path(data["texture"]) if data.get("texture") else None,
                         light=Path(data["envmap"]) if data.get("envmap") else None)

    def write(folder: Path) -> dict:
        result = run_pipeline(data["mesh"], None, data.get("photo") or None, tuple(data["placement"]), folder,
                              data["config"], progress=progress, cancel=cancel, stages=("adapt",), given=given)
        adapted = result.stages["adapt"]
        outputs = result.outputs("adapt")
        # several materials: each one's maps from the adapted texture, in its own UVs, for its slots
        per_material = material_results(data["materials"], outputs["weights"], folder / "materials") \
            if data.get("materials") else []
        return {"maps": {k: outputs[k] for k in TEXTURE_KEYS}, "texture": outputs["weights"],
                "report": str(folder / "report.json"), "material_maps": per_material,
                "numbers": {"iterations": adapted.report["iterations"]}}

    # a cancelled adaptation keeps its checkpoint
    return texture_outcome(data["out"], written_whole(data["out"], write, resume=True))


def view_config(view: dict, **settings):
    """A RunConfig of `settings` seeing the photo as `view` (operators/photo.photo_view) says: the artist's
    camera or the panel's values, the asset's size and turn, the artist's sun. Run All's prepare() here and
    on a worker (its job is this config's table, core/pipeline/run_table.py) build it here."""
    from ..core.pipeline.run_config import RunConfig

    source, why = camera_source(view)
    return RunConfig(size=view["size"], camera_overrides=dict(view["camera"] or {}), camera_source=source,
                     camera_why=why, turn_deg=view["turn_deg"],
                     sun_deg=tuple(view["sun_deg"]) if view.get("sun_deg") else None,
                     sun_uncertainty_deg=float(view.get("sun_uncertainty_deg", 0.0)), **settings)


def plain_config(**settings):
    """A RunConfig of `settings` that sees no photo (Convert; Adapt before a photo is chosen)."""
    from ..core.pipeline.run_config import RunConfig

    return RunConfig(**settings)


def quick_overrides(op) -> dict:
    """The operator's iterations / model_resolution / render_size (0: the preset's) as stage overrides:
    a quick look. render_size also caps the light's apparatus renders and the composite's samples."""
    overrides: dict = {}
    iterations = getattr(op, "iterations", 0)
    if iterations:
        overrides = {"convert": {"iterations": iterations}, "light": {"optimise": {"iterations": iterations}},
                     "adapt": {"iterations": iterations}}
    size = getattr(op, "model_resolution", 0)
    if size:
        overrides.setdefault("adapt", {})["model_resolution"] = size
        overrides.setdefault("light", {}).update(diffusion={"model_resolution": size},
                                                 outpaint={"resolution": size})
    render = getattr(op, "render_size", 0)
    if render:
        overrides.setdefault("adapt", {})["stages"] = [[1.0, render, 2, [500, 990]]]
        overrides.setdefault("light", {}).update(map_height=render, apparatus={"render_size": render, "spp": 2})
        overrides["compose"] = {"pilot_spp": 1, "min_spp": 1, "max_spp": 2}
    return overrides


def material_results(info: Mapping[str, Any], texture_path: str, folder: Path) -> list[dict]:
    """Each material's maps baked from the neural texture in that material's own UVs (core.game_bake, as
    Bake Asset and the command line's bake do), written into folder/<n>/: what the new material in its
    slots shows. The run's own maps are the atlas of every material (core.materials), which no slot reads.
    info: operators.asset.AssetLayout.bake_data()."""
    import numpy as np

    from ..core.stages.bake.game_bake import bake_game_maps as bake, default_texture_size
    from ..core.data.imageio import write_image
    from ..core.texture.bake import load_neural_texture

    texture = load_neural_texture(texture_path)
    size = default_texture_size(texture, len(info["names"]))
    baked = bake(texture, info["mesh"], list(info["names"]), size, [dict(c) for c in info["constants"]],
                 [tuple(w) for w in info["wraps"]])
    maps = []
    for index, material in enumerate(baked, start=1):
        where = folder / str(index)
        paths: dict[str, str | float] = {"base_color": str(write_image(where / "base_color.png", material.base_color / 255.0, "uint8"))}
        for key in ("roughness", "metallic"):
            value = getattr(material, key)
            paths[key] = str(write_image(where / f"{key}.png", value / 255.0, "uint8")) \
                if isinstance(value, np.ndarray) else float(value)
        maps.append(dict(paths, name=material.name, size=size))
    return maps


def run(inputs: RunInputs, progress: ProgressCallback, cancel: threading.Event) -> RunOutcome:
    """The command line's pipeline (core.run.run_pipeline: convert -> light -> adapt -> compose; the
    game bake is Bake Asset's, on the main thread) into the request's folder with its RunConfig; returns
    what Blender applies (job_seam.run_outcome). Written resumably: a cancelled, failed or interrupted run
    keeps its finished stages and the adaptation's checkpoint beside the folder, which the same request
    continues from (Resume)."""
    from ..core.base.report import write_report
    from ..core.data.map_plan import resolved_asset
    from ..core.pipeline.run import run_pipeline

    request = inputs.request
    mesh, maps = resolved_asset(inputs.asset).fitting_view()   # the maps decoded here, off the main thread

    def write(folder: Path) -> dict:
        write_request(folder, request)
        result = run_pipeline(mesh, maps, request.photo, request.placement, folder,
                              request.config, progress=progress, cancel=cancel,
                              bake_skipped_why="in Blender the game file is written by Bake Asset",
                              reuse_from=inputs.reuse_from)
        report = result.to_report()
        stages = report["stages"]
        if result.stages["adapt"].status == "skipped" and request.why_no_adapt:
            stages["adapt"]["why"] = report["stage_status"]["adapt"]["why"] = request.why_no_adapt
        per_material = material_results(inputs.materials, result.outputs(result.texture_stage)["weights"],
                                        folder / "materials") if inputs.materials else []
        if per_material:
            report["materials_in_blender"] = per_material
        write_report(folder / "report.json", report)  # paths relative to the run folder, which moves
        return {"material_maps": per_material}

    written = written_whole(request.out, write, resume=True)
    return read_run_outcome(request.out, tuple(written["material_maps"]))


def bake_game_maps(data: dict, progress: ProgressCallback, cancel: threading.Event) -> dict:
    """The neural texture baked per material for glTF: at data['size']² for all, or (0) each at its own
    images' shape from its own maps (data['own_maps']), within data['max_size'], as `scenefit bake` does.
    A channel whose baked map is what the artist's material already gives keeps that material's nodes
    (BakedMaterial.unchanged), also where the slot holds a SceneFit result: the file is written from the
    artist's material (operators/asset.AssetLayout.artists)."""
    from ..blender_io.uv_unwrap import NEW_UV_MAP
    from ..core.stages.bake.game_bake import bake_game_maps as bake, bake_shapes
    from ..core.base.progress import emit
    from ..core.data.map_plan import resolved_asset
    from ..core.texture.bake import load_neural_texture

    texture = load_neural_texture(data["texture"])
    own = [m.maps for m in resolved_asset(data["own_maps"]).materials]   # decoded here, off the main thread
    shapes = bake_shapes(own, data["size"], data.get("max_size", 8192))
    shown = ", ".join(sorted({f"{s}²" if isinstance(s, int) else f"{s[1]}x{s[0]}" for s in shapes}))
    emit(progress, "bake", 0, 1, f"{len(data['names'])} material(s) at {shown}")
    baked = bake(texture, data["mesh"], list(data["names"]), shapes, [dict(c) for c in data["constants"]],
                 [tuple(w) for w in data.get("wraps", ())] or None, own, data.get("remapped"),
                 data.get("remap", frozenset()), NEW_UV_MAP)
    emit(progress, "bake", 1, 1, "maps ready")
    return {"baked": baked, "size": max(max(b.base_color.shape[:2]) for b in baked)}
