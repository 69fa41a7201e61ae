"""The photo's camera, found rather than guessed: horizontal field of view, pitch, roll and horizon.

    estimate_photo_camera(photo_path, fspy_path=None) -> CameraEstimate

Each field comes from the best source that has it, best first:
  user       given by the user (CameraEstimate.overridden: a stage's --fov / --pitch / --roll);
  blender    the Blender scene's camera that shows the photo (matched by the fSpy importer or by eye);
  fspy       an fSpy project (the artist drew the vanishing lines by hand);
  exif_35mm  the 35 mm equivalent focal length (field of view only; core/data/photo.load_photo);
  exif_sensor  the focal length with the sensor width of a known camera model (field of view only);
  lines      the photo's own straight lines: segments from OpenCV's line segment detector, grouped by
             the three orthogonal (Manhattan) directions of a built scene on the Gauss sphere;
  default    what the light stage assumes without any of these (60 deg, pitch -10 deg, roll 0).
Where the lines are weak (a forest, a close-up, a smooth sky) the estimate says so in `notes` and the
field keeps its fallback, so a report never passes a guess off as a measurement. The lines' field of
view is the median of its posterior over a profile of lenses (each refitted), under a broad prior of
what photographers use: where the lines fix the focal length it is theirs; where they hardly do (one
vanishing point, or far ones) it stays near the prior's 60 deg, and its confidence, from the
posterior's width, says so. Pitch and roll are fitted at that field of view, their confidence counting
how much the lens's uncertainty could move them.

Camera coordinates inside this module: x right, y up, z forward (the view axis); image points are
normalised so that the half width is 1 (x_n = (u - W/2) / (W/2), y_n = (H/2 - v) / (W/2)) and the
ray through (x_n, y_n) is (x_n, y_n, F) with F = 1 / tan(horizontal fov / 2). The principal point is
the image centre, as in core/scene/camera.PhotoCamera.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..data.photo import load_photo
from ..scene.camera import DEFAULT_FOV_DEG, DEFAULT_PITCH_DEG, PHOTO_YAW_DEG, PhotoCamera
# The fSpy and EXIF readers live in their own modules; their names are this module's too (what callers import).
from .camera_exif import SENSOR_WIDTH_MM, exif_focal_and_model, fov_from_sensor, sensor_width_mm  # noqa: F401
from .camera_fspy import FSPY_HEADER, FSPY_MAGIC, MAX_FSPY_SIDE, read_fspy  # noqa: F401

SOURCES = ("user", "blender", "fspy", "exif_35mm", "exif_sensor", "lines", "default")
@dataclass(frozen=True)
class CameraEstimate:
    """One photo's camera. Pixel positions (horizon, vanishing points) are in the upright photo at its
    stored size, x right and y down, pixel centres at +0.5 (as PhotoCamera.project)."""

    fov_deg: float
    pitch_deg: float
    roll_deg: float
    fov_source: str
    pitch_source: str
    roll_source: str
    fov_confidence: float
    pitch_confidence: float
    roll_confidence: float
    width: int
    height: int
    horizon: tuple[tuple[float, float], tuple[float, float]]
    vanishing_points: dict = field(default_factory=dict)
    lines: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    shift_x: float = 0.0     # the lens shift (PhotoCamera's): an off-centre principal point, as fSpy solves
    shift_y: float = 0.0
    # (x1, y1, x2, y2, direction: 0 vertical, 1-2 horizontal) of the segments that point at a vanishing
    # point, for drawing over the photo; left out of to_dict/--json, which stay short.
    segments: tuple[tuple[float, float, float, float, int], ...] = field(default=(), repr=False)

    @property
    def source(self) -> str:
        """The fields' sources, best first, joined by '+' ('lines', 'exif_35mm+lines', 'default')."""
        used = {self.fov_source, self.pitch_source, self.roll_source}
        return "+".join(s for s in SOURCES if s in used)

    @property
    def fallback(self) -> bool:
        return "default" in (self.fov_source, self.pitch_source, self.roll_source)

    def photo_camera(self, yaw_deg: float = PHOTO_YAW_DEG, width: int | None = None,
                     height: int | None = None) -> PhotoCamera:
        """The camera as the stages use it (looking along +Y by default, the composition's azimuth 0)."""
        return PhotoCamera(yaw_deg=yaw_deg, pitch_deg=self.pitch_deg, fov_deg=self.fov_deg,
                           width=width or self.width, height=height or self.height, roll_deg=self.roll_deg,
                           shift_x=self.shift_x, shift_y=self.shift_y)

    def overridden(self, fov_deg: float | None = None, pitch_deg: float | None = None,
                   roll_deg: float | None = None, source: str = "user", why: str = "given by the user",
                   shift_x: float | None = None, shift_y: float | None = None) -> "CameraEstimate":
        """This estimate with the fields given (`source`, confidence 1) and its horizon moved to match;
        the vanishing points are dropped once the camera is no longer the lines'."""
        if source not in SOURCES:
            raise InputError(f"A camera's source is one of {', '.join(SOURCES)}, not {source!r}.")
        given = {k: v for k, v in (("fov", fov_deg), ("pitch", pitch_deg), ("roll", roll_deg)) if v is not None}
        shifts = {k: float(v) for k, v in (("shift_x", shift_x), ("shift_y", shift_y)) if v is not None}
        if not given and not shifts:
            return self
        changes: dict = dict(shifts)
        for name, value in given.items():
            changes.update({f"{name}_deg": float(value), f"{name}_source": source, f"{name}_confidence": 1.0})
        out = replace(self, **changes)
        return replace(out, horizon=horizon_points(out.photo_camera()), vanishing_points={},
                       notes=self.notes + (f"{why}: {', '.join([*given, *(['lens shift'] if shifts else [])])}",))

    def to_dict(self) -> dict:
        out = asdict(self)
        del out["segments"]
        out["horizon"] = [list(p) for p in self.horizon]
        out["notes"] = list(self.notes)
        return {"source": self.source, "fallback": self.fallback, **out}

    def to_json(self, indent: int | None = None) -> str:
        """Strict JSON: NaN or infinity anywhere raises instead of writing a non-standard token."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)


def photo_camera_estimate(photo_path: str | Path, fspy_path: str | Path | None = None,
                          overrides: dict | None = None, source: str = "user",
                          why: str = "given by the user") -> CameraEstimate:
    """The camera every stage uses for a photo: `overrides` ({"fov_deg", "pitch_deg", "roll_deg"}, each
    from `source`) over the estimate. With all three given the photo's lines are not looked at."""
    overrides = check_camera_values(overrides or {})
    if {"fov_deg", "pitch_deg", "roll_deg"} <= set(overrides) and fspy_path is None:
        width, height = (int(v) for v in load_photo(photo_path)[1]["size"])
        base = _estimate(overrides["fov_deg"], overrides["pitch_deg"], overrides["roll_deg"], (source,) * 3,
                         (1.0, 1.0, 1.0), width, height, None, ())
        return base.overridden(**overrides, source=source, why=why)
    return estimate_photo_camera(photo_path, fspy_path).overridden(**overrides, source=source, why=why)


