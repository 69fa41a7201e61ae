"""scenefit camera: the photo's field of view, pitch, roll and horizon, each with its source and confidence."""
from __future__ import annotations


def run(args) -> int:
    from ..core.stages.camera import estimate_photo_camera

    estimate = estimate_photo_camera(args.photo, args.fspy)
    if args.overlay:
        write_overlay(args.photo, estimate, args.overlay)
    if args.json:
        print(estimate.to_json())
        return 0
    for name, unit in (("fov", "(horizontal)"), ("pitch", "(up from the horizon)"), ("roll", "(counter-clockwise)")):
        value, source = getattr(estimate, f"{name}_deg"), getattr(estimate, f"{name}_source")
        print(f"{name:<6}{value:8.2f} deg {unit:<23}source {source}, "
              f"confidence {getattr(estimate, f'{name}_confidence'):.2f}")
    (x0, y0), (x1, y1) = estimate.horizon
    print(f"horizon ({x0:.1f}, {y0:.1f}) to ({x1:.1f}, {y1:.1f}) px in the {estimate.width}x{estimate.height} photo")
    print(f"source {estimate.source}" + (" (some fields are defaults)" if estimate.fallback else ""))
    for note in estimate.notes:
        print(f"  {note}")
    return 0


def write_overlay(photo: str, estimate, path: str) -> None:
    """The photo with the estimate's lines and horizon drawn over it (core/stages/camera_overlay.py), as a new file."""
    from pathlib import Path

    import numpy as np

    from ..core.stages.camera_overlay import camera_overlay
    from ..core.base.errors import InputError
    from ..core.data.imageio import linear_to_srgb, read_color_image, write_image

    out = Path(path)
    if out.exists() or out.is_symlink():
        raise InputError(f"'{out}' exists; give --overlay a new file name (SceneFit never writes over a file).")
    srgb = linear_to_srgb(np.clip(read_color_image(photo, upright=True)[..., :3], 0.0, 1.0))
    lines = camera_overlay(estimate)   # at the photo's upright size, as the estimate's pixels are
    alpha = lines[..., 3:]
    write_image(out, srgb * (1.0 - alpha) + lines[..., :3] * alpha)


def add_parser(sub) -> None:
    p = sub.add_parser("camera", help="the photo's camera: field of view, pitch, roll and horizon (fSpy, EXIF or "
                                      "its own lines)")
    p.add_argument("--photo", required=True, help="the photo (PNG, JPEG, EXR, ...)")
    p.add_argument("--fspy", help="an fSpy project (.fspy) of the photo: its solved camera is used as is")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of lines")
    p.add_argument("--overlay", metavar="FILE.png", help="also write the photo with the lines found (coloured by the "
                                                          "direction they vanish in) and the horizon drawn over it")
    p.set_defaults(func=run)
