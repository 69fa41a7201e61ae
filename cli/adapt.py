"""scenefit adapt: restyle a converted texture with diffusion guidance (or texture/edit from a prompt)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .options import (PRESETS, add_asset_args, add_model_args, add_output_args, add_prompt_service_args, environment,
                      finite_float, load_asset, model_config, output, placement_fractions, positive_float, positive_int,
                      progress, scene_conditional_prompt)


def run(args) -> int:
    # Checkpoints live in the run's folder while it is written, so an interrupted run resumes.
    with output(args, resume=True) as out:
        return _adapt(args, out)


def _adapt(args, out: Path) -> int:
    import numpy as np

    from ..core.adapt import StageSpec, adapt_and_bake, adapt_preset
    from ..core.guidance import Placement
    from ..core.imageio import linear_to_srgb, read_color_image
    from ..core.pipeline import environment_info, write_report
    from ..core.texture.bake import load_neural_texture

    mesh, _ = load_asset(args.asset, args.object)
    overrides = {k: v for k, v in (("iterations", args.iterations), ("seed", args.seed),
                                   ("elevation", args.elevation)) if v is not None}
    mode = args.mode
    prompt, instruction, written = scene_conditional_prompt(args, mode)
    config = adapt_preset(args.preset, mode, prompt=prompt, object_prompt=args.object_prompt or "",
                          instruction=instruction, models=model_config(args),
                          **({"views_type": "local"} if mode == "scene" and not args.photo else {}),
                          **({"light_type": "envmap"} if args.envmap else {}), **overrides)
    if args.model_resolution or args.render_size:
        stages = tuple(StageSpec(st.fraction, min(st.render_size, args.render_size or st.render_size), st.spp, st.t_range)
                       for st in config.stages)
        config = replace(config, stages=stages, model_resolution=args.model_resolution or config.model_resolution)
    texture = load_neural_texture(args.texture) if args.texture else None
    photo = placement = None
    if args.photo:
        photo = linear_to_srgb(np.clip(read_color_image(args.photo), 0.0, 1.0))
        placement = Placement(args.at, args.size)
    env = environment(args)[0] if args.envmap else None
    result, report = adapt_and_bake(mesh, texture, config, out, photo=photo, placement=placement,
                                    envmap=env, progress=progress(args))
    report["environment"] = environment_info()
    if written is not None:
        report["prompt_writing"] = written.to_report()
    write_report(out / "report.json", report)
    print(f"adapted '{mesh.name}' ({mode}, {result.iterations} iterations, {result.seconds:.1f} s) -> {args.out}/maps")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("adapt", help="restyle a converted texture with diffusion guidance (or texture/edit from a prompt)")
    add_asset_args(p)
    add_output_args(p, help="output folder: maps/, checkpoint/, report.json (an interrupted run resumes when rerun)")
    p.add_argument("--mode", choices=("scene", "generate", "edit"), default="scene")
    p.add_argument("--texture", help="texture.pt from `scenefit convert` (required unless --mode generate)")
    p.add_argument("--prompt", help="appearance description, e.g. 'a leather sofa, soggy and stained with mud'")
    p.add_argument("--object-prompt", help="the object, e.g. 'a leather sofa' (edit mode, and for writing the prompt)")
    p.add_argument("--scene-prompt", help="the scene, e.g. 'a swamp': without --prompt, a language model writes the "
                                          "prompt from the object and scene (edit mode: the instruction)")
    p.add_argument("--instruction", help="edit mode: e.g. 'add dust to the sofa'")
    p.add_argument("--photo", help="scene mode: the photo the object goes into")
    p.add_argument("--at", default=(0.5, 0.6), type=placement_fractions, help="X,Y centre of the object in the photo, fractions (default 0.5,0.6)")
    p.add_argument("--size", type=positive_float, default=0.4, help="object size as a fraction of the photo height")
    p.add_argument("--envmap", help="light the object with this HDR map while adapting (e.g. the estimated one)")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--iterations", type=positive_int)
    p.add_argument("--elevation", type=finite_float)
    p.add_argument("--seed", type=int)
    p.add_argument("--model-resolution", type=positive_int, help="image size the diffusion models see (default 512)")
    p.add_argument("--render-size", type=positive_int, help="largest render size of the coarse-to-fine stages")
    add_model_args(p)
    add_prompt_service_args(p, prefix="prompt-")
    p.set_defaults(func=run)