# The photo cameras SceneFit takes (the light stage's config holds the same bounds for its own fields).
GIVEN_FOV_RANGE_DEG = (1.0, 170.0)
MAX_PITCH_DEG = 89.0
MAX_SHIFT = 2.0   # an optical axis more than two frames off the photo is a mistake, not a lens
CAMERA_VALUES = ("fov_deg", "pitch_deg", "roll_deg", "shift_x", "shift_y")


def check_camera_values(values: dict) -> dict:
    """CAMERA_VALUES given over an estimate (None: not given) as floats, each finite and one a camera can have:
    a field of view within GIVEN_FOV_RANGE_DEG, a pitch within +-MAX_PITCH_DEG (straight up or down has no
    horizon to stand the asset on), a lens shift within +-MAX_SHIFT; one sentence otherwise. Every entry point's values pass here."""
    wrong = sorted(set(values) - set(CAMERA_VALUES))
    if wrong:
        raise InputError(f"A photo camera takes {', '.join(CAMERA_VALUES)}, not {wrong[0]!r}.")
    given = {k: v for k, v in values.items() if v is not None}
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in given.values()):
        raise InputError(f"The camera's angles and shift must be finite numbers, got {given!r}.")
    if any(abs(given.get(k, 0.0)) > MAX_SHIFT for k in ("shift_x", "shift_y")):
        raise InputError(f"The camera's lens shift must be within +-{MAX_SHIFT:g} of the photo's longer side, got "
                         f"({given.get('shift_x', 0.0)!r}, {given.get('shift_y', 0.0)!r}).")
    if "fov_deg" in given and not GIVEN_FOV_RANGE_DEG[0] <= given["fov_deg"] <= GIVEN_FOV_RANGE_DEG[1]:
        low, high = GIVEN_FOV_RANGE_DEG
        raise InputError(f"The camera's field of view must be between {low:g} and {high:g} degrees, got "
                         f"{given['fov_deg']!r}.")
    if "pitch_deg" in given and not -MAX_PITCH_DEG <= given["pitch_deg"] <= MAX_PITCH_DEG:
        raise InputError(f"The camera's pitch must be within +-{MAX_PITCH_DEG:g} degrees (straight up or down shows "
                         f"no horizon), got {given['pitch_deg']!r}.")
    return {k: float(v) for k, v in given.items()}


def estimate_photo_camera(photo_path: str | Path, fspy_path: str | Path | None = None) -> CameraEstimate:
    """The photo's camera from the best source there is (module docstring); raises InputError with one
    sentence for a photo or fSpy file that cannot be read."""
    srgb, info = load_photo(photo_path)
    width, height = (int(v) for v in info["size"])
    if fspy_path is not None:
        return _from_fspy(read_fspy(fspy_path), width, height)
    exif_fov, exif_source, notes = _exif_fov(Path(photo_path), info, srgb.shape[1], srgb.shape[0])
    fit = fit_lines(srgb, exif_fov)
    notes += fit.notes
    fov, fov_src, fov_conf = _pick_fov(fit, exif_fov, exif_source)
    pitch, pitch_src, pitch_conf = _pick(fit.pitch_deg, fit.pitch_confidence, DEFAULT_PITCH_DEG)
    roll, roll_src, roll_conf = _pick(fit.roll_deg, fit.roll_confidence, 0.0)
    notes += _fallback_notes(fov_src, pitch_src, roll_src)
    return _estimate(fov, pitch, roll, (fov_src, pitch_src, roll_src), (fov_conf, pitch_conf, roll_conf),
                     width, height, fit, tuple(notes))


# -- choosing between sources ----------------------------------------------------------------------
# The lines' field of view is used when its confidence reaches this, else EXIF's or the default. Their
# pitch and roll are used whenever the lines show a built scene (LinesFit.usable): even at an assumed
# field of view the horizon they find beats the default; their confidence says how far to trust it.
MIN_CONFIDENCE = 0.5
EXIF_CONFIDENCE = {"exif_35mm": 0.9, "exif_sensor": 0.75}


