"""Composition: the asset rendered into the photo under the estimated light, with its shadow.

    job = build_compose(inputs, config)      # place the asset, build the Mitsuba scenes, pick spp
    while not job.done: job.step()           # one render pass per step (object, floor with/without it)
    result = job.finish()                    # denoise, matte, composite, report
    report = write_compose(result, folder)   # composite.png/.exr, layers/, report.json

Geometry is the scene's (core/scene/): the photo camera (`PhotoCamera`) stands
CAMERA_HEIGHT above the floor z = 0, and the asset stands on the floor where the ray through the
picked pixel meets it (`place_on_floor`), turned to face the camera and scaled so that it spans
`size` of the photo's height. The light map is latitude-longitude in Blender's convention and in
the photo's exposure (what `scenefit light` writes), so the render and the photo share units and
the composite needs no exposure factor.

The shadow (appendix "Scene Composition" of the paper, and the shadow-catcher default):
- "ratio" (default): the floor's radiance with the object divided by the floor's radiance without
  it, per colour channel, clipped to [0, 1], multiplied into the photo in linear light. Both floor
  passes use the same samples (same sampler, seed and window), so wherever the object changes
  nothing the two are bit-identical and the ratio is exactly 1. The object is black in the floor
  pass: it blocks light (shadow, contact shadow) but adds none (no colour bleeding); an albedo AOV
  tells the samples that met the floor from those that met the object. Darkening under
  `matte_tolerance` is dropped (the object's faint occlusion of the sky reaches every floor pixel).
- "paper": the floor with the object only, thresholded at `paper_threshold` x its mean intensity
  into shadowed and lit regions; shadowed intensities are divided by the lit mean and used as the
  matte, lit pixels keep the photo (our reading of "scale by norm([1,1,1]) / E(I | lit) and convert
  to transparency": a floor as bright as the lit mean is fully transparent).
- "none": no floor pass. Neither runs when the picked point is above the horizon: the asset then
  floats on the ray through the picked pixel, touches no floor and casts no shadow onto it.
"""
from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..render.backend import init_mitsuba, render_whole
from ..render.denoise import DENOISER_TYPES, denoise, oidn_available
from ..base.atomic import write_json_atomic
from ..base.errors import InputError, check_choice
from ..base.names import SHADOW_TYPES
from ..base.limits import COMPOSE_MAX_SIDE
from ..data.imageio import linear_to_srgb, srgb_to_linear, write_image
from ..data.mesh import Mesh, normalize_to_unit_sphere
from ..base.progress import ProgressCallback, check_cancel, emit
from ..render.renderer import _mitsuba_mesh, material_shapes
from ..scene.asset_pose import ASSUMED_CAMERA_HEIGHT_M, ObjectPlacement, place_asset, placed_mesh
from ..scene.camera import CAMERA_HEIGHT, PhotoCamera, camera_origin, horizon_row
from ..scene.frame import ENVMAP_TO_WORLD
from ..scene.mattes import composite_linear, paper_shadow_matte
from ..scene.placement import DEFAULT_OBJECT_SIZE

SAMPLER_TYPES = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)


