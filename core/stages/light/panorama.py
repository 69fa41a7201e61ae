"""The LDR environment map: the photo unwrapped around the object (indoors) or warped into the sky (outdoors).

Map convention (the one the renderer and Blender share, see `core/render/renderer.py`): latitude-longitude,
twice as wide as high, rows top (+Z, zenith) to bottom (-Z, nadir); the column at u = 0.5 looks
along world +X and u = 0.25 along +Y, exactly Blender's equirectangular Environment Texture
(checked against Cycles in tests/blender/test_lighting_blender.py):

    u = 0.5 - atan2(d.y, d.x) / 2pi,        v_top = 0.5 - atan2(d.z, hypot(d.x, d.y)) / pi

so `blender_direction_to_equirect_uv` maps a world direction to the texel that lights the asset
from that direction in Mitsuba (through `ENVMAP_TO_WORLD`) and in Blender (World > Environment
Texture > Background, no Mapping node, default vector).

Geometry (indoors): the photo camera stands at (0, 0, h) above a floor z = 0 (h = 1: only ratios
matter), looking along `PhotoCamera.yaw/pitch`. The object stands on the floor where the ray
through the placement pixel meets it. Each photo pixel is lifted to 3D with its distance along
the ray, the origin moved to the object (ORIGIN_LIFT above the floor point), and the point splatted into the map (the nearest point
wins a texel). Holes are filled with cv2.inpaint, small isolated splats removed with
cv2.morphologyEx, and what the photo never saw (behind the camera) takes the photo's mean colour.

Values are the photo's, sRGB-encoded in [0, 1]; `srgb_to_linear` gives radiance in photo units.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...base.errors import InputError
from ...scene.camera import CAMERA_HEIGHT, PhotoCamera
from ...scene.floor import ORIGIN_LIFT, FloorPoint
from ...scene.frame import blender_direction_to_equirect_uv, equirect_directions


@dataclass
class Panorama:
    """An LDR map (sRGB-encoded, (H, 2H, 3) float32 in [0, 1]) and how each texel got its value."""

    ldr: np.ndarray
    distance: np.ndarray          # (H, W) distance from the object to the surface seen; inf where unknown
    seen: np.ndarray              # (H, W) bool: value splatted or warped from the photo
    inpainted: np.ndarray         # (H, W) bool: hole filled by cv2.inpaint
    unseen: np.ndarray            # (H, W) bool: outside what the photo saw -> mean colour / sky-ground prior
    decisions: dict = field(default_factory=dict)
    painted: bool = False         # the unseen part was painted by a model: its bright texels are lights it drew


HIGHLIGHT_LEVEL = 0.95             # clipped (the far-light threshold tau_f)
HIGHLIGHT_DEPTH_TOLERANCE = 1.05   # "on the nearest surface": within 5% of its distance


def splat(colors: np.ndarray, points: np.ndarray, origin: np.ndarray, height: int) -> tuple[np.ndarray, ...]:
    """Splat 3D points with colours into an (height, 2 height) map seen from `origin`; nearest point wins."""
    width = 2 * height
    rel = points.reshape(-1, 3) - origin
    dist = np.linalg.norm(rel, axis=-1)
    ok = np.isfinite(dist) & (dist > 1e-9)
    rel, dist, cols = rel[ok], dist[ok], colors.reshape(-1, colors.shape[-1])[ok]
    uv = blender_direction_to_equirect_uv(rel)
    col_idx = np.minimum((uv[:, 0] * width).astype(np.int64), width - 1)
    row_idx = np.clip((uv[:, 1] * height).astype(np.int64), 0, height - 1)
    texel = row_idx * width + col_idx
    order = np.lexsort((dist, texel))           # by texel, then nearest first
    starts, counts = np.unique(texel[order], return_index=True, return_counts=True)[1:]
    first = order[starts]
    # A clipped highlight (a lamp smaller than a texel) on the texel's nearest surface wins the texel,
    # so small lights are not lost to a neighbouring sample that happens to be nearer.
    level = cols[order, :3].mean(axis=-1)
    front = dist[order] <= HIGHLIGHT_DEPTH_TOLERANCE * np.repeat(dist[first], counts)
    bright = np.flatnonzero(front & (level >= HIGHLIGHT_LEVEL))
    if bright.size:
        group = np.repeat(np.arange(len(starts)), counts)[bright]
        groups, pick = np.unique(group, return_index=True)
        first = first.copy()
        first[groups] = order[bright[pick]]
    image = np.zeros((height * width, cols.shape[1]), np.float32)
    distance = np.full(height * width, np.inf, np.float32)
    mask = np.zeros(height * width, bool)
    image[texel[first]] = cols[first]
    distance[texel[first]] = dist[first]
    mask[texel[first]] = True
    return image.reshape(height, width, -1), distance.reshape(height, width), mask.reshape(height, width)


def _kernel(size: float):
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    size = max(3, int(size) | 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def _wrap(image: np.ndarray, pad: int) -> np.ndarray:
    """Pad columns by wrapping (the map is periodic in u) so filters see across the seam."""
    return np.concatenate([image[:, -pad:], image, image[:, :pad]], axis=1)


def fill_panorama(ldr: np.ndarray, seen: np.ndarray, fill_color: np.ndarray,
                  close_fraction: float = 1 / 24, open_fraction: float = 1 / 48,
                  inpaint_radius: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fill holes inside what the photo covers; everything else takes `fill_color`.

    1. MORPH_CLOSE of the splat mask (kernel `close_fraction` of the map width) gives the covered area
       with its small holes; 2. MORPH_OPEN (kernel `open_fraction`) removes small isolated islands;
    3. cv2.inpaint (Telea) fills the holes inside the covered area, per channel in 16 bits;
    4. the rest (behind the camera, gaps too large to be holes) gets `fill_color`.
    Returns (filled, kept_seen, inpainted, unseen) with every texel assigned a finite value.
    """
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    h, w = seen.shape
    pad = max(4, w // 8)
    seen_u8 = _wrap(seen.astype(np.uint8), pad)
    covered = cv2.morphologyEx(seen_u8, cv2.MORPH_CLOSE, _kernel(w * close_fraction))
    covered = cv2.morphologyEx(covered, cv2.MORPH_OPEN, _kernel(w * open_fraction))
    covered = covered[:, pad:pad + w].astype(bool)
    kept = seen & covered
    holes = covered & ~seen
    out = np.empty_like(ldr, dtype=np.float32)
    out[...] = np.asarray(fill_color, np.float32)
    out[kept] = ldr[kept]
    if holes.any():
        src = _wrap(np.where(kept[..., None], ldr, 0.0).astype(np.float32), pad)
        # Texels outside the covered area must not bleed in: inpaint from kept texels only, so the
        # unknown outside is masked too and then reset.
        unknown = _wrap((~kept).astype(np.uint8), pad)
        # 16-bit per channel: OpenCV's Telea is biased on float32 input (0.4 fills as 1.2), exact on uint16.
        src16 = np.round(np.clip(src, 0.0, 1.0) * 65535.0).astype(np.uint16)
        for c in range(ldr.shape[2]):
            filled = cv2.inpaint(np.ascontiguousarray(src16[..., c]), unknown, inpaint_radius, cv2.INPAINT_TELEA)
            out[..., c][holes] = filled[:, pad:pad + w][holes].astype(np.float32) / 65535.0
    unseen = ~covered
    return np.clip(out, 0.0, 1.0), kept, holes, unseen


def keep_highlights(photo: np.ndarray, reduced: np.ndarray, level: float = 0.95) -> np.ndarray:
    """A reduced photo in which a clipped highlight smaller than one reduced pixel survives.

    Area-averaging a lamp of a few pixels (or a 1e6 spot in an EXR, clipped at exposure) with its
    dark surroundings would bring it under the light thresholds, and no light would be found; a
    reduced pixel whose footprint holds a clipped pixel keeps the brightest colour there instead.
    """
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    h, w = photo.shape[:2]
    rh, rw = reduced.shape[:2]
    peak = photo[..., :3].mean(axis=-1)
    if peak.max() < level:
        return reduced
    ky, kx = int(np.ceil(h / rh)), int(np.ceil(w / rw))
    brightest = cv2.dilate(photo, np.ones((ky, kx), np.uint8))          # per channel, over each footprint
    lit = cv2.dilate((peak >= level).astype(np.uint8), np.ones((ky, kx), np.uint8))
    # Sample both at the reduced pixels' centres.
    ys = np.minimum(((np.arange(rh) + 0.5) * h / rh).astype(int), h - 1)
    xs = np.minimum(((np.arange(rw) + 0.5) * w / rw).astype(int), w - 1)
    lit_r = lit[np.ix_(ys, xs)].astype(bool)
    return np.where(lit_r[..., None], brightest[np.ix_(ys, xs)], reduced).astype(np.float32)


def _resize_for_splat(photo: np.ndarray, distance: np.ndarray, long_side: int) -> tuple[np.ndarray, np.ndarray]:
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    h, w = photo.shape[:2]
    scale = long_side / max(h, w)
    size = (max(2, round(w * scale)), max(2, round(h * scale)))
    photo_r = cv2.resize(photo, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    if scale < 1:
        photo_r = keep_highlights(photo, photo_r)
    # Distances are interpolated in inverse (smooth across depth edges, never invents far points).
    inv = cv2.resize(1.0 / np.maximum(distance, 1e-6), size, interpolation=cv2.INTER_LINEAR)
    return photo_r, (1.0 / np.maximum(inv, 1e-9)).astype(np.float32)


def indoor_panorama(photo: np.ndarray, ray_distance: np.ndarray, camera: PhotoCamera, placement: FloorPoint,
                    height: int = 128, splat_long_side: int | None = None,
                    height_above_floor: float = CAMERA_HEIGHT) -> Panorama:
    """Unwrap the photo around the object using its per-pixel distance along the camera rays.

    photo: (h, w, 3) sRGB-encoded in [0, 1]; ray_distance: (h, w) distances along each pixel's ray in
    the camera-height unit (see `depth.py`). The photo is resampled before splatting so that, seen from
    the camera, about 6 photo samples fall on each map texel (at least 96, at most 768 on the long side).
    """
    if photo.shape[:2] != ray_distance.shape:
        raise InputError(f"Photo {photo.shape[:2]} and depth {ray_distance.shape} differ in size.")
    long_side = splat_long_side or int(np.clip(6 * 2 * height * camera.fov_deg / 360.0, 96, 768))
    photo_r, dist_r = _resize_for_splat(photo.astype(np.float32), ray_distance.astype(np.float32), long_side)
    cam_r = replace(camera, width=photo_r.shape[1], height=photo_r.shape[0])   # its roll and shift kept
    dirs = cam_r.ray_directions()
    origin = np.array([0.0, 0.0, height_above_floor])
    points = origin + dirs * dist_r[..., None]
    # Seen from a point just above the floor (ORIGIN_LIFT camera heights), so the floor lies strictly
    # below the horizon instead of straddling it by rounding.
    centre = placement.object_position + np.array([0.0, 0.0, ORIGIN_LIFT * height_above_floor])
    image, distance, seen = splat(photo_r, points, centre, height)
    mean_color = photo.reshape(-1, 3).mean(axis=0)
    ldr, kept, holes, unseen = fill_panorama(image, seen, mean_color)
    # Holes take the nearest surface around them (a min filter over the closing kernel); unseen stays inf.
    import cv2

    finite = np.where(kept, distance, 1e30).astype(np.float32)
    pad = max(4, 2 * height // 8)
    nearest = cv2.erode(_wrap(finite, pad), _kernel(2 * height / 24 * 2))[:, pad:pad + 2 * height]
    distance = np.where(kept, distance, np.where(holes & (nearest < 1e29), nearest, np.inf)).astype(np.float32)
    return Panorama(ldr.astype(np.float32), distance, kept, holes, unseen, {
        "scene_type": "indoor",
        "splat_samples": int(photo_r.shape[0] * photo_r.shape[1]),
        "seen_fraction": round(float(kept.mean()), 4),
        "inpainted_fraction": round(float(holes.mean()), 4),
        "mean_colour_fraction": round(float(unseen.mean()), 4),
        "mean_colour_srgb": np.round(mean_color, 4).tolist(),
    })


def outdoor_panorama(photo: np.ndarray, camera: PhotoCamera, height: int = 128,
                     feather_fraction: float = 1 / 32, outpaint=None) -> Panorama:
    """Warp the photo into its place on the map (the sun is far: the object's offset is ignored) and
    complete the rest with a sky/ground prior fitted to the photo, feathered across the seam.

    outpaint: optional `outpaint(map, seen) -> map` (outpaint.py's SD2 outpainting) that repaints the
    unseen part of the map (the warped photo over the prior) and keeps the seen texels; the photo's
    region then stays exactly the photo.

    The prior, per map row: above the horizon, the photo's mean colour in the nearest rows that hold
    sky, blended towards the brightest tenth of the photo's upper part at the zenith; below it, the mean
    colour of the photo's lower part (see `sky_ground_prior`).
    """
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    width = 2 * height
    dirs = equirect_directions(height, width)
    sx, sy, z = camera.image_xy(dirs)
    inside = (z > 1e-6) & (np.abs(sx) <= 1) & (np.abs(sy) <= 1)
    h, w = photo.shape[:2]
    map_x = np.where(inside, (sx + 1) / 2 * w - 0.5, -1).astype(np.float32)
    map_y = np.where(inside, (1 - sy) / 2 * h - 0.5, -1).astype(np.float32)
    warped = cv2.remap(photo.astype(np.float32), map_x, map_y, interpolation=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    prior = sky_ground_prior(warped, inside)
    completion = "sky/ground prior fitted to the photo (no outpainting model)"
    if outpaint is not None:
        prior = outpaint(np.where(inside[..., None], warped, prior).astype(np.float32), inside)
        completion = "outpainted by the Stable Diffusion 2 inpainting model (over the sky/ground prior)"
    # Feather the photo's border into the prior over a few texels (seam-aware: wrap in u).
    pad = max(4, width // 8)
    feather = max(1.0, width * feather_fraction)
    dist_in = cv2.distanceTransform(_wrap(inside.astype(np.uint8), pad), cv2.DIST_L2, 3)[:, pad:pad + width]
    alpha = np.clip(dist_in / feather, 0.0, 1.0)[..., None]
    ldr = np.clip(alpha * warped + (1 - alpha) * prior, 0.0, 1.0).astype(np.float32)
    return Panorama(ldr, np.full((height, width), np.inf, np.float32), inside, np.zeros_like(inside), ~inside, {
        "scene_type": "outdoor",
        "seen_fraction": round(float(inside.mean()), 4),
        "completion": completion,
    }, painted=outpaint is not None)


def sky_ground_prior(warped: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Per-row colours: known rows take the mean of the photo in that row; unknown sky rows blend from the
    nearest known sky row to a zenith colour (the brightest tenth of the photo's sky); unknown ground rows
    take the mean of the photo's ground."""
    height, width = inside.shape
    horizon = height // 2
    rows = np.zeros((height, 3), np.float32)
    known = inside.sum(axis=1) > 0
    for r in np.nonzero(known)[0]:
        rows[r] = warped[r][inside[r]].mean(axis=0)
    sky_pixels = warped[:horizon][inside[:horizon]]
    ground_pixels = warped[horizon:][inside[horizon:]]
    all_pixels = warped[inside] if inside.any() else np.full((1, 3), 0.5, np.float32)
    if len(sky_pixels) == 0:
        sky_pixels = all_pixels
    if len(ground_pixels) == 0:
        ground_pixels = all_pixels
    lum = sky_pixels.mean(axis=1)
    zenith = sky_pixels[lum >= np.quantile(lum, 0.9)].mean(axis=0)
    ground = ground_pixels.mean(axis=0)
    known_sky = [r for r in range(horizon) if known[r]]
    top_known = min(known_sky) if known_sky else horizon
    for r in range(horizon):
        if known[r]:
            continue
        if r < top_known:
            t = r / max(top_known, 1)
            start = rows[top_known] if known_sky else sky_pixels.mean(axis=0)
            rows[r] = (1 - t) * zenith + t * start
        else:
            near = min(known_sky, key=lambda k: abs(k - r)) if known_sky else None
            rows[r] = rows[near] if near is not None else zenith
    for r in range(horizon, height):
        if not known[r]:
            rows[r] = ground
    return np.broadcast_to(rows[:, None, :], (height, width, 3)).copy()

