"""scenefit camera: the photo's field of view, pitch, roll and horizon, each with its source and confidence."""
from __future__ import annotations


def run(args) -> int:
    from ..core.photo_camera import estimate_photo_camera

    estimate = estimate_photo_camera(args.photo, args.fspy)
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


def add_parser(sub) -> None:
    p = sub.add_parser("camera", help="the photo's camera: field of view, pitch, roll and horizon (fSpy, EXIF or "
                                      "its own lines)")
    p.add_argument("--photo", required=True, help="the photo (PNG, JPEG, EXR, ...)")
    p.add_argument("--fspy", help="an fSpy project (.fspy) of the photo: its solved camera is used as is")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of lines")
    p.set_defaults(func=run)