def _pick_fov(fit: "LinesFit", exif_fov: float | None, exif_source: str | None) -> tuple[float, str, float]:
    """EXIF's lens where the photo has one; else the lines' posterior median whatever its confidence (where
    the lines hardly fix the lens it sits near the default, and was measured closer to the truth than the
    default on the bench's built scenes); else the default."""
    if exif_fov is not None and exif_source is not None:
        return exif_fov, exif_source, EXIF_CONFIDENCE[exif_source]
    if fit.fov_deg is not None:
        return fit.fov_deg, "lines", fit.fov_confidence
    return DEFAULT_FOV_DEG, "default", 0.0


def _pick(value: float | None, confidence: float, default: float) -> tuple[float, str, float]:
    if value is not None:
        return value, "lines", confidence
    return default, "default", 0.0


def _fallback_notes(fov_src: str, pitch_src: str, roll_src: str) -> list[str]:
    notes = []
    if fov_src == "default":
        notes.append(f"field of view: the default {DEFAULT_FOV_DEG:g} deg (no EXIF focal length and the lines "
                     "do not fix it); an fSpy project of the photo would")
    for name, src, default in (("pitch", pitch_src, DEFAULT_PITCH_DEG), ("roll", roll_src, 0.0)):
        if src == "default":
            notes.append(f"{name}: the default {default:g} deg (the lines do not fix it); an fSpy project of the "
                         "photo would")
    return notes


def _unit(confidence: float) -> float:
    """A confidence in [0, 1], 0 where a degenerate fit left it undefined (JSON has no NaN)."""
    return round(min(max(float(confidence), 0.0), 1.0), 3) if math.isfinite(confidence) else 0.0


def _estimate(fov: float, pitch: float, roll: float, sources: tuple[str, str, str],
              confidences: tuple[float, float, float], width: int, height: int, fit: "LinesFit | None",
              notes: tuple[str, ...], shift: tuple[float, float] = (0.0, 0.0)) -> CameraEstimate:
    camera = PhotoCamera(pitch_deg=pitch, fov_deg=fov, width=width, height=height, roll_deg=roll,
                         shift_x=shift[0], shift_y=shift[1])
    vps = fit.vanishing_points(width, height) if fit is not None and "lines" in sources else {}
    return CameraEstimate(
        fov_deg=round(fov, 3), pitch_deg=round(pitch, 3), roll_deg=round(roll, 3),
        fov_source=sources[0], pitch_source=sources[1], roll_source=sources[2],
        fov_confidence=_unit(confidences[0]), pitch_confidence=_unit(confidences[1]),
        roll_confidence=_unit(confidences[2]), width=width, height=height,
        horizon=horizon_points(camera), vanishing_points=vps,
        lines=fit.counts if fit is not None else {}, notes=notes, shift_x=shift[0], shift_y=shift[1],
        segments=fit.inlier_segments(width, height) if fit is not None and "lines" in sources else ())


def _from_fspy(camera: dict, width: int, height: int) -> CameraEstimate:
    notes = ["camera solved by fSpy (vanishing lines drawn by hand); world Z taken as up, fSpy's default axes"]
    fw, fh = camera["image_size"]
    if abs(fw / fh - width / height) > 0.01 * width / height:
        notes.append(f"the fSpy project's image is {fw}x{fh} but the photo is {width}x{height}: the camera was solved "
                     "for another framing")
    # fSpy's principal point is in units of half the longer side, y up; Blender's shift (and
    # PhotoCamera's) in the longer side, the other way round (fSpy's own Blender importer does the same).
    px, py = camera["principal_point"]
    shift = (-px / 2.0, -py / 2.0)
    if max(abs(px), abs(py)) > 0.01:
        notes.append(f"fSpy's principal point is off centre ({px:.3f}, {py:.3f}): the camera has the lens shift "
                     f"({shift[0]:.3f}, {shift[1]:.3f}) that puts it there")
    return _estimate(camera["fov_deg"], camera["pitch_deg"], camera["roll_deg"], ("fspy",) * 3, (1.0, 1.0, 1.0),
                     width, height, None, tuple(notes), shift)


# -- EXIF (core/stages/camera_exif.py reads it) -------------------------------------------------------
def _exif_fov(path: Path, info: dict, width: int, height: int) -> tuple[float | None, str | None, list[str]]:
    if info.get("fov_from_metadata_deg"):
        return float(info["fov_from_metadata_deg"]), "exif_35mm", ["field of view from the EXIF 35 mm equivalent "
                                                                   "focal length"]
    focal, model = exif_focal_and_model(path)
    if not focal:
        return None, None, [info["metadata_ignored"]] if info.get("metadata_ignored") else []
    sensor = sensor_width_mm(model)
    if sensor is None:
        return None, None, [f"EXIF focal length {focal:g} mm but the camera model '{model}' is not in SceneFit's "
                            "sensor table, so it gives no field of view"]
    return fov_from_sensor(focal, sensor, width, height), "exif_sensor", [
        f"field of view from the EXIF focal length {focal:g} mm and the {sensor:g} mm sensor of the {model}"]


# -- geometry shared by the fit and the report -------------------------------------------------------
def focal_from_fov(fov_deg: float) -> float:
    """F, the focal length in half-widths, of a horizontal field of view."""
    return 1.0 / math.tan(math.radians(fov_deg) / 2.0)


