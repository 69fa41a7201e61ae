"""Weight-free cues for the light scales and the unseen part of the map (issue 11).

The paper's pipeline stays: LDR panorama -> bright regions -> one scale per region. These cues give
the scales a physical starting point instead of one global inverse-tone-mapping prior, and give the
part of the map the photo never saw a level and a direction. Each can be switched off (CueConfig)
and the report records which were used and each region's share of the map's power.

- exposure (clipped texels): an auto-exposed photo maps its log-average luminance to mid-grey
  (0.18). The unclipped pixels keep their values, so the clipped ones must hold the rest of the
  log-average: that fixes their geometric-mean radiance (`exposure_clip_scale`), a lower bound on
  their mean. Clipped texels of the upper hemisphere become their own region "clipped" with that
  scale; bright texels that did not clip, and clipped ones below the horizon (a white floor or a lit
  table is a surface the lights light, not a light), keep their stored radiance (scale 1). A photo more than 3 stops darker than
  mid-grey was not metered that way (night, kept dark): its clipped texels then get the power the
  surfaces call for (below), spread over their solid angle, so a dark scene stays dark.
  The equation multiplies a metering error by 1/f (f: the clipped fraction; 150x at f = 0.6%,
  and cameras also meter by the median, which says nothing about clipped pixels), so its answer
  is trusted by `exposure_weight(f)` (log-space shrink, when f is small, towards the surface prior:
  the clipped texels carry the power the surfaces call for)
  and bounded by what the photo supports (`bound_scales`): the map's mean radiance stays within
  `mean_bound` (4x) of the mean the photo's exposure implies: the flat environment that lights its
  surfaces as they appear (S / albedo), and at least the photo's own mean radiance.
- surface energy (unseen upper hemisphere): the photo's surfaces (texels below the near-light
  threshold, mean linear radiance S in photo exposure units) are lit by something. A camera-facing
  diffuse surface of albedo rho sees about half unseen light L and half ground (~S), so
  S = rho (L + S) / 2 and L = S (2 / rho - 1); rho = 0.4 by default, the report gives L for rho in
  [0.15, 0.5]. The upper hemisphere the photo did not see becomes the region "unseen" at mean L.
- lobe (direction of the unseen light): a light that is not in the photo is where the photo did
  not look: the unseen light is a cos^4 lobe (over a floor of 0.25) at the azimuth of the unseen
  upper hemisphere's centroid (behind the camera), turned towards the side of the photo that is
  brighter (`photo_bright_side`: walls fall off away from a lamp, the sky brightens towards the
  sun), 35 deg up (real lights sit low); or along the artist's `sun` when given, as a narrower lobe
  (cos^8 over 0.05): a known direction need not hedge; one known only roughly (a short shadow's
  clicks: shadow_hint.sun_uncertainty_deg) widens to the guess's lobe as its uncertainty goes from
  SURE_DEG to UNSURE_DEG (`sun_lobe`). Front or behind
  is not decided from the photo: the sky's rise from its horizon to its top called it on 18 of the
  corpus's 24 real views but on 28 of Blender's 48 (always-front: 30), the ground/sky ratio on at
  best 14 of 24 and 23 of 38; a guess at chance moves the lobe's error from 90 to 180 deg.
  Only the photo's clipped pixels (and a model's painted ones) are lights the exposure cue speaks
  for; a fill's bright texels in the unseen upper hemisphere belong to the unseen light.

    build_cues(photo, ldr, unseen, regions, thresholds, config) -> Cues (LDR, regions, scales, report)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...base.errors import InputError
from ...data.imageio import linear_to_srgb, srgb_to_linear
from ...scene.camera import PhotoCamera
from ...scene.frame import equirect_directions
from .regions import RegionThresholds, intensity

LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)


@dataclass(frozen=True)
class CueConfig:
    # Mean albedo of the photo's surfaces (energy cue). 0.4: at 0.25 the unseen light was ~2x too bright
    # on the corpus's real views (map mean 4x off on 15 of 48 photos, 11 at 0.4). 0.25 for outdoor photos
    # only suits Blender's city and forest but loses on the real views and 3 of 4 held-out maps (benchmarks/FINDINGS.md).
    albedo: float = 0.4
    albedo_range: tuple[float, float] = (0.15, 0.5)   # reported as the bound on the unseen light
    lobe_sharpness: float = 4.0        # cos^k lobe of the unseen light around its centroid direction
    lobe_floor: float = 0.25           # the lobe's lowest value (relative), so no unseen texel is black
    # The artist's sun (--sun, the shadow pick) is a known direction, not a guess to hedge: its lobe is
    # narrower and its floor lower. Hinted, on the corpus's 24 real views, the matte sphere's si-RMSE
    # median falls to 22% / 30% below the constant's (median / log-average metering) from 14% / 16% with
    # the guess's lobe; unhinted, the same lobe loses 2-3 of 13-14 both-wins (benchmarks/FINDINGS.md, light on real photos).
    sun_lobe_floor: float = 0.05
    sun_lobe_sharpness: float = 8.0
    mean_bound: float = 4.0            # the map's mean radiance stays within this factor of the photo's mean
    metering_error: float = 0.01       # log-units error of the metering that `exposure_weight` tolerates
    use_exposure: bool = True          # the cues can be switched off one by one (the bench's ablation)
    use_energy: bool = True
    use_lobe: bool = True
    clipped_level: float = 0.98        # stored (sRGB) intensity at which a texel counts as clipped
    key: float = 0.18                  # the photo's metering: log-average luminance -> this (mid-grey)

    def __post_init__(self) -> None:
        if not 0.01 <= self.albedo <= 1.0:
            raise InputError(f"albedo must be in [0.01, 1], got {self.albedo}.")
        if not all(0.0 <= f <= 1.0 for f in (self.lobe_floor, self.sun_lobe_floor)) \
                or min(self.lobe_sharpness, self.sun_lobe_sharpness) < 0:
            raise InputError("lobe_floor and sun_lobe_floor must be in [0, 1], lobe_sharpness and "
                             "sun_lobe_sharpness >= 0.")
        if not self.mean_bound > 1.0 or not self.metering_error > 0.0:
            raise InputError(f"mean_bound must be above 1 and metering_error positive, got {self.mean_bound} and "
                             f"{self.metering_error}; use the defaults (4 and 0.01).")


@dataclass
class Cues:
    ldr: np.ndarray                         # the panorama with the unseen lobe shaded in (sRGB)
    regions: dict[str, np.ndarray]          # the bright regions plus "unseen" (disjoint)
    scales: dict[str, float]
    report: dict = field(default_factory=dict)


def solid_angles(height: int, width: int) -> np.ndarray:
    """(H, 1) steradians per texel of an equirectangular map."""
    rows = (np.arange(height) + 0.5) / height
    return (np.sin(np.pi * rows) * (np.pi / height) * (2 * np.pi / width))[:, None].astype(np.float64)


def surface_radiance(photo_srgb: np.ndarray, threshold: float) -> tuple[np.ndarray, float]:
    """Mean linear RGB and level of the photo's texels below the light threshold (its lit surfaces)."""
    level = intensity(photo_srgb)
    surfaces = level < threshold
    linear = srgb_to_linear(np.asarray(photo_srgb, np.float32))
    pixels = linear[surfaces] if surfaces.mean() > 0.01 else linear.reshape(-1, 3)
    rgb = pixels.mean(axis=0).astype(np.float64)
    return rgb, float(rgb.mean())


