"""`scenefit` on the command line: the same pipeline the Blender operators run, headless.

It lives beside core/ rather than in it because reading .blend/glTF assets and making the bundled
example need Blender (bpy), which core/ never imports.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .core.errors import Cancelled, SceneFitError

PRESETS = ("draft", "balanced", "final")


def load_asset(path: str, object_name: str | None = None):
    """(Mesh, PBRMaps) from an asset folder, or from a file Blender reads (needs bpy)."""
    from .core.asset_io import is_asset_folder, load_asset_folder

    if is_asset_folder(path):
        return load_asset_folder(path)
    from .blender_io.asset_file import load_asset_file

    return load_asset_file(path, object_name)


def _progress(args):
    from .core.progress import TerminalProgress

    return None if getattr(args, "quiet", False) else TerminalProgress()


def _environment(args):
    from .core.pipeline import constant_environment, load_environment
    from .core.photo import studiolight_path

    if getattr(args, "envmap", None):
        return load_environment(args.envmap), f"environment map {args.envmap}"
    if getattr(args, "studiolight", None):
        return load_environment(studiolight_path(args.studiolight)), f"Blender studio light '{args.studiolight}'"
    value = float(getattr(args, "ambient", 1.0))
    return constant_environment([value] * 3), f"constant environment of radiance {value}"


def cmd_convert(args) -> int:
    from .core.convert import convert_preset
    from .core.pipeline import convert_and_bake, environment_info, write_report
    from .core.asset_io import save_asset_folder

    mesh, maps = load_asset(args.asset, args.object)
    overrides = {k: v for k, v in (("method_type", args.method), ("iterations", args.iterations),
                                   ("resolution", args.resolution), ("seed", args.seed)) if v is not None}
    config = convert_preset(args.preset, **overrides)
    out = Path(args.out)
    result, report = convert_and_bake(mesh, maps, out / "maps", config, progress=_progress(args))
    save_asset_folder(mesh, maps, out / "asset")
    report["environment"] = environment_info()
    write_report(out / "report.json", report)
    print(f"converted '{mesh.name}': {result.psnr:.2f} dB on covered texels in {result.seconds:.1f} s "
          f"({config.method_type}) -> {out}")
    return 0


def cmd_render(args) -> int:
    import torch

    from .core.camera import orbit_cameras
    from .core.imageio import write_image
    from .core.mesh import normalize_to_unit_sphere
    from .core.pipeline import render_views, tonemap_srgb, write_report, environment_info
    from .core.texture.bake import load_neural_texture
    from .core.texture.uv_raster import rasterize_uv
    from .core.convert import target_stack

    mesh, maps = load_asset(args.asset, args.object)
    normalized, _ = normalize_to_unit_sphere(mesh)
    if args.texture:
        texture = load_neural_texture(Path(args.texture))
        resolution = texture.config.resolution
        raster = rasterize_uv(normalized, resolution)
        with torch.no_grad():
            stack = texture.texture(raster.position, raster.border, raster.fill_index)
        label = "neural texture"
    else:
        stack, label = torch.from_numpy(target_stack(maps, max(maps.resolution))), "asset maps"
    env, env_label = _environment(args)
    cameras = orbit_cameras(args.views, args.elevation, fov_multiplier=1.1, size=args.size)
    images = render_views(normalized, {label: stack}, env, cameras, args.spp, progress=_progress(args))[label]
    out = Path(args.out)
    files = []
    for camera, image in zip(cameras, images):
        path = out / f"view_az{int(round(camera.azimuth_deg)):03d}.png"
        write_image(path, tonemap_srgb(image, args.exposure))
        files.append(str(path))
    write_report(out / "report.json", {"stage": "render", "source": label, "lighting": env_label,
                                       "views": files, "spp": args.spp, "environment": environment_info()})
    print(f"rendered {len(files)} views of '{mesh.name}' ({label}, {env_label}) -> {out}")
    return 0


def cmd_export(args) -> int:
    from .core.camera import Camera
    from .core.export import export_mitsuba_scene

    mesh, maps = load_asset(args.asset, args.object)
    env = None
    if args.envmap or args.studiolight:
        env, _ = _environment(args)
    camera = Camera(azimuth_deg=args.azimuth, elevation_deg=args.elevation, width=args.size, height=args.size)
    xml = export_mitsuba_scene(mesh, maps, args.out, camera=camera, envmap=env, spp=args.spp)
    print(f"wrote {xml}; render it with: mitsuba {xml}")
    return 0


def cmd_demo(args) -> int:
    from .demo import run_demo

    report = run_demo(Path(args.out), preset=args.preset, progress=_progress(args), refresh=args.refresh,
                      guidance=args.guidance)
    print(f"demo done in {report['seconds_total']:.1f} s: conversion {report['convert']['psnr_covered_texels_db']:.2f} dB "
          f"-> {args.out}/report.json")
    return 0


def cmd_light(args) -> int:
    from .core.lighting import estimate_light, light_preset, light_report, load_photo, parse_placement, write_light_outputs
    from .core.lighting.depth import DEFAULT_DEPTH_MODEL, DepthConfig
    from .core.pipeline import environment_info, write_report

    photo, info = load_photo(args.photo)
    placement = parse_placement(args.at, photo.shape[1], photo.shape[0])
    depth = DepthConfig(depth_type=args.depth, model=args.depth_model or DEFAULT_DEPTH_MODEL)
    overrides = {k: v for k, v in (("scene_type", args.scene), ("fov_deg", args.fov), ("tint", args.tint),
                                   ("camera_pitch_deg", -args.elevation if args.elevation is not None else None))
                 if v is not None}
    from dataclasses import replace

    from .core.guidance import ModelConfig, models_available

    models = ModelConfig(**{k: v for k, v in (("base_model", args.base_model), ("inpaint_model", args.inpaint_model),
                                              ("cache_dir", args.cache_dir)) if v}, local_files_only=args.offline)
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
    result = estimate_light(photo, placement, config, photo_info=info, progress=_progress(args))
    result.decisions["critic"]["choice"] = critic_choice
    out = Path(args.out)
    outputs = write_light_outputs(result, out)
    report = light_report(result, config, outputs)
    report["photo"] = info
    report["environment"] = environment_info()
    write_report(out / "report.json", report)
    depth_used = result.decisions.get("depth", {}).get("method", "none (outdoor)")
    print(f"light: {result.decisions['scene_type']['chosen']} scene, depth {depth_used}, scales "
          f"{ {k: round(v, 3) for k, v in result.scales.items()} } -> {out}/light.exr")
    return 0


def cmd_adapt(args) -> int:
    import numpy as np

    from .core.adapt import adapt_and_bake, adapt_preset
    from .core.guidance import ModelConfig, Placement
    from .core.imageio import linear_to_srgb, read_color_image
    from .core.pipeline import environment_info, write_report
    from .core.texture.bake import load_neural_texture

    mesh, _ = load_asset(args.asset, args.object)
    models = ModelConfig(**{k: v for k, v in (("base_model", args.base_model), ("inpaint_model", args.inpaint_model),
                                              ("cache_dir", args.cache_dir)) if v}, local_files_only=args.offline)
    overrides = {k: v for k, v in (("iterations", args.iterations), ("seed", args.seed),
                                   ("elevation", args.elevation)) if v is not None}
    mode = args.mode
    config = adapt_preset(args.preset, mode, prompt=args.prompt or "", object_prompt=args.object_prompt or "",
                          instruction=args.instruction or "", models=models,
                          **({"views_type": "local"} if mode == "scene" and not args.photo else {}),
                          **({"light_type": "envmap"} if args.envmap else {}), **overrides)
    if args.model_resolution or args.render_size:
        from dataclasses import replace

        from .core.adapt import StageSpec

        stages = tuple(StageSpec(st.fraction, min(st.render_size, args.render_size or st.render_size), st.spp, st.t_range)
                       for st in config.stages)
        config = replace(config, stages=stages, model_resolution=args.model_resolution or config.model_resolution)
    texture = load_neural_texture(args.texture) if args.texture else None
    photo = placement = None
    if args.photo:
        photo = linear_to_srgb(np.clip(read_color_image(args.photo), 0.0, 1.0))
        x, y = (float(v) for v in args.at.split(","))
        placement = Placement((x, y), args.size)
    env = _environment(args)[0] if args.envmap else None
    result, report = adapt_and_bake(mesh, texture, config, Path(args.out), photo=photo, placement=placement,
                                    envmap=env, progress=_progress(args))
    report["environment"] = environment_info()
    write_report(Path(args.out) / "report.json", report)
    print(f"adapted '{mesh.name}' ({mode}, {result.iterations} iterations, {result.seconds:.1f} s) -> {args.out}/maps")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="scenefit", description=(
        "Restyle a textured 3D asset to fit a photo: neural PBR textures rendered by Mitsuba 3."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def asset_args(p):
        p.add_argument("asset", help="a SceneFit asset folder (mesh.npz + maps) or a .blend/.glb/.gltf/.obj/.fbx file")
        p.add_argument("--object", help="mesh object to use from a Blender file (default: the largest)")
        p.add_argument("--quiet", action="store_true", help="no progress bar")

    def light_args(p):
        p.add_argument("--envmap", help="equirectangular HDR map (EXR/HDR) to light the asset")
        p.add_argument("--studiolight", help="one of Blender's bundled HDR maps (studio, interior, city, forest, ...)")
        p.add_argument("--ambient", type=float, default=1.0, help="constant environment radiance when no map is given")

    p = sub.add_parser("convert", help="fit a neural texture to the asset's own maps and bake it")
    asset_args(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--preset", choices=PRESETS, default="balanced", help="speed/accuracy trade (default: balanced)")
    p.add_argument("--method", choices=("direct", "inverse"), help="direct texture-space fit (default) or inverse rendering")
    p.add_argument("--iterations", type=int)
    p.add_argument("--resolution", type=int, help="texture size (default: the asset's, capped by the preset)")
    p.add_argument("--seed", type=int)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("render", help="render the asset (or its converted neural texture) from orbit views")
    asset_args(p)
    light_args(p)
    p.add_argument("--out", required=True)
    p.add_argument("--texture", help="a texture.pt written by `scenefit convert` (default: the asset's maps)")
    p.add_argument("--views", type=int, default=4)
    p.add_argument("--elevation", type=float, default=15.0)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--exposure", type=float, default=1.0)
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("export", help="write the asset, maps, camera and light as a Mitsuba scene (XML + PLY + images)")
    asset_args(p)
    light_args(p)
    p.add_argument("--out", required=True)
    p.add_argument("--azimuth", type=float, default=30.0)
    p.add_argument("--elevation", type=float, default=15.0)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--spp", type=int, default=256)
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("demo", help="run SceneFit on the bundled example (what `make demo` runs)")
    p.add_argument("--out", default="out/demo")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--refresh", action="store_true", help="re-make the example asset and photo")
    p.add_argument("--guidance", choices=("auto", "sd2", "none"), default="auto",
                   help="texture adaptation: sd2 (needs the Stable Diffusion 2 weights), none, or auto (sd2 when "
                        "its weights are on this machine)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("adapt", help="restyle a converted texture with diffusion guidance (or texture/edit from a prompt)")
    asset_args(p)
    p.add_argument("--out", required=True, help="output folder: maps/, checkpoint/ (rerun to resume), report.json")
    p.add_argument("--mode", choices=("scene", "generate", "edit"), default="scene")
    p.add_argument("--texture", help="texture.pt from `scenefit convert` (required unless --mode generate)")
    p.add_argument("--prompt", help="appearance description, e.g. 'a leather sofa, soggy and stained with mud'")
    p.add_argument("--object-prompt", help="edit mode: the object, e.g. 'a leather sofa'")
    p.add_argument("--instruction", help="edit mode: e.g. 'add dust to the sofa'")
    p.add_argument("--photo", help="scene mode: the photo the object goes into")
    p.add_argument("--at", default="0.5,0.6", help="X,Y centre of the object in the photo, fractions (default 0.5,0.6)")
    p.add_argument("--size", type=float, default=0.4, help="object size as a fraction of the photo height")
    p.add_argument("--envmap", help="light the object with this HDR map while adapting (e.g. the estimated one)")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--iterations", type=int)
    p.add_argument("--elevation", type=float)
    p.add_argument("--seed", type=int)
    p.add_argument("--model-resolution", type=int, help="image size the diffusion models see (default 512)")
    p.add_argument("--render-size", type=int, help="largest render size of the coarse-to-fine stages")
    p.add_argument("--base-model", help="hub id or folder (default stabilityai/stable-diffusion-2-base)")
    p.add_argument("--inpaint-model", help="hub id or folder (default stabilityai/stable-diffusion-2-inpainting)")
    p.add_argument("--cache-dir", help="Hugging Face cache folder to look in")
    p.add_argument("--offline", action="store_true", help="never download (also HF_HUB_OFFLINE=1)")
    p.set_defaults(func=cmd_adapt)
    p = sub.add_parser("light", help="estimate an HDR environment map from a photo and the object's placement")
    p.add_argument("--photo", required=True, help="the scene photo (JPEG/PNG/EXR, any size)")
    p.add_argument("--at", required=True, help="X,Y where the object stands: fractions of width,height (or pixels)")
    p.add_argument("--out", required=True, help="output folder: light.exr, light_preview.png, report.json")
    p.add_argument("--preset", choices=PRESETS, default="balanced")
    p.add_argument("--scene", choices=("auto", "indoor", "outdoor"), help="scene type (default: auto)")
    p.add_argument("--fov", type=float, help="horizontal field of view in degrees (default: metadata, else 60)")
    p.add_argument("--elevation", type=float, help="how far the camera looks down, degrees (default 10)")
    p.add_argument("--depth", choices=("auto", "model", "geometric"), default="auto",
                   help="auto: the depth model if it is on this machine, else the geometric room")
    p.add_argument("--depth-model", help="hub id or local folder of a transformers depth model")
    p.add_argument("--tint", help='colour phrase for the critic prompt, e.g. "in blue tint"')
    p.add_argument("--critic", choices=("auto", "diffusion", "none"), default="auto",
                   help="what refines the light scales: diffusion (VSD with Stable Diffusion 2 base), none (the "
                        "inverse-tone-mapping prior alone), or auto (diffusion when its weights are on this machine)")
    p.add_argument("--iterations", type=int, help="light-scale optimisation steps (default: the preset's)")
    p.add_argument("--outpaint", choices=("auto", "sd2", "prior"), default="auto",
                   help="outdoor: complete the unseen map by SD2 inpainting (sd2), the sky/ground prior (prior), or "
                        "auto (sd2 when its weights are on this machine)")
    p.add_argument("--model-resolution", type=int,
                   help="image size the diffusion critic sees and the outpainting height (default 512)")
    p.add_argument("--inpaint-model", help="hub id or folder (default stabilityai/stable-diffusion-2-inpainting)")
    p.add_argument("--base-model", help="hub id or folder (default stabilityai/stable-diffusion-2-base)")
    p.add_argument("--cache-dir", help="Hugging Face cache folder to look in")
    p.add_argument("--offline", action="store_true", help="never download (also HF_HUB_OFFLINE=1)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_light)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except Cancelled as error:
        print(f"\nscenefit: {error}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("\nscenefit: interrupted; outputs already written are complete, nothing half-written remains.",
              file=sys.stderr)
        return 130
    except SceneFitError as error:
        print(f"scenefit: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