def fov_from_focal(focal: float) -> float:
    return math.degrees(2.0 * math.atan(1.0 / focal))


def camera_frame(pitch_deg, roll_deg, theta_deg) -> np.ndarray:
    """The scene's three orthogonal directions in camera coordinates, (..., 3, 3): world up, then two
    horizontal directions turned by theta about it. Follows PhotoCamera.basis (roll included)."""
    p, r, t = (np.radians(np.asarray(a, dtype=np.float64)) for a in (pitch_deg, roll_deg, theta_deg))
    p, r, t = np.broadcast_arrays(p, r, t)
    sp, cp, sr, cr = np.sin(p), np.cos(p), np.sin(r), np.cos(r)
    up = np.stack([sr * cp, cr * cp, sp], axis=-1)
    across = np.stack([cr, -sr, np.zeros_like(r)], axis=-1)          # world X (the level camera's right)
    ahead = np.stack([-sr * sp, -cr * sp, cp], axis=-1)              # world Y (the level view direction)
    ct, st = np.cos(t)[..., None], np.sin(t)[..., None]
    return np.stack([up, ct * across + st * ahead, ct * ahead - st * across], axis=-2)


def horizon_points(camera: PhotoCamera) -> tuple[tuple[float, float], tuple[float, float]]:
    """Where the horizon (level rays) meets the photo's left and right edges, in pixels (y down)."""
    forward, right, up, half_w, half_h = camera.basis()
    off_y = camera.plane_offset()[1]
    def at(x: float) -> tuple[float, float]:
        plane_x = float(camera.plane_xy(x, 0.0)[0])
        plane_y = -(forward[2] + plane_x * right[2]) / up[2]   # the ray forward + x right + y up is level
        return round(x, 2), round((1.0 - (plane_y - off_y) / half_h) / 2.0 * camera.height, 2)

    return at(0.0), at(float(camera.width))


# -- the photo's own lines -------------------------------------------------------------------------
LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
MIN_SEGMENT = 0.02            # shortest segment kept, as a share of the photo's long side (and >= 12 px)
MAX_SEGMENTS = 400            # the longest ones; more add time, not accuracy
COARSE_SEGMENTS = 200
TOLERANCE_DEG = 1.5           # a segment belongs to a direction when it points at its vanishing point this well
COARSE_TOLERANCE_DEG = 4.0    # wider on the coarse grid, whose steps are 3 deg
# The search's range: cameras held roughly upright, lenses from long to wide.
FOV_RANGE_DEG = (20.0, 120.0)
PITCH_RANGE_DEG = (-60.0, 50.0)
ROLL_RANGE_DEG = (-15.0, 15.0)
# Confidence of pitch and roll: support / (1 + (u / tolerable error)^2), u combining the fit's standard
# error (times INFLATION: it treats segments as independent, which they are not, a wall's edges share
# its blur) with how far the value moves over the field of view's own uncertainty. Tolerable errors:
# the targets for fov, pitch, roll.
TOLERABLE_DEG = (5.0, 2.0, 1.0)
INFLATION = 3.0
# The field of view: the score is profiled over PROFILE_LENSES focal lengths (each refitted) and read as
# a log-likelihood, each explained segment worth 1 / INFLATION (they are not independent, above); the
# prior is what photographers use: log focal length normal about the default 60 deg's with
# LENS_PRIOR_SIGMA (1 sigma: 24-115 deg), pitch normal about level with PITCH_PRIOR_DEG. Its median is
# the estimate; its 16-84% interval the uncertainty, against TOLERABLE_DEG[0] for the confidence.
PROFILE_LENSES = 21
LENS_PRIOR_SIGMA = 1.0
PITCH_PRIOR_DEG = 30.0
# The lens needs more of a built scene than pitch and roll: below this share of the segments' length
# explained (a forest's trunks with stray branches, 0.31-0.35 on the bench; built scenes mostly 0.36-0.81)
# the lens is the default and pitch and roll are fitted at it, their confidence counting how far
# DEFAULT_LENS_RANGE_DEG could move them.
LENS_MIN_INLIER_SHARE = 0.35
DEFAULT_LENS_RANGE_DEG = (45.0, 80.0)
# A built scene (set on the bench's views, benchmarks/bench_camera.py): at least this share of the
# segments' length pointing at the three directions, this many verticals, and horizontals.
MIN_SEGMENTS = 8
MIN_INLIER_SHARE = 0.3
MIN_VERTICAL = 12
MIN_HORIZONTAL = 10           # both horizontal directions together
MIN_MAIN_HORIZONTAL = 6       # the better seen one