def build_cues(photo_srgb: np.ndarray, ldr: np.ndarray, unseen: np.ndarray, regions: dict[str, np.ndarray],
               thresholds: RegionThresholds = RegionThresholds(), config: CueConfig = CueConfig(),
               camera: PhotoCamera | None = None, sun: np.ndarray | None = None,
               painted_unseen: bool = False, sun_uncertainty_deg: float = 0.0) -> Cues:
    """Scales for the bright regions and an "unseen" region (upper hemisphere the photo did not see).

    camera: the photo's camera (its right/up give the photo's bright side a world direction);
    sun: a world unit vector given by the artist, the unseen light's direction then;
    painted_unseen: a model painted the unseen part, so its bright texels are lights it drew and keep
    their regions; otherwise the unseen part is a fill (the sky prior's zenith, an edge's colour) that
    no camera measured, and all of its upper hemisphere is the unseen light;
    sun_uncertainty_deg: how far off `sun` may be (`sun_lobe`)."""
    h, w = unseen.shape
    omega = solid_angles(h, w)
    dirs = equirect_directions(h, w)
    s_rgb, s_level = surface_radiance(photo_srgb, thresholds.near)
    report: dict = {"surface_radiance": round(s_level, 5), "albedo": config.albedo}

    # Energy: the light the surfaces call for, and how much of it the map already holds.
    power = math.pi * s_level / config.albedo
    report["light_power_needed"] = round(power, 5)
    out_ldr = np.array(ldr, np.float32, copy=True)
    upper = dirs[..., 2] > 0.0
    # A fill's clipped texels (the sky prior's zenith is the photo's brightest sky, often 1.0) are not
    # lights the photo clipped: counted as such, they took the exposure cue's scale over up to 45% of
    # the map (blouberg away: mean 5.8x too bright).
    stored = intensity(ldr)
    hidden = unseen & upper & (stored < config.clipped_level) if painted_unseen else unseen & upper
    measured = np.ones((h, w), bool) if painted_unseen else ~unseen   # where a clipped texel is a light
    regions = {k: m & ~hidden for k, m in regions.items()}
    regions = {k: m for k, m in regions.items() if m.any()}
    scales: dict[str, float] = {}
    out_regions = dict(regions)

    # Clipped texels: the exposure cue gives their geometric-mean radiance; unclipped texels keep theirs.
    clip_scale, clip_info = exposure_clip_scale(photo_srgb, config.clipped_level, config.key)
    report["exposure"] = clip_info
    clipped_all = np.zeros((h, w), bool)
    for name, mask in regions.items():
        # Below the horizon a clipped texel is a lit surface (studio_small_05: the white floor, unwrapped
        # all around the object, took the lamp's scale; diffuse RMSE 0.74 against the constant's 0.22).
        clipped = mask & measured & upper & (stored >= config.clipped_level)
        clipped_all |= clipped
        rest = mask & ~clipped
        if rest.any():
            out_regions[name] = rest
            scales[name] = 1.0
        else:
            del out_regions[name]
    if clipped_all.any() and config.use_exposure:
        out_regions["clipped"] = clipped_all
        scales["clipped"], report["clipped"] = _clipped_scale(ldr, clipped_all, omega, clip_scale, clip_info,
                                                              power, config)
        report["clipped_from"] = report["clipped"]["from"]

    # The unseen light: mean radiance S / rho over the hidden upper hemisphere, as a lobe.
    if hidden.any() and config.use_energy:
        direction, report["direction"] = unseen_light_direction(photo_srgb, hidden, omega, dirs, camera, sun)
        lobe = sun_lobe(config, sun_uncertainty_deg) if sun is not None else (config.lobe_floor, config.lobe_sharpness)
        out_ldr, scales["unseen"], report["unseen"] = _unseen_light(out_ldr, hidden, omega, dirs, direction, s_level,
                                                                    config, *lobe)
        out_regions["unseen"] = hidden
    report["used"] = [name for name, on in (("exposure", config.use_exposure and "clipped" in scales),
                                            ("energy", "unseen" in scales),
                                            ("lobe", config.use_lobe and "unseen" in scales)) if on]
    scales, report["bound"] = bound_scales(out_ldr, out_regions, scales, omega, implied_mean(photo_srgb, s_level, config.albedo), config)
    report["energy_share"] = _energy_shares(out_ldr, out_regions, scales, omega)
    if "clipped" in scales:
        report["clipped"]["scale"] = round(scales["clipped"], 4)
    report["confidence"] = _confidence(report)
    return Cues(out_ldr, out_regions, scales, report)


