"""The bundled example, end to end: what `make demo` runs (later stages join as they land).

Inputs are made here, never downloaded: Suzanne with a procedural material baked by Blender's
Cycles into image maps, and a photo cut from one of the CC0 HDR maps inside the bpy wheel,
exposed and clipped to 8 bits as a camera would.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from .core.asset_io import is_asset_folder, load_asset_folder
from .core.camera import orbit_cameras
from .core.convert import convert_preset, target_stack
from .core.imageio import read_image, write_image
from .core.lighting import estimate_light, light_preset, light_report, load_photo, parse_placement, write_light_outputs
from .core.mesh import normalize_to_unit_sphere
from .core.photo import PhotoCamera, develop_photo, perspective_view, studiolight_path
from .core.pipeline import (contact_sheet, convert_and_bake, environment_info, image_psnr,
                            render_views, tonemap_srgb, write_report)
from .core.progress import ProgressCallback, emit
from .core.scene_needs import envmap_height_for
from .core.texture.uv_raster import rasterize_uv

DEMO_STUDIOLIGHT = "interior"
DEMO_PHOTO_CAMERA = PhotoCamera(yaw_deg=60.0, pitch_deg=-12.0, fov_deg=60.0, width=768, height=512)
DEMO_PLACEMENT = (0.5, 0.75)  # where the asset goes, as a fraction of the photo's width and height
DEMO_VIEWS = 4


def make_example(folder: Path) -> str:
    """Make the example asset with Blender in a child process (it resets Blender's file); reuse it if present."""
    if is_asset_folder(folder):
        return "reused"
    code = f"from scenefit.blender_io import make_example_asset; make_example_asset({str(folder)!r})"
    subprocess.run([sys.executable, "-c", code], check=True)
    return "made by Blender (Suzanne, Smart UV Project, procedural material baked by Cycles)"


def make_photo(path: Path) -> dict:
    hdr = read_image(studiolight_path(DEMO_STUDIOLIGHT))[..., :3]
    photo = develop_photo(perspective_view(hdr, DEMO_PHOTO_CAMERA))
    write_image(path, photo.astype(np.float32) / 255.0)
    return {"source": f"bpy studiolights/world/{DEMO_STUDIOLIGHT}.exr (CC0)",
            "camera": asdict(DEMO_PHOTO_CAMERA)}


def run_demo(out: Path, preset: str = "balanced", progress: ProgressCallback | None = None,
             refresh: bool = False, guidance: str = "auto") -> dict:
    started = time.perf_counter()
    out = Path(out)
    # Texture adaptation needs Stable Diffusion 2: "sd2" insists (a missing model stops the demo here,
    # before any work), "auto" uses it when its weights are on this machine, "none" skips it.
    from .core.errors import InputError
    from .core.guidance import ModelConfig, locate_models, models_available

    if guidance not in ("auto", "sd2", "none"):
        raise InputError(f"guidance must be 'auto', 'sd2' or 'none', got {guidance!r}.")
    if guidance == "sd2":
        locate_models(ModelConfig(), need_inpaint=True)
    found, where = models_available(ModelConfig()) if guidance == "auto" else (guidance == "sd2", "")
    adapt_info: dict = {"guidance": guidance, "used": bool(found)}
    if not found:
        adapt_info["why"] = ("--guidance none: the weight-free path (the converted texture is not adapted)"
                             if guidance == "none" else "Stable Diffusion 2 weights were not found, so the demo "
                             "ran the weight-free path (the converted texture is not adapted): " + where)
    inputs = out / "input"
    if refresh and inputs.exists():
        shutil.rmtree(inputs)
    timings: dict[str, float] = {}

    t = time.perf_counter()
    emit(progress, "example", 0, 1, "making the example asset with Blender")
    example_origin = make_example(inputs / "asset")
    photo_info = make_photo(inputs / "photo.png")
    emit(progress, "example", 1, 1, example_origin)
    timings["inputs"] = time.perf_counter() - t

    mesh, maps = load_asset_folder(inputs / "asset")
    # Light: the photo's HDR environment, estimated from the photo alone (no diffusion critic
    # without weights, so the inverse-tone-mapping prior sets the light scales; the report says so).
    t = time.perf_counter()
    photo_srgb, photo_read = load_photo(inputs / "photo.png")
    placement_px = parse_placement(DEMO_PLACEMENT, photo_srgb.shape[1], photo_srgb.shape[0])
    # Only what the scene needs: the map is as sharp as the asset's glossiest reflections.
    normalized, _ = normalize_to_unit_sphere(mesh)
    covered = rasterize_uv(normalized, max(maps.resolution)).mask
    envmap_height = envmap_height_for(maps, covered)
    light_config = light_preset(preset, map_height=envmap_height.value)
    light = estimate_light(photo_srgb, placement_px, light_config, photo_camera=DEMO_PHOTO_CAMERA,
                           photo_info=photo_read, progress=progress)
    light_outputs = write_light_outputs(light, out / "light")
    env = light.hdr.astype(np.float32)
    lighting = light_report(light, light_config, light_outputs)
    lighting["decisions"]["envmap_height"] = envmap_height.to_dict()
    timings["light"] = time.perf_counter() - t

    # Convert the asset's own maps into the neural texture and bake it.
    config = convert_preset(preset)
    result, convert_report = convert_and_bake(mesh, maps, out / "converted", config, progress=progress,
                                              keep_constants=True)
    timings["convert"] = result.seconds

    # The original maps, next to the converted ones.
    (out / "original").mkdir(parents=True, exist_ok=True)
    for name in ("base_color.png", "roughness.png", "metallic.png", "material.json"):
        if (inputs / "asset" / name).is_file():
            shutil.copyfile(inputs / "asset" / name, out / "original" / name)

    # Render both under the demo light from orbit views.
    t = time.perf_counter()
    normalized, _ = normalize_to_unit_sphere(mesh)
    with torch.no_grad():
        converted = result.predicted()
    original = torch.from_numpy(target_stack(maps, result.raster.resolution[0]))
    cameras = orbit_cameras(DEMO_VIEWS, elevation_deg=15.0, fov_multiplier=1.1, size=256)
    images = render_views(normalized, {"original": original, "converted": converted}, env, cameras, spp=64,
                          progress=progress)
    display = {name: [tonemap_srgb(im) for im in ims] for name, ims in images.items()}
    render_files = []
    for name, ims in display.items():
        for camera, image in zip(cameras, ims):
            path = out / "renders" / f"{name}_az{int(round(camera.azimuth_deg)):03d}.png"
            write_image(path, image)
            render_files.append(str(path))
    write_image(out / "renders" / "comparison.png", contact_sheet({"original": display["original"],
                                                                   "converted": display["converted"]}))
    render_psnr = float(np.mean([image_psnr(a, b) for a, b in zip(display["original"], display["converted"])]))
    timings["render"] = time.perf_counter() - t

    if found:  # scene-conditional adaptation of the converted texture (draft-sized for the demo)
        from .core.adapt import adapt_and_bake, adapt_preset
        from .core.guidance import Placement

        adapt_config = adapt_preset(preset, "scene", prompt="a monkey head sculpture standing in a living room, "
                                    "its painted surface dusty and worn, photo")
        _, adapt_info["report"] = adapt_and_bake(mesh, result.texture, adapt_config, out / "adapted",
                                                 photo=photo_srgb,
                                                 placement=Placement(DEMO_PLACEMENT, 0.4), progress=progress)
        timings["adapt"] = adapt_info["report"]["seconds"]

    report = {
        "stage": "demo",
        "preset": preset,
        "inputs": {"asset": example_origin, "photo": photo_info, "placement": DEMO_PLACEMENT},
        "lighting": lighting,
        "convert": convert_report,
        "renders": {"files": render_files, "comparison": str(out / "renders" / "comparison.png"),
                    "psnr_original_vs_converted_db": round(render_psnr, 3), "spp": 64, "views": DEMO_VIEWS},
        "timings_seconds": {k: round(v, 3) for k, v in timings.items()},
        "environment": environment_info(),
        "not_yet": ["texture adaptation (diffusion critics)", "composition"],
    }
    report["adapt"] = adapt_info
    if found:
        report["not_yet"] = [item for item in report["not_yet"] if not item.startswith("texture adaptation")]
    report["seconds_total"] = round(time.perf_counter() - started, 3)
    write_report(out / "report.json", report)
    return report
