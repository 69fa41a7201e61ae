"""scenefit compose: the asset in the photo, lit by the estimated light, casting its shadow."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .options import (PRESETS, add_asset_args, add_old_photo_elevation_arg, add_output_args, add_photo_camera_args,
                      add_placement_args, load_asset, output, photo_pitch, progress)


def run(args) -> int:
    from ..core.stages.compose import ComposeInputs, compose_to_folder
    from ..core.stages.convert import asset_stack
    from ..core.data.photo import load_photo
    from ..core.render.backend import environment_info
    from ..core.render.environment import load_environment
    from ..core.scene.placement import Placement
    from ..core.texture.surface_layout import texture_view
    from ..core.texture.bake import load_neural_texture

    from ..core.pipeline.run_table import run_config
    from ..core.pipeline.stage_configs import compose_config

    # The run this asks for, read through the run table as a jobs file's job is.
    settings = {k: v for k, v in (("sampler_type", args.sampler), ("denoiser_type", args.denoiser),
                                  ("exposure", args.exposure)) if v is not None}
    table = {"preset": args.preset, "object_size": args.object_size, "overrides": {"compose": settings},
             **{k: v for k, v in (("shadow_type", args.shadow), ("compose_spp", args.spp)) if v is not None}}
    config = compose_config(run_config(table, "scenefit compose", stages=("compose",)))
    mesh, maps = load_asset(args.asset, args.object)
    photo, info = load_photo(args.photo, max_side=config.max_side)
    h, w = photo.shape[:2]
    placement = Placement.parse(args.at, tuple(info["size"])).pixel((h, w))
    envmap = load_environment(args.light)
    camera, camera_source = compose_camera(args, w, h)
    if args.texture:
        texture = load_neural_texture(Path(args.texture))
        view = texture_view(texture, mesh)
        mesh, stack, source, layout = view.mesh, view.stack(texture), "neural texture", view.report["uv_layout"]
    else:
        stack, source, layout = asset_stack(maps, f"'{args.asset}'"), "the asset's own maps", "own"
    with output(args) as out:
        report = compose_to_folder(
            ComposeInputs(mesh, stack, photo, placement, envmap, camera), config, out,
            {"inputs": {"asset": args.asset, "texture": args.texture or source, "photo": info, "light": args.light,
                        "camera_from": camera_source, "uv_layout": layout},
             "environment": environment_info()},
            progress=progress(args))
    shadow = report["shadow"]
    print(f"composed '{mesh.name}' at {report['placement']['distance_m']} m, {report['spp']} spp, "
          f"shadow {shadow['type']} ({shadow['pixels']} px) in {report['seconds']:.1f} s -> {args.out}/composite.png")
    return 0


def compose_camera(args, width: int, height: int):
    """The photo's camera at `width` x `height`, and where it came from: the camera stage of the run the light
    map was made in (`scenefit run`'s, or `scenefit light`'s folder), else the camera stage's estimate of the
    photo (fSpy, EXIF, its lines); --fov, --pitch and --roll given here win. The lens shift is kept."""
    from dataclasses import replace

    from ..core.pipeline.layout import camera_of, run_folder_of
    from ..core.stages.camera import photo_camera_estimate

    given: dict[str, Any] = {k: v for k, v in (("fov_deg", args.fov), ("pitch_deg", photo_pitch(args)),
                                               ("roll_deg", args.roll)) if v is not None}
    run_folder = run_folder_of(args.light)
    if run_folder is None:
        estimate = photo_camera_estimate(args.photo, args.fspy, given)
        return estimate.photo_camera(width=width, height=height), \
            f"the photo's camera as the camera stage estimates it ({estimate.to_dict().get('source', '')})"
    camera, _ = camera_of(run_folder, width, height)
    source = f"the camera stage of the run in '{run_folder}'"
    return replace(camera, **given), source + (f"; overridden: {given}" if given else "")


def add_parser(sub) -> None:
    from ..core.stages.compose import SAMPLER_TYPES, SHADOW_TYPES
    from ..core.scene.placement import DEFAULT_OBJECT_SIZE

    p = sub.add_parser("compose", help="render the asset into the photo under the estimated light, with its shadow")
    add_asset_args(p)
    p.add_argument("--texture", help="a texture.pt (convert/adapt output) to render instead of the asset's own maps")
    p.add_argument("--photo", required=True, help="the scene photo")
    add_placement_args(p, required=True, object_size=DEFAULT_OBJECT_SIZE)
    p.add_argument("--light", required=True, help="light.exr from `scenefit light` or `scenefit run` (the camera "
                                                  "stage of its run gives the camera)")
    add_output_args(p, help="output folder: composite.png/.exr, layers/, report.json")
    p.add_argument("--preset", choices=PRESETS, default="balanced", help="noise target and sample cap")
    p.add_argument("--shadow", choices=SHADOW_TYPES, help="ratio (shadow catcher, default), paper (thresholded), none")
    p.add_argument("--spp", type=int, help="samples per pixel (default: from the preset's noise target)")
    p.add_argument("--sampler", choices=SAMPLER_TYPES, help="Mitsuba sampler (default multijitter)")
    p.add_argument("--denoiser", choices=("auto", "oidn", "none"),
                   help="Intel Open Image Denoise (oidn), none, or auto (default: oidn where pyoidn is installed)")
    p.add_argument("--exposure", type=float, help="multiply the light map (default 1: it is in the photo's exposure)")
    add_photo_camera_args(p)
    add_old_photo_elevation_arg(p)
    p.set_defaults(func=run)
