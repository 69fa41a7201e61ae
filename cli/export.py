"""scenefit export: the asset, maps, camera and light as a Mitsuba scene (XML + PLY + images)."""
from __future__ import annotations

from pathlib import Path

from .options import (add_asset_args, add_lighting_args, add_orbit_camera_args, add_output_args, environment,
                      finite_float, load_asset, output)


def run(args) -> int:
    from ..core.render.orbit_camera import Camera
    from ..core.render.export import export_mitsuba_scene

    camera = Camera(azimuth_deg=args.azimuth, elevation_deg=args.elevation, width=args.size, height=args.size)
    with output(args) as out:
        mesh, maps = load_asset(args.asset, args.object)
        env = None
        if args.envmap or args.studiolight:
            env, _ = environment(args)
        xml = export_mitsuba_scene(mesh, maps, out, camera=camera, envmap=env, spp=args.spp)
    xml = Path(args.out) / xml.name
    print(f"wrote {xml}; render it with: mitsuba {xml}")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("export", help="write the asset, maps, camera and light as a Mitsuba scene (XML + PLY + images)")
    add_asset_args(p)
    add_lighting_args(p)
    add_output_args(p)
    p.add_argument("--azimuth", type=finite_float, default=30.0)
    add_orbit_camera_args(p, size=512, spp=256)
    p.set_defaults(func=run)