@dataclass(frozen=True)
class LinesFit:
    """What the photo's lines say. None where they say nothing; `params` is (fov, pitch, roll, theta)."""

    fov_deg: float | None = None
    pitch_deg: float | None = None
    roll_deg: float | None = None
    fov_confidence: float = 0.0
    pitch_confidence: float = 0.0
    roll_confidence: float = 0.0
    params: tuple[float, float, float, float] | None = None
    counts: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    segments: np.ndarray | None = None      # (N, 4) normalised ends, longest first
    weights: np.ndarray | None = None       # (N,) their length weights
    families: np.ndarray | None = None      # (N,) 0 vertical, 1 and 2 horizontal, -1 none

    @property
    def usable(self) -> bool:
        return self.params is not None

    def vanishing_points(self, width: int, height: int) -> dict:
        """Each direction's vanishing point in pixels, or None where it lies at infinity."""
        if self.params is None:
            return {}
        fov, pitch, roll, theta = self.params
        focal = focal_from_fov(fov)
        out = {}
        for name, d in zip(("vertical", "horizontal_1", "horizontal_2"), camera_frame(pitch, roll, theta)):
            out[name] = None if abs(d[2]) < 1e-6 else [
                round(width / 2 * (1 + focal * d[0] / d[2]), 2), round(height / 2 - width / 2 * focal * d[1] / d[2], 2)]
        return out


    def inlier_segments(self, width: int, height: int) -> tuple[tuple[float, float, float, float, int], ...]:
        """The segments pointing at a vanishing point, in pixels of a width x height photo, each with its
        direction (0 vertical, 1 and 2 horizontal)."""
        if self.segments is None or self.families is None:
            return ()
        keep = self.families >= 0
        xs = (self.segments[keep][:, 0::2] + 1.0) * width / 2.0
        ys = height / 2.0 - self.segments[keep][:, 1::2] * width / 2.0
        return tuple((round(float(x[0]), 1), round(float(y[0]), 1), round(float(x[1]), 1), round(float(y[1]), 1),
                      int(f)) for x, y, f in zip(xs, ys, self.families[keep]))


def fit_lines(srgb: np.ndarray, fov_deg: float | None = None) -> LinesFit:
    """Field of view (unless given), pitch and roll from the photo's straight lines (sRGB float RGB)."""
    ends, weights = photo_segments(srgb)
    counts = {"segments": int(len(ends))}
    if len(ends) < MIN_SEGMENTS:
        return LinesFit(counts=counts, notes=(f"lines: only {len(ends)} straight segments in the photo (a smooth or "
                                              "natural scene), too few to find its vanishing points",))
    if fov_deg is not None:
        params = _fit_at_fov(ends, weights, float(fov_deg))
        return _judge(ends, weights, params, _families(ends, params), counts)
    profile = fov_profile(ends, weights)
    fov, low, high = fov_posterior(profile, ends, weights)
    near = min(profile, key=lambda p: abs(p[0] - fov))
    params = max((_fit_at_fov(ends, weights, fov), _refine(ends, weights, (fov,) + tuple(near[1:]))),
                 key=lambda p: _score(ends, weights, p))
    fit = _judge(ends, weights, params, _families(ends, params), counts)
    if not fit.usable:
        return fit
    if fit.counts["inlier_share"] < LENS_MIN_INLIER_SHARE:
        params = _fit_at_fov(ends, weights, DEFAULT_FOV_DEG)
        fit = _judge(ends, weights, params, _families(ends, params), dict(segments=counts["segments"]))
        note = (f"field of view: the lines explain too little of the photo ({fit.counts['inlier_share']:.0%} of "
                f"the segments' length, under {LENS_MIN_INLIER_SHARE:.0%}) to fix the lens; pitch and roll at the "
                f"default {DEFAULT_FOV_DEG:g} deg")
        return _with_lens_spread(replace(fit, notes=fit.notes + (note,)), DEFAULT_LENS_RANGE_DEG) \
            if fit.usable else fit
    half = (high - low) / 2.0
    fit = _with_lens_spread(fit, (low, high))
    note = (f"field of view from the lines: {fov:.1f} deg, 68% between {low:.1f} and {high:.1f}" +
            ("" if half < TOLERABLE_DEG[0] else " (the lines hardly fix the lens: the value leans on the lenses "
                                                 "photographers use, an fSpy project of the photo would fix it)"))
    support = 1.0 - math.exp(-sum(fit.counts[k] for k in ("vertical", "horizontal_1", "horizontal_2")) / 8.0)
    return replace(fit, fov_deg=float(fov), fov_confidence=support / (1.0 + (half / TOLERABLE_DEG[0]) ** 2),
                   notes=fit.notes + (note,))


def _fit_at_fov(ends: np.ndarray, weights: np.ndarray, fov_deg: float) -> tuple:
    """The best (fov, pitch, roll, theta) with the field of view held."""
    starts = _coarse_search(ends[:COARSE_SEGMENTS], weights[:COARSE_SEGMENTS], fov_deg)
    return max((_refine(ends, weights, s) for s in starts), key=lambda p: _score(ends, weights, p))


def fov_profile(ends: np.ndarray, weights: np.ndarray) -> list[tuple]:
    """The best fit at each of PROFILE_LENSES fields of view (even steps of log focal length over
    FOV_RANGE_DEG): the score's profile. Profiled rather than searched jointly: the score along the
    focal length is flat with many small peaks, and a joint search picked whichever peak it met."""
    focals = np.geomspace(focal_from_fov(FOV_RANGE_DEG[1]), focal_from_fov(FOV_RANGE_DEG[0]), PROFILE_LENSES)
    return [_fit_at_fov(ends, weights, fov_from_focal(f)) for f in focals]


def fov_posterior(profile: list[tuple], ends: np.ndarray, weights: np.ndarray) -> tuple[float, float, float]:
    """Median and 16-84% interval of the field of view over the profile's lenses (constants above). Every
    lens counts, built scene or not: kept to those that looked like one, the posterior jumped to a lone
    lens at the range's end on meadows and forests."""
    segments = np.sum(weights) / np.mean(weights)
    log_likelihood = [_score(ends, weights, params) * segments / INFLATION - 0.5 * (params[1] / PITCH_PRIOR_DEG) ** 2
                      for params in profile]
    return lens_posterior([params[0] for params in profile], log_likelihood)