def _unseen_light(ldr: np.ndarray, hidden: np.ndarray, omega: np.ndarray, dirs: np.ndarray, direction: np.ndarray,
                  s_level: float, config: CueConfig, floor: float, sharpness: float) -> tuple[np.ndarray, float, dict]:
    """The hidden upper hemisphere shaded as a cos^sharpness lobe around `direction` over `floor`, and the
    scale that gives it mean radiance S (2 / rho - 1): camera-facing surfaces see it and the ground
    (about S) half each."""
    h, w = hidden.shape
    weights = (omega * np.ones((1, w)))[hidden]
    lobe = np.maximum(dirs @ direction, 0.0) ** sharpness
    shade = floor + (1.0 - floor) * lobe if config.use_lobe else np.ones((h, w))
    linear = srgb_to_linear(ldr)
    linear[hidden] *= shade[hidden, None]
    out_ldr = linear_to_srgb(linear).astype(np.float32)
    target = s_level * (2.0 / config.albedo - 1.0)
    held_mean = float(np.average(srgb_to_linear(out_ldr).mean(axis=-1)[hidden], weights=weights))
    lo, hi = config.albedo_range
    return out_ldr, float(max(target / max(held_mean, 1e-12), 1e-3)), {
        "direction": np.round(direction, 4).tolist(), "lobe": {"floor": floor, "sharpness": sharpness},
        "mean_radiance": round(target, 5),
        "mean_radiance_range": [round(s_level * (2 / hi - 1), 5), round(s_level * (2 / lo - 1), 5)],
        "fraction_of_map": round(float(hidden.mean()), 4)}


