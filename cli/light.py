"""scenefit light: an HDR environment map from a photo and the object's placement."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .options import (PRESETS, add_model_args, add_output_args, finite_float, model_config, output, placement_fractions, positive_float,
                      positive_int, progress)


def run(args) -> int:
    with output(args) as out:
        return _light(args, out)


def _light(args, out: Path) -> int:
    from ..core.guidance import models_available
    from ..core.lighting import estimate_light, light_preset, light_report, load_photo, parse_placement, write_light_outputs
    from ..core.lighting.depth import DEFAULT_DEPTH_MODEL, DepthConfig
    from ..core.pipeline import environment_info, write_report

    photo, info = load_photo(args.photo)
    placement = parse_placement(args.at, photo.shape[1], photo.shape[0])
    # --offline and --cache-dir apply to the depth model as to the diffusion models (no network retries).
    depth = DepthConfig(depth_type=args.depth, model=args.depth_model or DEFAULT_DEPTH_MODEL, cache_dir=args.cache_dir,
                        local_files_only=True if args.offline else None)
    overrides = {k: v for k, v in (("scene_type", args.scene), ("fov_deg", args.fov), ("tint", args.tint),
                                   ("camera_pitch_deg", -args.elevation if args.elevation is not None else None))
                 if v is not None}
    models = model_config(args)
    # --critic auto (as the demo's --guidance and --depth): the diffusion critic when SD2 is on this machine.
    if args.critic == "auto":
        found, where = models_available(models, need_inpaint=False)
        critic_choice = {"asked": "auto", "chosen": "diffusion" if found else "none",
                         "why": f"Stable Diffusion 2 found ({where})" if found else
                                "Stable Diffusion 2 weights are not on this machine, so the prior sets the scales"}
    else:
        critic_choice = {"asked": args.critic, "chosen": args.critic, "why": "the user's choice"}
    config = light_preset(args.preset, depth=depth, critic_type=critic_choice["chosen"], models=models, **overrides)
    if args.iterations is not None:
        config = replace(config, optimise=replace(config.optimise, iterations=args.iterations))
    config = replace(config, outpaint=replace(config.outpaint, completion_type=args.outpaint))
    if args.model_resolution is not None:
        config = replace(config, diffusion=replace(config.diffusion, model_resolution=args.model_resolution),
                         outpaint=replace(config.outpaint, resolution=args.model_resolution))
    result = estimate_light(photo, placement, config, photo_info=info, progress=progress(args))
    result.decisions["critic"]["choice"] = critic_choice
    outputs = write_light_outputs(result, out)
    report = light_report(result, config, outputs)
    report["photo"] = info
    report["environment"] = environment_info()
    write_report(out / "report.json", report)
    depth_used = result.decisions.get("depth", {}).get("method", "none (outdoor)")
    print(f"light: {result.decisions['scene_type']['chosen']} scene, depth {depth_used}, scales "
          f"{ {k: round(v, 3) for k, v in result.scales.items()} } -> {Path(args.out) / 'light.exr'}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("light", help="estimate an HDR environment map from a photo and the object's placement")
    p.add_argument("--photo", required=True, help="the scene photo (JPEG/PNG/EXR, any size)")
    p.add_argument("--at", required=True, type=placement_fractions,
                   help="X,Y where the object stands: fractions of the photo's width and height")
    add_output_args(p, help="output folder: light.exr, light_preview.png, report.json")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--scene", choices=("auto", "indoor", "outdoor"), help="scene type (default: auto)")
    p.add_argument("--fov", type=positive_float, help="horizontal field of view in degrees (default: metadata, else 60)")
    p.add_argument("--elevation", type=finite_float, help="how far the camera looks down, degrees (default 10)")
    p.add_argument("--depth", choices=("auto", "model", "geometric"), default="auto",
                   help="auto: the depth model if it is on this machine, else the geometric room")
    p.add_argument("--depth-model", help="hub id or local folder of a transformers depth model")
    p.add_argument("--tint", help='colour phrase for the critic prompt, e.g. "in blue tint"')
    p.add_argument("--critic", choices=("auto", "diffusion", "none"), default="auto",
                   help="what refines the light scales: diffusion (VSD with Stable Diffusion 2 base), none (the "
                        "inverse-tone-mapping prior alone), or auto (diffusion when its weights are on this machine)")
    p.add_argument("--iterations", type=positive_int, help="light-scale optimisation steps (default: the preset's)")
    p.add_argument("--outpaint", choices=("auto", "sd2", "prior"), default="auto",
                   help="outdoor: complete the unseen map by SD2 inpainting (sd2), the sky/ground prior (prior), or "
                        "auto (sd2 when its weights are on this machine)")
    p.add_argument("--model-resolution", type=positive_int,
                   help="image size the diffusion critic sees and the outpainting height (default 512)")
    add_model_args(p)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)