def lens_posterior(fovs, log_likelihood) -> tuple[float, float, float]:
    """Median and 16-84% interval of the field of view, given each lens's log-likelihood, under the lens
    prior (log focal length normal about the default's, LENS_PRIOR_SIGMA)."""
    log_focal = np.log([focal_from_fov(fov) for fov in fovs])
    log_p = np.asarray(log_likelihood, dtype=np.float64) \
        - 0.5 * ((log_focal - math.log(focal_from_fov(DEFAULT_FOV_DEG))) / LENS_PRIOR_SIGMA) ** 2
    order = np.argsort(log_focal)
    x, p = log_focal[order], np.exp(log_p[order] - np.max(log_p))
    # Each lens stands for its bin of log focal length, so the cumulative sum is reached at bin edges (at
    # the nodes, a lens holding all the weight had its median half a step wider: +1.7 deg on the bench).
    mids = (x[1:] + x[:-1]) / 2.0
    edges = np.concatenate([[2 * x[0] - mids[0]], mids, [2 * x[-1] - mids[-1]]])
    cdf = np.concatenate([[0.0], np.cumsum(p) / np.sum(p)])
    fov_at = lambda q: fov_from_focal(float(np.exp(np.interp(q, cdf, edges))))   # noqa: E731
    return fov_at(0.5), fov_at(0.84), fov_at(0.16)   # (a longer focal length is a narrower view)


