"""scenefit light: an HDR environment map from a photo and the object's placement."""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from .options import (add_dry_run_arg, add_model_args, add_old_photo_elevation_arg, add_output_args,
                      add_photo_camera_args, add_placement_args, add_preset_args, add_scene_arg, add_sun_args,
                      model_config, output, photo_pitch, positive_int, progress, require)


def light_run(args):
    """The run the arguments ask for, read through the run table as a jobs file's light job is: the light
    options that are a run's settings as its keys, the others as the light stage's overrides ("auto", the
    critic's default, left to light_critic)."""
    from ..core.pipeline.run_table import run_config

    light = {"critic_type": None if args.critic == "auto" else args.critic, "tint": args.tint,
             "depth": {"depth_type": args.depth}, "outpaint": {"completion_type": args.outpaint}}
    if args.iterations is not None:
        light["optimise"] = {"iterations": args.iterations}
    if args.model_resolution is not None:
        light["diffusion"] = {"model_resolution": args.model_resolution}
        light["outpaint"]["resolution"] = args.model_resolution
    camera = {k: v for k, v in (("fov", args.fov), ("pitch", photo_pitch(args)), ("roll", args.roll)) if v is not None}
    table = {"preset": args.preset, "scene": args.scene or "auto", "sun": None if args.sun is None else list(args.sun),
             "sun_shadow": list(args.sun_from_shadow) if args.sun_from_shadow else None, "fspy": args.fspy,
             "camera": camera, "depth_model": args.depth_model,
             "overrides": {"light": {k: v for k, v in light.items() if v is not None}}}
    return run_config(table, "scenefit light", stages=("light",), models=model_config(args))


def print_strict_json(config: dict) -> int:
    """--dry-run: the resolved configuration as strict JSON (an infinite distance threshold is null)."""
    import json

    from ..core.base.atomic import strict_json

    plain = json.loads(json.dumps(config, default=str))   # objects as their text, as print_config did
    print(json.dumps(strict_json(plain), indent=2, allow_nan=False))
    return 0


def run(args) -> int:
    if args.dry_run:
        from ..core.pipeline.stage_configs import light_config

        config = light_config(light_run(args), "diffusion" if args.critic == "auto" else args.critic)
        return print_strict_json({"stage": "light", "preset": args.preset, "config": asdict(config),
                                  "note": "--critic auto resolves to diffusion when the SD2 weights are found"
                                  if args.critic == "auto" else ""})
    require(args, "--photo", "--out")
    with output(args) as out:
        return _light(args, out)


def _light(args, out: Path) -> int:
    from ..core.pipeline.stage_configs import light_config, light_critic, with_shadow_sun
    from ..core.stages.light.scene_type import is_blended, scene_type_words
    from ..core.stages.light.stage import light_inputs, run_light, sun_words, write_light
    from ..core.render.backend import environment_info
    from ..core.pipeline.layout import RunLayout
    from ..core.pipeline.registry import names
    from ..core.stages.camera_stage import write_camera

    run = light_run(args)
    critic = light_critic(run)
    inputs = light_inputs(args.photo, args.at, run.fspy, run.camera_overrides)
    config = with_shadow_sun(light_config(run, critic.choice), run, inputs.camera, tuple(inputs.info["size"]),
                             (inputs.photo.shape[0], inputs.photo.shape[1]))
    write_camera(inputs.camera, inputs.camera_record, RunLayout(out).stage(names().CAMERA_STAGE))   # (compose reads it)
    result = run_light(inputs, config, progress(args))
    if args.sun_from_shadow:
        result.decisions["sun"]["from"] = "the shadow given by --sun-from-shadow (foot, top, tip)"
    result.decisions["critic"]["choice"] = {"asked": args.critic, "chosen": critic.choice, "why": critic.reason}
    write_light(result, out, {"environment": environment_info()})
    depth_used = result.decisions.get("depth", {}).get("method", "none (outdoor)")
    scene = result.decisions["scene_type"]
    if is_blended(scene):   # an unsure call: the map blends both, so say so, with both types' scales
        said = (scene_type_words(scene, "--scene") + ", scales "
                + ", ".join(f"{kind} { {k: round(v, 3) for k, v in scene['scales'][kind].items()} }"
                            for kind in ("indoor", "outdoor")))
    else:
        said = f"{scene_type_words(scene)} scene, scales { {k: round(v, 3) for k, v in result.scales.items()} }"
    direction = sun_words(result.decisions, "--sun AZ,EL or --sun-from-shadow")
    print(f"light: {said}, {direction}, depth {depth_used} -> {Path(args.out) / 'light.exr'}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("light", help="estimate an HDR environment map from a photo and the object's placement")
    p.add_argument("--photo", help="the scene photo (JPEG/PNG/EXR, any size)")
    add_placement_args(p, required=False)
    add_output_args(p, help="output folder: light.exr, light_preview.png, report.json and the "
                                    "camera stage's camera/camera.json", required=False)
    add_preset_args(p)
    add_scene_arg(p)
    add_photo_camera_args(p)
    add_old_photo_elevation_arg(p)
    add_sun_args(p)
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
                   help="image size the diffusion critic sees (default: the model's own) and the outpainting "
                        "height (default 512)")
    add_model_args(p)
    p.add_argument("--quiet", action="store_true")
    add_dry_run_arg(p)
    p.set_defaults(func=run)