@dataclass(frozen=True)
class ComposeConfig:
    size: float = DEFAULT_OBJECT_SIZE  # fraction of the photo's height the asset spans
    shadow_type: str = "ratio"        # ratio (a shadow catcher) | paper (the thresholded matte) | none
    spp: int | None = None            # None: chosen from noise_target by a pilot render
    noise_target: float = 0.03        # RMS noise of the raw object render, display sRGB units
    pilot_spp: int = 4                # samples of each of the two pilot renders that measure the noise
    min_spp: int = 4                  # the chosen sample count's bounds
    max_spp: int = 64                 # (the preset sets the upper one)
    sampler_type: str = "multijitter"  # picked by benchmarks/bench_compose.py
    denoiser_type: str = "auto"       # oidn | none | auto (Open Image Denoise when installed)
    max_depth: int = 6                # light bounces per path
    floor_albedo: float = 0.8          # cancels in the ratio; sets only the paper shadow's noise level
    paper_threshold: float = 0.9       # "shadowed" below this fraction of the floor's mean intensity
    matte_tolerance: float = 0.01      # darkening below 1% (about one 8-bit level of the photo at most) is
                                       # dropped: the object's faint occlusion of the sky reaches every floor pixel
    exposure: float = 1.0              # multiplies the light map (1: the map is in the photo's exposure)
    shadow_max_side: int = 1024        # the floor passes render at most this many pixels on the long side and
                                       # the matte is scaled up: shadows are soft, and a 12 MP floor pass would
                                       # cost ten times the object pass for no visible change
    max_side: int = COMPOSE_MAX_SIDE   # the composite's long side at most (a larger photo is reduced to it)
    seed: int = 0                      # the renders' sampler

    def __post_init__(self) -> None:
        if not 64 <= self.max_side <= COMPOSE_MAX_SIDE:
            raise InputError(f"max_side (the composite's long side) must be between 64 and {COMPOSE_MAX_SIDE} "
                             f"pixels, got {self.max_side}.")
        if not 0.0 < self.size <= 2.0:
            raise InputError(f"--object-size is the fraction of the photo's height the asset spans, in (0, 2]; "
                             f"got {self.size}.")
        check_choice("shadow_type", self.shadow_type, SHADOW_TYPES)
        check_choice("sampler_type", self.sampler_type, SAMPLER_TYPES)
        check_choice("denoiser_type", self.denoiser_type, DENOISER_TYPES)
        if self.spp is not None and not 1 <= self.spp <= 65536:
            raise InputError(f"spp must be between 1 and 65536, got {self.spp}.")
        if not (1 <= self.min_spp <= self.max_spp and self.pilot_spp >= 1):
            raise InputError(f"Need 1 <= min_spp <= max_spp and pilot_spp >= 1, got {self.min_spp}, {self.max_spp}, "
                             f"{self.pilot_spp}.")
        if not self.noise_target > 0:
            raise InputError(f"noise_target must be positive, got {self.noise_target}.")
        if not 0.0 <= self.matte_tolerance < 1.0:
            raise InputError(f"matte_tolerance must be in [0, 1), got {self.matte_tolerance}.")
        if not 0.0 < self.paper_threshold <= 1.0:
            raise InputError(f"paper_threshold must be in (0, 1], got {self.paper_threshold}.")
        if not self.exposure > 0:
            raise InputError(f"exposure must be positive, got {self.exposure}.")
        if self.shadow_max_side < 16:
            raise InputError(f"shadow_max_side must be at least 16 pixels, got {self.shadow_max_side}.")


@dataclass(frozen=True)
class ComposeInputs:
    mesh: Mesh                        # any scale; normalised here into the radius-0.5 sphere
    maps: np.ndarray                  # (H, W, 5) linear base colour, roughness, metallic (rows top first)
    photo_srgb: np.ndarray            # (h, w, 3) float in [0, 1], sRGB-encoded, as load_photo gives it
    placement_px: tuple[float, float]
    envmap: np.ndarray                # (He, 2 He, 3) linear, Blender's lat-long convention
    camera: PhotoCamera               # the light stage's photo camera (its width/height are replaced by the photo's)
    turn_deg: float = 0.0             # extra turn about Z after facing the camera (the adapt stage's global
                                      # views turn the asset so the photo camera sees the side a view samples)