def photo_segments(srgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Straight segments (OpenCV's LSD) as normalised ends (N, 4), longest first, with length weights."""
    h, w = srgb.shape[:2]
    gray = np.clip(np.round(srgb[..., :3] @ LUMA * 255.0), 0, 255).astype(np.uint8)
    found = _line_detector().detect(gray)[0]
    if found is None:
        return np.zeros((0, 4)), np.zeros(0)
    px = found.reshape(-1, 4).astype(np.float64)
    length = np.hypot(px[:, 2] - px[:, 0], px[:, 3] - px[:, 1])
    keep = np.argsort(-length)[:MAX_SEGMENTS]
    keep = keep[length[keep] >= max(12.0, MIN_SEGMENT * max(w, h))]
    px, length = px[keep], length[keep]
    ends = np.empty_like(px)
    ends[:, 0::2] = (px[:, 0::2] - w / 2) / (w / 2)
    ends[:, 1::2] = (h / 2 - px[:, 1::2]) / (w / 2)
    return ends, np.minimum(length, 0.25 * max(w, h)) / max(w, h)


def _line_detector():
    """OpenCV's LSD (back in 4.5.1+, present in the pinned 4.11); the contrib fast line detector where a
    build lacks it (4.1-4.5.0 shipped LSD as a stub that raises)."""
    import cv2  # lazy: Blender may lack it (missing_modules)

    try:
        return cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
    except (AttributeError, cv2.error):
        return cv2.ximgproc.createFastLineDetector()


def _great_circles(ends: np.ndarray, focal: float) -> tuple[np.ndarray, np.ndarray]:
    """Each segment's plane through the eye (unit normal n) and the ray through its midpoint in the image
    (unit m), where its residual is measured."""
    f = np.full(len(ends), focal)
    p1 = np.stack([ends[:, 0], ends[:, 1], f], axis=-1)
    p2 = np.stack([ends[:, 2], ends[:, 3], f], axis=-1)
    n = np.cross(p1, p2)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    m = p1 + p2
    return n, m / np.linalg.norm(m, axis=-1, keepdims=True)


def _signed_residual_deg(n: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The angle in the image, at the segment's midpoint, between the segment and the line to direction
    d's vanishing point (0 when the segment points at it; works for vanishing points at infinity).

    Measured in the image plane, not between great circles on the sphere: there, a segment far off
    the axis of a wide lens is foreshortened, its angles squeezed, so every tolerance widened with the
    lens and the fit preferred fields of view of 120-170 deg (the bench's corridors)."""
    n, m, d = np.broadcast_arrays(n, m, d)
    along = np.stack([n[..., 1], -n[..., 0]], axis=-1)            # the segment's image line n . (x, y, 1) = 0
    to_vp = d[..., :2] - m[..., :2] / m[..., 2:3] * d[..., 2:3]    # homogeneous: scale does not change angles
    cross = along[..., 0] * to_vp[..., 1] - along[..., 1] * to_vp[..., 0]
    angle = (np.degrees(np.arctan2(cross, np.sum(along * to_vp, axis=-1))) + 90.0) % 180.0 - 90.0
    return np.where(np.linalg.norm(to_vp, axis=-1) > 1e-9, angle, 90.0)


def _kernel(residual_deg: np.ndarray, tolerance: float) -> np.ndarray:
    return np.maximum(0.0, 1.0 - (residual_deg / tolerance) ** 2)


def _score(ends: np.ndarray, weights: np.ndarray, params, tolerance: float = TOLERANCE_DEG,
           circles: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """Share of the segments' weight the three directions explain (each segment by its best one).
    `circles`: _great_circles(ends) at params' field of view, where the caller holds it fixed."""
    fov, pitch, roll, theta = params
    n, m = circles if circles is not None else _great_circles(ends, focal_from_fov(fov))
    frame = camera_frame(pitch, roll, theta)
    res = _signed_residual_deg(n[:, None], m[:, None], frame[None])
    return float(np.sum(weights * _kernel(res, tolerance).max(axis=1)) / np.sum(weights))


def _coarse_search(ends: np.ndarray, weights: np.ndarray, fov_deg: float) -> list[tuple]:
    """The best few (fov, pitch, roll, theta) on a grid at one field of view: the best of each 12 deg band
    of pitch, three of them. Each segment votes for the horizontal direction its great circle meets
    (theta mod 90 deg pairs the two horizontal families), so theta costs a histogram, not a search; the
    exact score then refines these."""
    pitch, roll = np.meshgrid(np.arange(PITCH_RANGE_DEG[0], PITCH_RANGE_DEG[1] + 0.1, 3.0),
                              np.arange(ROLL_RANGE_DEG[0], ROLL_RANGE_DEG[1] + 0.1, 2.5), indexing="ij")
    pitch, roll = pitch.ravel(), roll.ravel()
    scores = _theta_votes(ends, weights, focal_from_fov(fov_deg), pitch, roll)
    per_pitch = np.max(scores, axis=1)
    bands = np.floor(pitch / 12.0)
    best = []
    for band in np.unique(bands):
        i = int(np.flatnonzero(bands == band)[np.argmax(per_pitch[bands == band])])
        t = int(np.argmax(scores[i]))
        best.append((float(scores[i, t]), (float(fov_deg), float(pitch[i]), float(roll[i]), THETA_STEP_DEG * t)))
    best.sort(key=lambda b: -b[0])
    return [b[1] for b in best[:3]]


THETA_STEP_DEG = 2.0   # the coarse grid's bins of theta, over the 90 deg that pair the horizontal families
THETA_BINS = 45


def _theta_votes(ends: np.ndarray, weights: np.ndarray, focal: float, pitch: np.ndarray, roll: np.ndarray,
                 chunk: int = 96) -> np.ndarray:
    """Score of every (pitch, roll) x theta bin at one focal length: each segment counts by its best
    direction, max(vertical, horizontal), summed with its weight. max(v, h) = v + max(0, h - v), and the
    horizontal kernel is zero beyond COARSE_TOLERANCE / slope degrees from the segment's theta, so each
    segment adds to the few bins it reaches (about 6 of 45 on real photos), not to all of them."""
    n, m = _great_circles(ends, focal)
    out = []
    for lo in range(0, len(pitch), chunk):
        frame = camera_frame(pitch[lo:lo + chunk], roll[lo:lo + chunk], 0.0)
        up, across, ahead = frame[:, 0, None], frame[:, 1, None], frame[:, 2, None]
        vertical = _kernel(_signed_residual_deg(n, m, up), COARSE_TOLERANCE_DEG)
        meet = np.cross(n, up)                       # the one horizontal direction on each segment's circle
        meet /= np.maximum(np.linalg.norm(meet, axis=-1, keepdims=True), 1e-12)
        theta = np.degrees(np.arctan2(np.sum(meet * ahead, -1), np.sum(meet * across, -1))) % 90.0
        # deg of residual per deg of theta: segments along the horizon fit every theta
        turned = np.cos(0.02) * meet + np.sin(0.02) * np.cross(up, meet)
        slope = np.abs(_signed_residual_deg(n, m, turned)) / np.degrees(0.02)
        poses, segments = vertical.shape
        scores = np.repeat((vertical @ weights)[:, None], THETA_BINS, axis=1)
        with np.errstate(divide="ignore"):   # (slope 0: every bin)
            reach = np.floor(COARSE_TOLERANCE_DEG / slope / THETA_STEP_DEG).ravel()
        side = np.minimum(reach, THETA_BINS // 2 - 1).astype(np.int64) + 1   # bins looked at either side
        count = 2 * side + 1
        pair = np.repeat(np.arange(poses * segments), count)                 # (pose, segment) of each entry
        offset = np.arange(len(pair)) - np.repeat(np.cumsum(count) - count + side, count)
        theta, slope = theta.ravel()[pair], slope.ravel()[pair]
        bins = (np.round(theta / THETA_STEP_DEG).astype(np.int64) + offset) % THETA_BINS
        off = np.abs((bins * THETA_STEP_DEG - theta + 45.0) % 90.0 - 45.0)
        gain = np.maximum(0.0, _kernel(slope * off, COARSE_TOLERANCE_DEG) - vertical.ravel()[pair])
        scores += np.bincount((pair // segments) * THETA_BINS + bins, gain * weights[pair % segments],
                              minlength=poses * THETA_BINS).reshape(poses, THETA_BINS)
        out.append(scores)
    return np.concatenate(out) / np.sum(weights)


REFINE_STEPS = (2.0, 1.0, 0.5, 1.0)   # first steps of (fov, pitch, roll, theta), halved down to 1/64


def _refine(ends: np.ndarray, weights: np.ndarray, start) -> tuple:
    """Pattern search on the exact score from a coarse start, its field of view held (no gradient: the
    score is piecewise)."""
    x = list(start)
    steps = list(REFINE_STEPS)
    circles = _great_circles(ends, focal_from_fov(x[0]))   # the field of view (x[0]) never moves here
    best = _score(ends, weights, x, circles=circles)
    for _ in range(500):   # a bound, never reached in practice
        if steps[1] <= REFINE_STEPS[1] / 64:
            break
        improved = False
        for i in (1, 2, 3):
            for sign in (1.0, -1.0):
                y = list(x)
                y[i] += sign * steps[i]
                if not _in_range(y):
                    continue
                score = _score(ends, weights, y, circles=circles)
                if score > best:
                    x, best, improved = y, score, True
        if not improved:
            steps = [s / 2 for s in steps]
    return tuple(x)


def _in_range(params) -> bool:
    """The search's range of pitch and roll (the field of view is held)."""
    _, pitch, roll, _ = params
    return PITCH_RANGE_DEG[0] <= pitch <= PITCH_RANGE_DEG[1] and ROLL_RANGE_DEG[0] <= roll <= ROLL_RANGE_DEG[1]


def _families(ends: np.ndarray, params) -> np.ndarray:
    """Which direction each segment belongs to (0 vertical, 1-2 horizontal), -1 for none."""
    fov, pitch, roll, theta = params
    n, m = _great_circles(ends, focal_from_fov(fov))
    res = np.abs(_signed_residual_deg(n[:, None], m[:, None], camera_frame(pitch, roll, theta)[None]))
    best = np.argmin(res, axis=1)
    return np.where(res[np.arange(len(ends)), best] < TOLERANCE_DEG, best, -1)


def _standard_errors(ends: np.ndarray, weights: np.ndarray, params, families: np.ndarray,
                     free: tuple[int, ...]) -> np.ndarray:
    """Standard errors of the free parameters from the inliers' residuals (Gauss-Newton covariance,
    central differences); an unconstrained parameter gets a huge one."""
    inl = families >= 0
    if int(inl.sum()) <= len(free):
        return np.full(4, np.inf)

    def residuals(p) -> np.ndarray:
        fov, pitch, roll, theta = p
        n, m = _great_circles(ends[inl], focal_from_fov(fov))
        d = camera_frame(pitch, roll, theta)[families[inl]]
        return _signed_residual_deg(n, m, d)

    jac = []
    for i in free:
        hi, lo = list(params), list(params)
        hi[i] += 0.05
        lo[i] -= 0.05
        jac.append((residuals(hi) - residuals(lo)) / 0.1)
    jac = np.stack(jac, axis=1)
    w = weights[inl] / np.mean(weights[inl])
    r = residuals(params)
    sigma2 = float(np.sum(w * r ** 2) / max(int(inl.sum()) - len(free), 1))
    normal = jac.T @ (w[:, None] * jac)
    cov = sigma2 * np.linalg.inv(normal + 1e-9 * max(np.trace(normal), 1e-12) * np.eye(len(free)))
    errors = np.full(4, np.inf)
    errors[list(free)] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return np.nan_to_num(errors, nan=np.inf)


def _judge(ends: np.ndarray, weights: np.ndarray, params, families: np.ndarray, counts: dict) -> LinesFit:
    """The fit's pitch and roll and their confidences at its field of view (held: the caller sets the
    lines' own), or none where the segments do not show a built scene."""
    share = float(np.sum(weights[families >= 0]) / np.sum(weights))
    per = [int(np.sum(families == k)) for k in range(3)]
    counts.update(vertical=per[0], horizontal_1=per[1], horizontal_2=per[2], inlier_share=round(share, 3))
    seen: dict = dict(counts=counts, segments=ends, weights=weights, families=families)
    if (share < MIN_INLIER_SHARE or per[0] < MIN_VERTICAL or per[1] + per[2] < MIN_HORIZONTAL
                       or max(per[1:]) < MIN_MAIN_HORIZONTAL):
        return LinesFit(**seen, notes=(
            f"lines: {len(ends)} segments, {per[0]} vertical and {per[1] + per[2]} horizontal ones pointing at "
            f"orthogonal vanishing points ({share:.0%} of their length): not enough of a built scene's lines to "
            "fix the camera",))
    errors = _standard_errors(ends, weights, params, families, (1, 2, 3))
    support = 1.0 - math.exp(-sum(per) / 8.0)
    conf = [support / (1.0 + (INFLATION * float(errors[i]) / TOLERABLE_DEG[i]) ** 2) for i in (1, 2)]
    fov, pitch, roll, theta = (float(v) for v in params)
    note = (f"lines: {len(ends)} segments, {sum(per)} pointing at the vanishing points (vertical {per[0]}, "
            f"horizontal {per[1]} and {per[2]})")
    return LinesFit(pitch_deg=float(pitch), roll_deg=float((roll + 180.0) % 360.0 - 180.0),
                    pitch_confidence=conf[0], roll_confidence=conf[1], params=(fov, pitch, roll, theta),
                    notes=(note,), **seen)


def _with_lens_spread(fit: LinesFit, fov_range: tuple[float, float]) -> LinesFit:
    """The fit with pitch's and roll's confidence also counting how far they move over `fov_range`, the
    lenses the lines leave possible (pitch trades against the focal length when the verticals converge)."""
    assert fit.segments is not None and fit.weights is not None and fit.params is not None   # (a fit that found lines)
    first, last = (_refine(fit.segments, fit.weights, (f,) + tuple(fit.params[1:])) for f in fov_range)
    spread = [abs(first[i] - last[i]) / 2.0 for i in (1, 2)]
    pitch_conf, roll_conf = (min(c, 1.0 / (1.0 + (u / TOLERABLE_DEG[i + 1]) ** 2))
                             for i, (c, u) in enumerate(zip((fit.pitch_confidence, fit.roll_confidence), spread)))
    note = (f"over lenses of {fov_range[0]:.0f}-{fov_range[1]:.0f} deg pitch and roll move +-{spread[0]:.1f} and "
            f"+-{spread[1]:.1f} deg")
    return replace(fit, pitch_confidence=pitch_conf, roll_confidence=roll_conf, notes=fit.notes + (note,))