# A given direction within SURE_DEG of the truth keeps most of the narrow lobe's gain; at UNSURE_DEG off it
# is no better than the guess (benchmarks/FINDINGS.md: turned 15 and 30 deg off on the corpus's views and Blender's maps).
SURE_DEG, UNSURE_DEG = 15.0, 30.0


SUN_UNSURE_ADVICE = "a longer shadow, or its tip picked closer, pins it better"


def sun_is_unsure(uncertainty_deg: float) -> bool:
    """Whether a sun given this uncertain is worth a word to the artist (as it is shown: whole degrees)."""
    return round(uncertainty_deg) > UNSURE_DEG


def sun_lobe(config: CueConfig, uncertainty_deg: float) -> tuple[float, float]:
    """(floor, sharpness) of the unseen light's lobe around the artist's direction: the narrow one for a
    sure direction, widening to the guess's as its uncertainty goes from SURE_DEG to UNSURE_DEG."""
    t = float(np.clip((uncertainty_deg - SURE_DEG) / (UNSURE_DEG - SURE_DEG), 0.0, 1.0))
    return (config.sun_lobe_floor + t * (config.lobe_floor - config.sun_lobe_floor),
            config.sun_lobe_sharpness + t * (config.lobe_sharpness - config.sun_lobe_sharpness))


def photo_bright_side(photo_srgb: np.ndarray) -> tuple[float, float]:
    """(x, y) in [-1, 1]: how far the photo's light-weighted centre sits right (x) and up (y) of its middle.

    A light out of frame brightens the side of the view nearest it (walls and floor fall off away
    from a lamp or window, the sky brightens towards the sun), so the weighted centre leans that way."""
    lum = np.maximum(srgb_to_linear(np.asarray(photo_srgb, np.float32)) @ LUMINANCE, 0.0).astype(np.float64)
    h, w = lum.shape
    xs = (np.arange(w) + 0.5) / w * 2 - 1
    ys = 1 - (np.arange(h) + 0.5) / h * 2
    total = max(float(lum.sum()), 1e-12)
    # The centre of a uniform photo is 0; a photo lit only at one edge reaches about +-1 after the x2.
    return (float(np.clip(2.0 * (lum.sum(axis=0) @ xs) / total, -1, 1)),
            float(np.clip(2.0 * (lum.sum(axis=1) @ ys) / total, -1, 1)))


SIDE_GAIN = 1.5        # how far the lobe turns towards the photo's bright side (1: 45 deg for a one-sided photo)
LOBE_ELEVATION_DEG = 35.0   # suns, lamps and windows sit low: 6-49 deg (median 28) on the corpus maps;
                            # the hidden hemisphere's centroid alone put every light at 54-66 deg