# -- Mitsuba ------------------------------------------------------------------------------------------
def _sensor(mi, camera: PhotoCamera, window: tuple[int, int, int, int], sampler_type: str, spp: int):
    forward, _, up, _, _ = camera.basis()
    origin = camera_origin()
    x0, y0, x1, y1 = window
    return mi.load_dict({
        "type": "perspective", "fov": float(camera.fov_deg), "fov_axis": "x",
        "principal_point_offset_x": camera.film_offset()[0], "principal_point_offset_y": camera.film_offset()[1],
        "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=(origin + forward).tolist(),
                                                   up=up.tolist()),
        "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height, "pixel_format": "rgba",
                 "rfilter": {"type": "box"}, "crop_offset_x": x0, "crop_offset_y": y0,
                 "crop_width": x1 - x0, "crop_height": y1 - y0},
        "sampler": {"type": sampler_type, "sample_count": int(spp)},
    })


def _scene(mi, envmap: np.ndarray, mesh: Mesh | None, maps: np.ndarray | None, black: bool, floor_albedo: float | None):
    scene: dict = {"type": "scene",
                   "environment": {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(envmap, np.float32)),
                                   "to_world": mi.ScalarTransform4f(ENVMAP_TO_WORLD)}}
    if mesh is not None and black:   # the floor passes: the asset's shape alone
        shape = _mitsuba_mesh(mi, mesh)
        shape.set_bsdf(mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}))
        scene["asset"] = shape
    elif mesh is not None:   # one shape per material, sampling its own texels with its wrap mode
        scene.update(material_shapes(mi, mesh, maps)[0])  # type: ignore[arg-type]
    if floor_albedo is not None:
        scene["floor"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(1000.0 * CAMERA_HEIGHT),
                          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": floor_albedo}}}
    return mi.load_dict(scene)


@dataclass
class ComposeResult:
    composite_linear: np.ndarray      # (h, w, 3) linear, the photo's exposure
    composite_srgb: np.ndarray        # (h, w, 3) in [0, 1]; exactly the photo where nothing changed
    object_rgb: np.ndarray            # (h, w, 3) premultiplied linear radiance of the asset
    alpha: np.ndarray                 # (h, w) coverage
    matte: np.ndarray                 # (h, w, 3) shadow multiplier in [0, 1]; 1 = untouched
    changed: np.ndarray               # (h, w) bool: pixels that differ from the photo
    placement: ObjectPlacement
    report: dict = field(default_factory=dict)


class ComposeJob:
    """One composition as a small system: build (place, scenes, spp), step (one render pass), finish.

    With object_pass=False only the floor passes run (config.spp must be given): `matte()` is then the
    asset's shadow alone, which needs no texture (the object is black in the floor passes).
    """

    def __init__(self, inputs: ComposeInputs, config: ComposeConfig, progress: ProgressCallback | None = None,
                 cancel: threading.Event | None = None, object_pass: bool = True) -> None:
        t0 = time.perf_counter()
        self.config, self.progress, self.cancel = config, progress, cancel
        photo = np.clip(np.asarray(inputs.photo_srgb, np.float32)[..., :3], 0.0, 1.0)
        h, w = photo.shape[:2]
        self.photo = photo
        self.camera = replace(inputs.camera, width=w, height=h)
        maps = np.asarray(inputs.maps, np.float32) if object_pass else np.zeros((1, 1, 5), np.float32)
        if maps.ndim != 3 or maps.shape[2] != 5:
            raise InputError(f"The asset's maps must be (H, W, 5) base colour, roughness, metallic; got {maps.shape}.")
        if not object_pass and config.spp is None:
            raise InputError("A shadow-only composition needs a fixed spp (the noise target is set on the object).")
        envmap = np.asarray(inputs.envmap, np.float32)
        if envmap.ndim != 3 or envmap.shape[2] != 3 or envmap.shape[1] != 2 * envmap.shape[0]:
            raise InputError(f"The light map must be RGB with width = 2 x height, got {envmap.shape}.")
        if not np.isfinite(envmap).all() or envmap.min() < 0:
            raise InputError("The light map holds negative, NaN or infinite radiance.")
        self.envmap = envmap * np.float32(config.exposure)
        found, oidn_why = oidn_available()
        if config.denoiser_type == "oidn" and not found:
            raise InputError(f"--denoiser oidn: {oidn_why}.")
        # auto: denoise where OIDN is installed; elsewhere the raw render, with the reason in the report.
        self.denoiser = "oidn" if config.denoiser_type == "oidn" or (config.denoiser_type == "auto" and found) else "none"
        self.denoiser_why = oidn_why if self.denoiser == "oidn" else (
            "none (asked for)" if config.denoiser_type == "none" else f"none: {oidn_why}")
        self.backend = init_mitsuba()
        import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

        self.mi = mi
        normalized, _ = normalize_to_unit_sphere(inputs.mesh)
        self.placement = place_asset(normalized, self.camera, inputs.placement_px, config.size, inputs.turn_deg)
        self.mesh = placed_mesh(normalized, self.placement)
        self.maps = np.clip(maps, 0.0, 1.0)
        self.timings: dict[str, float] = {}
        self.decisions: dict = {}
        floor = config.shadow_type != "none" and self.placement.on_floor
        self.decisions["floor_pass"] = {
            "ran": floor,
            "why": ("the asset stands on the floor" if floor else
                    "shadow_type none" if config.shadow_type == "none" else self.placement.why)}
        # The object pass renders the asset's box at the photo's size; the floor passes the floor below
        # the horizon, at most shadow_max_side pixels across.
        self.object_window = self.placement.pixel_box
        scale = min(1.0, config.shadow_max_side / max(w, h))
        self.floor_camera = replace(self.camera, width=max(1, round(w * scale)), height=max(1, round(h * scale)))
        self.floor_window = (0, horizon_row(self.floor_camera), self.floor_camera.width, self.floor_camera.height)
        self.object_scene = (_scene(mi, self.envmap, self.mesh, self.maps, black=False, floor_albedo=None)
                             if object_pass else None)
        self.timings["build"] = time.perf_counter() - t0
        self.spp, self.decisions["spp"] = self._choose_spp()
        self.passes = ["object"] * object_pass + (["floor_with_object"] + (["floor_without_object"] if config.shadow_type == "ratio"
                                                              else []) if floor else [])
        self.images: dict[str, np.ndarray] = {}

    # -- build --------------------------------------------------------------------------------------
    def _object_integrator(self):
        return self.mi.load_dict({"type": "aov", "aovs": "albedo:albedo,normal:sh_normal",
                                  "integrator": {"type": "path", "max_depth": self.config.max_depth,
                                                 "hide_emitters": True}})

    def _render(self, scene, integrator, window, spp: int, seed: int, camera: PhotoCamera | None = None) -> np.ndarray:
        sensor = _sensor(self.mi, camera or self.camera, window, self.config.sampler_type, spp)
        image = render_whole(self.mi, scene, integrator, sensor=sensor, spp=spp, seed=seed)
        return np.array(image, dtype=np.float32)

    def _sampler_spp(self, spp: int) -> int:
        """The count the sampler really takes (multijitter and orthogonal round it up), asked quietly."""
        mi = self.mi
        logger = mi.logger()
        level = logger.log_level()
        logger.set_log_level(mi.LogLevel.Error)
        try:
            return int(mi.load_dict({"type": self.config.sampler_type, "sample_count": int(spp)}).sample_count())
        finally:
            logger.set_log_level(level)

    def _choose_spp(self) -> tuple[int, dict]:
        """Fixed, or from the noise target: two pilot renders with different seeds give the per-pixel
        noise (their difference / sqrt 2); noise falls as 1/sqrt(spp)."""
        c = self.config
        if c.spp is not None:
            spp = self._sampler_spp(c.spp)
            return spp, {"spp": spp, "from": "given" if spp == c.spp else f"given {c.spp}, rounded by the sampler"}
        t0 = time.perf_counter()
        integrator = self._object_integrator()
        pilot = self._sampler_spp(c.pilot_spp)
        camera, box = pilot_view(self.camera, self.placement.pixel_box)
        a = self._render(self.object_scene, integrator, box, pilot, c.seed + 101, camera)
        b = self._render(self.object_scene, integrator, box, pilot, c.seed + 202, camera)
        covered = (a[..., 3] > 0.999) & (b[..., 3] > 0.999)
        self.timings["pilot"] = time.perf_counter() - t0
        if not covered.any():
            return c.max_spp, {"spp": c.max_spp, "from": "max_spp (the pilot saw no fully covered pixel)"}
        da = linear_to_srgb(np.clip(a[..., :3], 0, 1))[covered]
        db = linear_to_srgb(np.clip(b[..., :3], 0, 1))[covered]
        noise = float(np.sqrt(np.mean((da - db) ** 2) / 2))
        wanted = math.ceil(pilot * (noise / c.noise_target) ** 2)
        spp = self._sampler_spp(int(np.clip(wanted, c.min_spp, c.max_spp)))
        return spp, {"spp": spp, "from": "noise target", "noise_target": c.noise_target,
                     "pilot_spp": pilot, "pilot_noise": round(noise, 5), "wanted_spp": wanted,
                     "predicted_raw_noise": round(noise * math.sqrt(pilot / spp), 5),
                     "limits": [c.min_spp, c.max_spp]}

    # -- step ---------------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return len(self.images) == len(self.passes)

    def step(self) -> dict:
        """Render the next pass; returns its name and seconds."""
        check_cancel(self.cancel)
        name = self.passes[len(self.images)]
        t0 = time.perf_counter()
        seed = self.config.seed
        if name == "object":
            image = self._render(self.object_scene, self._object_integrator(), self.object_window, self.spp, seed)
        else:
            mesh = self.mesh if name == "floor_with_object" else None
            scene = _scene(self.mi, self.envmap, mesh, None, black=True, floor_albedo=self.config.floor_albedo)
            # Direct light is exact here: a lone plane under a distant light has no inter-reflection, and
            # the black object reflects nothing. The albedo AOV says which samples met the floor.
            integrator = self.mi.load_dict({"type": "aov", "aovs": "albedo:albedo",
                                            "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True}})
            image = self._render(scene, integrator, self.floor_window, self.spp, seed, self.floor_camera)
        self.images[name] = image
        seconds = time.perf_counter() - t0
        self.timings[name] = seconds
        emit(self.progress, "compose", len(self.images), len(self.passes), f"{name} pass, {self.spp} spp")
        return {"pass": name, "seconds": seconds}

    # -- finish -------------------------------------------------------------------------------------
    def _full(self, crop: np.ndarray, window: tuple[int, int, int, int], fill: float,
              shape: tuple[int, int] | None = None) -> np.ndarray:
        h, w = shape or self.photo.shape[:2]
        x0, y0, x1, y1 = window
        out = np.full((h, w) + crop.shape[2:], fill, np.float32)
        out[y0:y1, x0:x1] = crop
        return out

    def _object_layers(self) -> tuple[np.ndarray, np.ndarray]:
        image = self.images["object"]
        rgb, alpha = image[..., 0:3], image[..., 3]
        if self.denoiser == "oidn":
            t0 = time.perf_counter()
            rgb = denoise(rgb, image[..., 4:7], image[..., 7:10])
            rgb = np.where(alpha[..., None] > 0, np.maximum(rgb, 0.0), 0.0)  # no light where there is no object
            self.timings["denoise_object"] = time.perf_counter() - t0
        return self._full(rgb, self.object_window, 0.0), self._full(alpha, self.object_window, 0.0)

    def _floor_radiance(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Mean radiance of the samples that met the floor, and the pixels mostly floor. The albedo AOV
        averages floor_albedo over floor samples and 0 over the black object and the sky."""
        image = self.images[name]
        free = np.clip(image[..., 4] / self.config.floor_albedo, 0.0, 1.0)
        radiance = np.where(free[..., None] > 1e-3, image[..., :3] / np.maximum(free[..., None], 1e-3), 0.0)
        return radiance.astype(np.float32), free > 0.5

    def _ratio_matte(self) -> np.ndarray:
        import cv2  # lazy: Blender may lack OpenCV (missing_modules)

        with_object, _ = self._floor_radiance("floor_with_object")
        without, _ = self._floor_radiance("floor_without_object")
        # Where the asset hides the floor entirely its shadow there is unseen (and covered): keep 1.
        seen = (self.images["floor_with_object"][..., 4:5] > 1e-3 * self.config.floor_albedo)
        raw = np.where((without > 0) & seen, with_object / np.where(without > 0, without, 1.0), 1.0)
        # Where the object changed no sample, both passes are identical: keep those pixels exactly 1.
        same = (self.images["floor_with_object"] == self.images["floor_without_object"]).all(axis=-1)
        raw = np.clip(np.where(same[..., None], 1.0, raw), 0.0, 1.0).astype(np.float32)
        touched = (raw < 1.0).any(axis=-1)
        if self.denoiser == "oidn" and touched.any():
            t0 = time.perf_counter()
            region = cv2.dilate(touched.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
            ys, xs = np.nonzero(region)
            sl = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
            smooth = np.clip(denoise(raw[sl], hdr=False), 0.0, 1.0)
            out = raw.copy()
            out[sl] = np.where(region[sl][..., None], smooth, raw[sl])
            raw = out
            self.timings["denoise_shadow"] = time.perf_counter() - t0
        faint = (raw >= 1.0 - self.config.matte_tolerance).all(axis=-1, keepdims=True)
        self.decisions["shadow_pixels"] = int((~faint[..., 0]).sum())
        return np.where(faint, 1.0, raw).astype(np.float32)

    def _paper_matte(self) -> np.ndarray:
        radiance, floor = self._floor_radiance("floor_with_object")
        if self.denoiser == "oidn" and floor.any():
            t0 = time.perf_counter()
            radiance = denoise(radiance)
            self.timings["denoise_shadow"] = time.perf_counter() - t0
        import torch  # lazy: torch takes seconds to load

        if not floor.any():
            return np.ones(radiance.shape, np.float32)
        matte, threshold, lit_mean, shadowed = paper_shadow_matte(torch.from_numpy(radiance @ LUMINANCE),
                                                                  torch.from_numpy(floor), self.config.paper_threshold)
        self.decisions["paper"] = {"threshold": threshold, "lit_mean": lit_mean}
        self.decisions["shadow_pixels"] = int(shadowed.sum())
        return np.repeat(matte.numpy().astype(np.float32)[..., None], 3, axis=-1)

    def matte(self) -> np.ndarray:
        """(h, w, 3) shadow multiplier over the whole photo, 1 where the floor is untouched (or not rendered)."""
        if not all(name in self.images for name in self.passes if name != "object"):
            raise RuntimeError("matte() before the floor passes ran.")
        if "floor_with_object" not in self.images:
            return np.ones(self.photo.shape[:2] + (3,), np.float32)
        crop = self._ratio_matte() if self.config.shadow_type == "ratio" else self._paper_matte()
        return self._photo_sized(self._full(crop, self.floor_window, 1.0,
                                            (self.floor_camera.height, self.floor_camera.width)))

    def _photo_sized(self, matte: np.ndarray) -> np.ndarray:
        """The floor passes' matte scaled up to the photo (bilinear: shadows are soft), with pixels the
        shadow does not reach exactly 1 again, so the photo stays untouched there."""
        import cv2  # lazy: Blender may lack OpenCV (missing_modules)

        h, w = self.photo.shape[:2]
        if matte.shape[:2] == (h, w):
            return matte
        t0 = time.perf_counter()
        big = cv2.resize(matte, (w, h), interpolation=cv2.INTER_LINEAR)
        big = np.where(big >= 1.0 - 1e-5, 1.0, np.clip(big, 0.0, 1.0)).astype(np.float32)
        self.decisions["shadow_pixels"] = int((big < 1.0).any(axis=-1).sum())
        self.timings["matte_upsample"] = time.perf_counter() - t0
        return big

    def finish(self) -> ComposeResult:
        if not self.done or "object" not in self.images:
            raise RuntimeError(f"finish() before every pass ran ({len(self.images)} of {len(self.passes)}).")
        t0 = time.perf_counter()
        object_rgb, alpha = self._object_layers()
        matte = self.matte()
        photo_linear = srgb_to_linear(self.photo).astype(np.float32)
        changed = (alpha > 0) | (matte < 1.0).any(axis=-1)
        # Only the box of changed pixels is computed: elsewhere the composite is the photo, exactly.
        composite, display = photo_linear.copy(), np.array(self.photo, dtype=np.float32)
        if changed.any():
            ys, xs = np.nonzero(changed.any(axis=1))[0], np.nonzero(changed.any(axis=0))[0]
            box = (slice(ys[0], ys[-1] + 1), slice(xs[0], xs[-1] + 1))
            inside = changed[box][..., None]
            mixed = composite_linear(object_rgb[box], alpha[box][..., None], photo_linear[box], matte[box])
            composite[box] = np.where(inside, mixed, photo_linear[box])
            display[box] = np.where(inside, linear_to_srgb(np.clip(composite[box], 0.0, 1.0)), display[box])
        self.timings["finish"] = time.perf_counter() - t0
        report = {
            "stage": "compose",
            "config": asdict(self.config),
            "camera": {**asdict(self.camera), "position_camera_heights": camera_origin().tolist(),
                       "position_m": [0.0, 0.0, ASSUMED_CAMERA_HEIGHT_M]},
            "placement": self.placement.report(),
            "size": {"fraction_of_photo_height": self.config.size, "height_m": round(self.placement.height
                                                                                      * ASSUMED_CAMERA_HEIGHT_M, 3)},
            "spp": self.spp, "sampler": self.config.sampler_type,
            "denoiser": self.denoiser_why,
            "exposure": {"factor": self.config.exposure,
                         "why": "the light map is in the photo's exposure (scenefit light), so the render and the "
                                "photo share units" if self.config.exposure == 1.0 else "given"},
            "shadow": {"type": self.config.shadow_type if self.placement.on_floor else "none",
                       "floor_pass": self.decisions["floor_pass"], "pixels": self.decisions.get("shadow_pixels", 0),
                       **({"paper": self.decisions["paper"]} if "paper" in self.decisions else {})},
            "decisions": {"spp": self.decisions["spp"]},
            "composite_size": [int(self.photo.shape[1]), int(self.photo.shape[0])],   # config.max_side bounds it
            "changed_pixels": int(changed.sum()),
            "render_windows": {"object": list(self.object_window),
                               **({"floor": list(self.floor_window),
                                   "floor_size": [self.floor_camera.width, self.floor_camera.height]}
                                  if "floor_with_object" in self.images else {})},
            "mitsuba_variant": self.backend.variant,
            "timings_seconds": {k: round(v, 3) for k, v in self.timings.items()},
        }
        return ComposeResult(composite, display, object_rgb, alpha, matte, changed, self.placement, report)


# The pilot measures the noise of a pixel, which barely depends on the pixel's size: the asset's whole
# box seen through the same camera with fewer, larger pixels (at most this many on its long side) is
# enough, where a 12 MP photo's asset spans ~1500 px.
PILOT_MAX_SIDE = 256


def pilot_view(camera: PhotoCamera, box: tuple[int, int, int, int], side: int = PILOT_MAX_SIDE
               ) -> tuple[PhotoCamera, tuple[int, int, int, int]]:
    """(camera, box): `camera` with its pixels k times larger and `box` (x0, y0, x1, y1) in them, so the
    box is at most `side` pixels on its long side (k = 1 when it already is)."""
    x0, y0, x1, y1 = box
    k = max(1, -(-max(x1 - x0, y1 - y0) // side))
    if k == 1:
        return camera, box
    small = replace(camera, width=max(1, camera.width // k), height=max(1, camera.height // k))
    x1, y1 = min(-(-x1 // k), small.width), min(-(-y1 // k), small.height)
    return small, (min(x0 // k, x1 - 1), min(y0 // k, y1 - 1), x1, y1)


def build_compose(inputs: ComposeInputs, config: ComposeConfig = ComposeConfig(),
                  progress: ProgressCallback | None = None, cancel: threading.Event | None = None) -> ComposeJob:
    return ComposeJob(inputs, config, progress, cancel)


def shadow_matte(inputs: ComposeInputs, config: ComposeConfig,
                 cancel: threading.Event | None = None) -> tuple[np.ndarray, ObjectPlacement]:
    """Only the floor passes: the (h, w, 3) shadow matte of the placed asset and the placement. The
    asset is black in those passes, so inputs.maps are not read."""
    job = ComposeJob(inputs, config, cancel=cancel, object_pass=False)
    while not job.done:
        job.step()
    return job.matte(), job.placement


def compose(inputs: ComposeInputs, config: ComposeConfig = ComposeConfig(), progress: ProgressCallback | None = None,
            cancel: threading.Event | None = None) -> ComposeResult:
    t0 = time.perf_counter()
    job = build_compose(inputs, config, progress, cancel)
    while not job.done:
        job.step()
    result = job.finish()
    result.report["seconds"] = round(time.perf_counter() - t0, 3)
    return result


def write_compose(result: ComposeResult, folder, extra: dict | None = None) -> dict:
    """The stage's files in `folder`: composite.png (sRGB, the photo's size), composite.exr (linear),
    layers/object_rgba.png (16-bit, straight alpha), layers/shadow.png (16-bit matte, 1 = untouched), and
    report.json (`extra` over the result's report); returns the report."""
    report = {**result.report, **(extra or {})}
    report["outputs"] = _write_images(result, Path(folder))
    write_json_atomic(Path(folder) / "report.json", report)
    return report


def _write_images(result: ComposeResult, out) -> dict[str, str]:
    alpha = result.alpha[..., None]
    straight = np.where(alpha > 0, result.object_rgb / np.maximum(alpha, 1e-8), 0.0)
    rgba = np.concatenate([linear_to_srgb(np.clip(straight, 0.0, 1.0)), alpha], axis=-1)
    files = {
        "composite_png": (out / "composite.png", result.composite_srgb, "uint8"),
        "composite_exr": (out / "composite.exr", result.composite_linear, "float"),
        "object_rgba_png": (out / "layers" / "object_rgba.png", rgba, "uint16"),
        "shadow_png": (out / "layers" / "shadow.png", result.matte, "uint16"),
    }
    # At a 12 MP photo's size each file takes a second or two to compress; OpenImageIO compresses
    # without holding Python's lock, so the four are written at once.
    with ThreadPoolExecutor(max_workers=len(files)) as pool:
        written = {key: pool.submit(write_image, path, pixels, dtype) for key, (path, pixels, dtype) in files.items()}
        return {key: str(job.result()) for key, job in written.items()}


def compose_to_folder(inputs: ComposeInputs, config: ComposeConfig, out_dir, report_extra: dict | None = None,
                      progress: ProgressCallback | None = None, cancel: threading.Event | None = None) -> dict:
    """compose() then write_compose() into out_dir; returns the report."""
    result = compose(inputs, config, progress, cancel)
    check_cancel(cancel)
    return write_compose(result, out_dir, report_extra)
