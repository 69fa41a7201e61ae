"""scenefit adapt: restyle a converted texture with diffusion guidance (or texture/edit from a prompt)."""
from __future__ import annotations

from ..core.base.names import MODES

from dataclasses import replace
from pathlib import Path

from .options import (add_asset_args, add_dry_run_arg, add_elevation_arg, add_model_args, add_output_args,
                      add_placement_args, add_preset_args, add_prompt_service_args, environment, load_asset,
                      model_config, output, placement, positive_int, print_config, progress, require,
                      scene_conditional_prompt)

# What --dry-run shows when the prompt would be given or written at run time.
PROMPT_PLACEHOLDER = "<the prompt: --prompt, or written from --object-prompt and --scene-prompt at run time>"


def resolve_config(args, prompt: str, instruction: str):
    """The AdaptConfig the arguments ask for: the preset for the mode, then the options given."""
    from ..core.stages.adapt import StageSpec
    from ..core.pipeline.presets import stage_config

    overrides = {k: v for k, v in (("iterations", args.iterations), ("seed", args.seed), ("elevation", args.elevation),
                                   ("views_per_step", args.views_per_step), ("global_crops", args.global_crops),
                                   ("model_resolution", args.model_resolution)) if v is not None}
    if args.mode == "scene" and not args.photo and not args.dry_run:
        overrides["views_type"] = "local"   # no photo: no global views (a dry run shows the scene setup)
    if args.envmap:
        overrides["light_type"] = "envmap"
    config = stage_config("adapt", args.preset, mode_type=args.mode, prompt=prompt,
                          object_prompt=args.object_prompt or "", instruction=instruction,
                          models=model_config(args), **overrides)
    if args.render_size:
        config = replace(config, stages=tuple(StageSpec(s.fraction, min(s.render_size, args.render_size), s.spp,
                                                        s.t_range) for s in config.stages))
    return config


def run(args) -> int:
    if args.dry_run:   # nothing is asked of the prompt service, loaded or written
        prompt = args.prompt or ("" if args.mode == "edit" else PROMPT_PLACEHOLDER)
        instruction = args.instruction or (PROMPT_PLACEHOLDER if args.mode == "edit" else "")
        config = resolve_config(args, prompt, instruction)
        return print_config({"stage": "adapt", "preset": args.preset, "schedule": config.schedule(),
                             "config": config.to_dict()})
    require(args, "asset", "--out")
    # Checkpoints live in the run's folder while it is written, so an interrupted run resumes.
    with output(args, resume=True) as out:
        return _adapt(args, out)


def _adapt(args, out: Path) -> int:
    import numpy as np

    from ..core.stages.adapt import adapt_and_bake
    from ..core.data.imageio import linear_to_srgb, read_color_image
    from ..core.base.report import write_report
    from ..core.render.backend import environment_info
    from ..core.texture.bake import load_neural_texture

    prompt, instruction, written = scene_conditional_prompt(args, args.mode)
    config = resolve_config(args, prompt, instruction)
    mesh, _ = load_asset(args.asset, args.object)
    texture = load_neural_texture(args.texture) if args.texture else None
    photo = where = None
    if args.photo:
        photo = linear_to_srgb(np.clip(read_color_image(args.photo, upright=True), 0.0, 1.0))
        where = placement(args, (photo.shape[0], photo.shape[1]))
    env = environment(args)[0] if args.envmap else None
    camera = None
    if photo is not None and args.envmap:  # the camera of the run this map was estimated in
        from ..core.pipeline.layout import camera_of, run_folder_of

        run_folder = run_folder_of(args.envmap)
        camera = None if run_folder is None else camera_of(run_folder, photo.shape[1], photo.shape[0])[0]
    result, report = adapt_and_bake(mesh, texture, config, out, photo=photo, placement=where,
                                    envmap=env, photo_camera=camera, progress=progress(args))
    if not report["outputs"]:   # another rank of a distributed run writes the outputs
        return 0
    report["environment"] = environment_info()
    if written is not None:
        report["prompt_writing"] = written.to_report()
    write_report(out / "report.json", report)
    print(f"adapted '{mesh.name}' ({args.mode}, {result.iterations} iterations, {result.seconds:.1f} s) -> {args.out}/maps")
    if report["uv_layout"]["uv_layout"] != "own":   # the texture reads per surface in a new layout
        print(f"  {report['uv_layout']['why']}; compose and `scenefit bake` read it there (bake: a new UV map)")
    return 0


def add_parser(sub) -> None:
    from ..core.scene.placement import DEFAULT_OBJECT_SIZE

    p = sub.add_parser("adapt", help="restyle a converted texture with diffusion guidance (or texture/edit from a "
                                     "prompt); several GPUs: torchrun --nproc_per_node N -m scenefit.cli adapt ...")
    add_asset_args(p, optional=True)
    add_output_args(p, help="output folder: maps/, checkpoint/, report.json (an interrupted run resumes when rerun)",
                    required=False)
    p.add_argument("--mode", choices=MODES, default="scene")
    p.add_argument("--texture", help="texture.pt from `scenefit convert` (required unless --mode generate)")
    p.add_argument("--prompt", help="appearance description, e.g. 'a leather sofa, soggy and stained with mud'")
    p.add_argument("--object-prompt", help="the object, e.g. 'a leather sofa' (edit mode, and for writing the prompt)")
    p.add_argument("--scene-prompt", help="the scene, e.g. 'a swamp': without --prompt, a language model writes the "
                                          "prompt from the object and scene (edit mode: the instruction)")
    p.add_argument("--instruction", help="edit mode: e.g. 'add dust to the sofa'")
    p.add_argument("--photo", help="scene mode: the photo the object goes into")
    add_placement_args(p, object_size=DEFAULT_OBJECT_SIZE)
    p.add_argument("--envmap", help="light the object with this HDR map while adapting (e.g. the estimated one)")
    add_preset_args(p)
    p.add_argument("--iterations", type=positive_int)
    add_elevation_arg(p)
    p.add_argument("--seed", type=int)
    p.add_argument("--views-per-step", type=positive_int, help="views averaged per step (paper: 4, one per GPU)")
    p.add_argument("--global-crops", type=positive_int, help="global-view crops scored per view (default 2)")
    p.add_argument("--model-resolution", type=positive_int, help="image size the diffusion models see (default: the model's own, from its config: 512 for SD2-base)")
    p.add_argument("--render-size", type=positive_int, help="cap on every stage's render size (pixels)")
    add_model_args(p)
    add_prompt_service_args(p, prefix="prompt-")
    add_dry_run_arg(p)
    p.set_defaults(func=run)