def unseen_light_direction(photo_srgb: np.ndarray, hidden: np.ndarray, omega: np.ndarray, dirs: np.ndarray,
                           camera: PhotoCamera | None, sun: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """The unseen light's direction: the artist's sun when given; else the azimuth of the hidden upper
    hemisphere's centroid (behind the camera) turned towards the side of the photo that is brighter,
    at LOBE_ELEVATION_DEG."""
    if sun is not None:
        d = np.asarray(sun, np.float64)
        return d / max(np.linalg.norm(d), 1e-12), {"from": "the artist's --sun", "vector": np.round(d, 4).tolist()}  # type: ignore[operator]
    weights = (omega * np.ones((1, hidden.shape[1])))[hidden]
    centroid = (dirs[hidden] * weights[:, None]).sum(axis=0)
    horizontal = np.array([centroid[0], centroid[1], 0.0])
    info: dict = {"from": "azimuth of the unseen upper hemisphere's centroid"}
    if camera is not None:
        right = camera.basis()[1]
        side_x, side_y = photo_bright_side(photo_srgb)
        horizontal = horizontal / max(np.linalg.norm(horizontal), 1e-12) + SIDE_GAIN * side_x * right
        info = {"from": "unseen centroid's azimuth turned towards the photo's bright side",
                "bright_side": [round(side_x, 4), round(side_y, 4)]}
    norm = np.linalg.norm(horizontal)
    if norm < 1e-9:   # the hidden part is all overhead: the light is there
        return np.array([0.0, 0.0, 1.0]), info
    el = math.radians(LOBE_ELEVATION_DEG)
    direction = np.array([*(horizontal[:2] / norm * math.cos(el)), math.sin(el)])
    info["elevation_deg"] = LOBE_ELEVATION_DEG
    return direction, info


def _clipped_scale(ldr: np.ndarray, clipped: np.ndarray, omega: np.ndarray, cue_scale: float | None,
                   cue_info: dict, power: float, config: CueConfig) -> tuple[float, dict]:
    """The clipped texels' scale: the exposure cue's, trusted by `exposure_weight`, shrunk in log space
    towards the surface prior (the clipped lights carry the power the surfaces call for); a photo not
    metered to mid-grey (kept dark) takes the surface prior alone."""
    level = srgb_to_linear(ldr).mean(axis=-1).astype(np.float64)
    stored = max(float((level * omega)[clipped].sum()), 1e-12)
    surface = max(power / stored, 1.0)
    if cue_scale is None:
        weight, source = 0.0, "surface power (the photo is not metered to mid-grey)"
    else:
        weight = exposure_weight(float(cue_info.get("clipped_fraction") or 0.0), config.metering_error)
        source = "exposure (the photo's metering), shrunk towards the surface power by its evidence weight"
    cue = max(cue_scale or 1.0, 1.0)
    scale = math.exp(weight * math.log(cue) + (1.0 - weight) * math.log(surface))
    return scale, {"from": source, "size_sr": round(float((omega * np.ones((1, ldr.shape[1])))[clipped].sum()), 5),
                   "cue_scale": round(float(cue), 4), "surface_scale": round(surface, 4),
                   "evidence_weight": round(weight, 4)}


def exposure_weight(fraction: float, metering_error: float) -> float:
    """How far the exposure cue's clipped scale is trusted (1: fully, 0: the surface prior instead).

    The cue's log-radiance moves by metering_error / f for a metering error of metering_error, so
    it is trusted while that stays well inside a factor of 2 and falls off steeply after (4th power:
    a 5% clipped window keeps 99% of it, a 0.6% speck 3%)."""
    if fraction <= 0.0:
        return 1.0
    spread = metering_error / (fraction * math.log(2.0))
    return float(1.0 / (1.0 + spread ** 4))


def implied_mean(photo_srgb: np.ndarray, surface_level: float, albedo: float) -> float:
    """The mean radiance the photo's exposure implies: a flat environment lighting its surfaces (mean
    radiance S, albedo rho) as they appear, S / rho, and never below the photo's own mean radiance."""
    return max(surface_level / albedo, float(srgb_to_linear(np.asarray(photo_srgb, np.float32)).mean()))


def bound_scales(ldr: np.ndarray, regions: dict[str, np.ndarray], scales: dict[str, float], omega: np.ndarray,
                 flat: float, config: CueConfig) -> tuple[dict[str, float], dict]:
    """Scale the lights down (clipped first, then the unseen light) until the map's mean radiance is
    within config.mean_bound of `flat` (`implied_mean`): no cue may claim more power than that."""
    level = srgb_to_linear(ldr).mean(axis=-1).astype(np.float64) * (omega * np.ones((1, ldr.shape[1])))
    total_omega = float((omega * np.ones((1, ldr.shape[1]))).sum())
    powers = {k: float(level[m].sum()) for k, m in regions.items()}
    fixed = float(level.sum()) - sum(powers.values())
    limit = config.mean_bound * max(flat, 1e-6) * total_omega
    current = fixed + sum(powers[k] * scales.get(k, 1.0) for k in powers)
    info = {"implied_mean": round(flat, 5), "mean_before": round(current / total_omega, 5),
            "limit_mean": round(limit / total_omega, 5), "bound": False}
    out = dict(scales)
    for name in ("clipped", "unseen"):
        if current <= limit or name not in out:
            continue
        excess = current - limit
        held = powers[name] * out[name]
        lowest = powers[name] * (1.0 if name == "clipped" else 1e-3)
        new = max(held - excess, lowest)
        out[name] = new / max(powers[name], 1e-30)
        current -= held - new
        info["bound"] = True
    info["mean_after"] = round(current / total_omega, 5)
    return out, info


def _confidence(report: dict) -> float:
    """0..1: how much of the estimate rests on evidence (the exposure cue's weight, no bound hit)."""
    c = 1.0
    if "clipped" in report and not report["clipped"]["from"].startswith("surface"):
        c *= 0.5 + 0.5 * report["clipped"]["evidence_weight"]
    if report["bound"]["bound"]:
        c *= 0.5
    return round(c, 3)


def _energy_shares(ldr: np.ndarray, regions: dict[str, np.ndarray], scales: dict[str, float],
                   omega: np.ndarray) -> dict[str, float]:
    """Each region's share of the map's power (radiance x solid angle), after its scale: what each cue moved."""
    level = srgb_to_linear(ldr).mean(axis=-1).astype(np.float64) * omega
    rest = np.ones(level.shape, bool)
    shares = {}
    for name, mask in regions.items():
        shares[name] = float(level[mask].sum()) * scales.get(name, 1.0)
        rest &= ~mask
    shares["rest"] = float(level[rest].sum())
    total = max(sum(shares.values()), 1e-12)
    return {k: round(v / total, 4) for k, v in shares.items()}


def exposure_clip_scale(photo_srgb: np.ndarray, clipped_level: float, key: float = 0.18,
                        metered_stops: float = 3.0) -> tuple[float | None, dict]:
    """The geometric-mean radiance of the photo's clipped pixels, from its metering.

    An auto-exposed photo maps its log-average luminance to `key` (mid-grey). The unclipped pixels
    hold their true values, so the clipped fraction f must make up the rest of the log-average:
    mean log L_clipped = (log key - (1 - f) mean log L_unclipped) / f. That is a geometric mean, a lower
    bound on the clipped region's mean (arithmetic >= geometric), so peaked sources stay underestimated.
    """
    linear = srgb_to_linear(np.asarray(photo_srgb, np.float32))
    lum = np.maximum(linear @ LUMINANCE, 1e-6).astype(np.float64)
    clipped = np.asarray(photo_srgb).max(axis=-1) >= clipped_level
    f = float(clipped.mean())
    if f == 0.0 or f == 1.0:
        return 1.0, {"clipped_fraction": f, "clipped_geometric_mean": None, "metered": None}
    # A photo kept dark on purpose (night, under-exposed by more than `metered_stops`) was not metered
    # to mid-grey: the equation would make its clipped pixels absurdly bright, so it is not used.
    stored_log_average = math.exp(float(np.log(np.minimum(lum, 1.0)).mean()))
    if stored_log_average < key * 2.0 ** -metered_stops:
        return None, {"clipped_fraction": round(f, 5), "clipped_geometric_mean": None, "metered": False,
                      "stored_log_average": round(stored_log_average, 5)}
    mean_log = (math.log(key) - (1.0 - f) * float(np.log(lum[~clipped]).mean())) / f
    value = math.exp(min(mean_log, math.log(1e6)))
    return value, {"clipped_fraction": round(f, 5), "clipped_geometric_mean": round(value, 4), "key": key,
                   "metered": True}
