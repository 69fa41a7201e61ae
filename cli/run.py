"""scenefit run: the whole pipeline (convert -> light -> adapt -> compose -> bake) for one asset and photo."""
from __future__ import annotations

from pathlib import Path

from .options import (add_asset_args, add_model_args, add_output_args, add_placement_args, add_prompt_service_args,
                      load_asset, model_config, output, progress, scene_conditional_prompt)
from .run_options import add_run_options, run_table_of


def run_config(args):
    """(RunConfig, prompt record or None), read through the run table as a jobs file's job is: the prompt
    is --prompt, else written from --object-prompt and --scene-prompt (and the photo, for a vision model)."""
    from ..core.pipeline.registry import names
    from ..core.pipeline.run_table import run_config as config_of_table

    table = run_table_of(args)
    prompt, instruction, written = scene_conditional_prompt(args, table.get("mode", "scene"))
    table.update({k: v for k, v in (("prompt", prompt), ("instruction", instruction)) if v})
    return config_of_table(table, "scenefit run", names().STAGES, models=model_config(args)), written


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
    p = sub.add_parser("run", help="convert, light, adapt, compose and bake in one go (resumable)")
    add_asset_args(p)
    p.add_argument("--photo", required=True, help="the scene photo")
    add_placement_args(p, required=True)   # (--object-size is a run option)
    add_output_args(p, help="output folder; a second run into it reuses the stages whose settings and inputs are "
                            "the same (--replace is not needed for that)")
    add_run_options(p)   # (one per key of the run table, as a jobs file's job gives them)
    p.add_argument("--scene-prompt", help="the scene, e.g. 'a swamp' (with --object-prompt, a language model writes "
                                          "the prompt)")
    p.add_argument("--no-bake", action="store_true", help="skip the game bake (a .glb of the asset with its new texture)")
    add_model_args(p)
    add_prompt_service_args(p, prefix="prompt-")
    p.set_defaults(func=run, by_stage=True)  # an interrupt keeps the finished stages (see the message)
