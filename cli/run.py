"""scenefit run: the whole pipeline (convert -> light -> adapt -> compose -> bake) for one asset and photo."""
from __future__ import annotations

from ..core.base.names import GUIDANCE_TYPES

from pathlib import Path

from .options import (add_asset_args, add_model_args, add_output_args, add_photo_camera_args, add_placement_args,
                      add_preset_args, add_scene_arg, add_sun_args,
                      add_prompt_service_args, load_asset, model_config, output, progress,
                      scene_conditional_prompt)


def run_config(args):
    """(RunConfig, prompt record or None): the prompt is --prompt, else written from --object-prompt
    and --scene-prompt (and the photo, for a vision model)."""
    from ..core.pipeline.run_config import RunConfig

    prompt, _, written = scene_conditional_prompt(args, "scene")
    camera = {k: v for k, v in (("fov_deg", args.fov), ("pitch_deg", args.pitch), ("roll_deg", args.roll))
              if v is not None}
    config = RunConfig(preset=args.preset, prompt=prompt, guidance_type=args.guidance,
                       size=args.object_size, shadow_type=args.shadow, compose_spp=args.spp, models=model_config(args),
                       fspy=args.fspy, camera_overrides=camera, sun_deg=args.sun,
                       sun_shadow=tuple(args.sun_from_shadow) if args.sun_from_shadow else None,
                       scene_type=args.scene)
    return config, written


def game_bake(args):
    """(bake function or None, why not) for the last stage (core/stages/bake/process.py)."""
    from ..core.stages.bake.process import asset_file_bake

    if args.no_bake:
        return None, "--no-bake was given"
    return asset_file_bake(args.asset, args.object)


def read_asset(args) -> tuple:
    """(mesh, maps, key, how it was read): the run folder's copy of an earlier run's read of the same
    files (core/data/asset_read_cache.py), else the asset itself (a file through Blender)."""
    import time

    from ..core.data.asset_read_cache import load_read, read_key
    from ..core.base.output_folder import is_run_folder

    start = time.perf_counter()
    key = read_key(args.asset, args.object)
    # (only from a SceneFit run folder, whose finished stages this run reuses too; --replace starts over)
    copied = load_read(args.out, key) if not args.replace and is_run_folder(Path(args.out)) else None
    mesh, maps = copied or load_asset(args.asset, args.object)
    how = {"source": "copy" if copied else "asset", "seconds": round(time.perf_counter() - start, 3),
           "why": "the run folder's copy of an earlier read of the same files" if copied else
           "read from the asset" + ("" if key else " (only glTF and OBJ reads are kept: their referenced files are "
                                                    "all known)")}
    return mesh, maps, key, how


def run(args) -> int:
    from ..core.data.asset_read_cache import save_read
    from ..core.base.report import write_report
    from ..core.pipeline.result import skipped_lines, stage_words
    from ..core.pipeline.run import run_pipeline
    from ..core.stages.light.stage import sun_words

    config, written = run_config(args)
    mesh, maps, key, how = read_asset(args)
    bake, why_not = game_bake(args)
    # Written beside and swapped in whole, like every command's folder; an earlier run's folder is
    # taken up (its finished stages reused), never mixed with this run's files.
    with output(args, reuse=not args.replace) as staging:   # (--replace starts over)
        result = run_pipeline(mesh, maps, args.photo, args.at, staging, config, progress=progress(args),
                              bake=bake, bake_skipped_why=why_not)
        if how["source"] == "asset":
            save_read(staging, key, mesh, maps)
        report = dict(result.to_report(), asset_read=how)
        if written is not None:
            report["prompt_writing"] = written.to_report()
        write_report(staging / "report.json", report)
    summary = stage_words(result.stage_status())
    decisions = result.stages["light"].report.get("decisions") if "light" in result.stages else None
    light = f"; {sun_words(decisions, '--sun AZ,EL or --sun-from-shadow')}" if decisions else ""
    print(f"run done in {result.seconds:.1f} s ({summary}{light}) -> "
          f"{Path(args.out) / 'compose' / 'composite.png'}")
    for line in skipped_lines(result.stage_status()):
        print(line)
    return 0


def add_parser(sub) -> None:
    from ..core.stages.compose import SHADOW_TYPES
    from ..core.scene.placement import DEFAULT_OBJECT_SIZE

    p = sub.add_parser("run", help="convert, light, adapt, compose and bake in one go (resumable)")
    add_asset_args(p)
    p.add_argument("--photo", required=True, help="the scene photo")
    add_placement_args(p, required=True, object_size=DEFAULT_OBJECT_SIZE)
    add_output_args(p, help="output folder; a second run into it reuses the stages whose settings and inputs are "
                            "the same (--replace is not needed for that)")
    p.add_argument("--prompt", help="what the asset should become in this scene (adapt; default from its name)")
    p.add_argument("--object-prompt", help="the object, e.g. 'a leather sofa': without --prompt, a language model "
                                           "writes the prompt from it and --scene-prompt (or the photo)")
    p.add_argument("--scene-prompt", help="the scene, e.g. 'a swamp'")
    add_preset_args(p)
    p.add_argument("--guidance", choices=GUIDANCE_TYPES, default="auto",
                   help="adapt with Stable Diffusion 2 (sd2), not at all (none), or when its weights are here (auto)")
    p.add_argument("--shadow", choices=SHADOW_TYPES, default="ratio")
    p.add_argument("--spp", type=int, help="compose: samples per pixel (default: from the preset's noise target)")
    p.add_argument("--no-bake", action="store_true", help="skip the game bake (a .glb of the asset with its new texture)")
    add_scene_arg(p, default="auto")
    add_photo_camera_args(p)
    add_sun_args(p)
    add_model_args(p)
    add_prompt_service_args(p, prefix="prompt-")
    p.set_defaults(func=run, by_stage=True)  # an interrupt keeps the finished stages (see the message)
