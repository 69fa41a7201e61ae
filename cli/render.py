"""scenefit render: the asset (or its converted neural texture) from orbit views."""
from __future__ import annotations

from pathlib import Path

from ..core.render.renderer import RENDERER_TYPES
from .options import (MAX_VIEWS, add_asset_args, add_lighting_args, add_orbit_camera_args, add_output_args,
                      count_up_to, environment, load_asset, positive_float, output, progress)


def run(args) -> int:
    from dataclasses import replace

    import torch

    from ..core.stages.convert import asset_stack
    from ..core.base.limits import LOOP_RENDER_BYTES_PER_PIXEL, RENDER_BYTES_PER_PIXEL, check_render_size
    from ..core.data.mesh import normalize_to_unit_sphere
    from ..core.texture.surface_layout import texture_view
    from ..core.texture.bake import load_neural_texture

    # Sizes and inputs are refused before the output folder is made or anything is rendered.
    check_render_size(args.size, args.size, bytes_per_pixel=LOOP_RENDER_BYTES_PER_PIXEL if args.renderer == "loop"
                      else RENDER_BYTES_PER_PIXEL)
    mesh, maps = load_asset(args.asset, args.object)
    normalized, _ = normalize_to_unit_sphere(mesh)
    if args.texture:
        texture = load_neural_texture(Path(args.texture))
        view = texture_view(texture, normalized)
        if view.mesh is not normalized:   # adaptation's new UV layout: the asset's normal map is in its own UVs
            normalized, maps = view.mesh, replace(maps, normal=None)
        stack, label = torch.from_numpy(view.stack(texture)), "neural texture"
    else:
        stack, label = torch.from_numpy(asset_stack(maps, f"'{args.asset}'")), "asset maps"
    with output(args) as out:
        return _render(args, out, mesh, normalized, maps, stack, label)


def _render(args, out: Path, mesh, normalized, maps, stack, label: str) -> int:
    from ..core.render.orbit_camera import orbit_cameras
    from ..core.data.imageio import write_image
    from ..core.base.report import write_report
    from ..core.render.backend import environment_info
    from ..core.texture.views import render_views, tonemap_srgb

    env, env_label = environment(args)
    cameras = orbit_cameras(args.views, args.elevation, fov_multiplier=1.1, size=args.size)
    normal_map = None if args.no_normal_map else maps.normal
    if args.renderer == "loop":
        images = _loop_views(normalized, stack, env, cameras, normal_map)
    else:
        images = render_views(normalized, {label: stack}, env, cameras, args.spp, progress=progress(args),
                              normal_map=normal_map)[label]
    files = []
    for camera, image in zip(cameras, images):
        path = out / f"view_az{int(round(camera.azimuth_deg)):03d}.png"
        write_image(path, tonemap_srgb(image, args.exposure))
        files.append(str(path))
    renderer = ("loop: G-buffers traced by Mitsuba, shaded in torch (the adapt stage's renderer)"
                if args.renderer == "loop" else f"path: Mitsuba path tracing at {args.spp} spp")
    write_report(out / "report.json", {"stage": "render", "source": label, "lighting": env_label,
                                       "views": files, "spp": args.spp if args.renderer == "path" else None,
                                       "renderer": renderer, "environment": environment_info()})
    print(f"rendered {len(files)} views of '{mesh.name}' ({label}, {env_label}, {args.renderer} renderer) -> {args.out}")
    return 0


def _loop_views(normalized, stack, env, cameras, normal_map) -> list:
    """The views drawn by the loop renderer (core/render/loop_renderer.py), as adapt draws them."""
    import torch

    from ..core.render.loop_renderer import LoopRenderer
    from ..core.render.renderer import SceneOptions

    renderer = LoopRenderer(normalized, tuple(stack.shape[:2]), env, SceneOptions(hide_emitters=False),
                            normal_map=normal_map)
    channels = (stack[..., 0:3], stack[..., 3:4], stack[..., 4:5])
    with torch.no_grad():
        return [renderer.render(camera, *channels, torch.from_numpy(env)).rgb.numpy() for camera in cameras]


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render the asset (or its converted neural texture) from orbit views")
    add_asset_args(p)
    add_lighting_args(p)
    add_output_args(p)
    p.add_argument("--texture", help="a texture.pt written by `scenefit convert` (default: the asset's maps)")
    p.add_argument("--views", type=count_up_to(MAX_VIEWS, "views"), default=4)
    add_orbit_camera_args(p, size=256, spp=64)
    p.add_argument("--exposure", type=positive_float, default=1.0)
    p.add_argument("--no-normal-map", action="store_true", help="render without the asset's normal map")
    p.add_argument("--renderer", choices=RENDERER_TYPES, default="path",
                   help="path: Mitsuba path tracing at --spp (the reference); loop: the adapt stage's renderer "
                        "(G-buffers traced once, shaded in torch; the asset alone on black) - draw both to compare")
    p.set_defaults(func=run)
