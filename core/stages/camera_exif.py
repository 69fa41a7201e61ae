"""What a photo's EXIF says about its lens: the focal length with the sensor of a known camera model gives
the field of view (the 35 mm equivalent is read with the photo, core/data/photo.load_photo). A
focal length that is not one (text, zero, negative, huge) is left aside."""
from __future__ import annotations

import math
from pathlib import Path

from ..data.photo import plausible_focal_mm

# Sensor width (long side, mm) of common cameras whose JPEGs may lack the 35 mm equivalent, from the
# makers' specification sheets; matched on the start of the EXIF Model, longest key first, where no
# digit follows (so "CANON EOS R5" is not the APS-C R50, while "ILCE-7" covers the A7 III's ILCE-7M3).
SENSOR_WIDTH_MM = {
    "CANON EOS 5D": 36.0, "CANON EOS 6D": 35.8, "CANON EOS R5": 36.0, "CANON EOS R6": 35.9,
    "CANON EOS 7D": 22.3, "CANON EOS 80D": 22.5, "CANON EOS 90D": 22.3, "CANON EOS 2000D": 22.3,
    "CANON EOS REBEL": 22.3, "CANON EOS M50": 22.3,
    "NIKON D850": 35.9, "NIKON D810": 35.9, "NIKON D750": 35.9, "NIKON D3500": 23.5, "NIKON D5600": 23.5,
    "NIKON D7500": 23.5, "NIKON Z 6": 35.9, "NIKON Z 7": 35.9,
    "ILCE-7": 35.8, "ILCE-9": 35.6,                           # Sony A7 and A9 families (full frame)
    "ILCE-6000": 23.5, "ILCE-6100": 23.5, "ILCE-6400": 23.5, "ILCE-6600": 23.5,   # Sony A6xxx (APS-C)
    "X-T3": 23.5, "X-T4": 23.5, "X-T30": 23.5, "X100": 23.6,   # Fujifilm
    "DC-GH5": 17.3, "DMC-GH4": 17.3, "E-M1": 17.3, "E-M5": 17.3, "E-M10": 17.3,   # Micro Four Thirds
    "DSC-RX100": 13.2,                                          # Sony 1-inch compacts
}



def fov_from_sensor(focal_mm: float, sensor_width_mm: float, width: int, height: int) -> float:
    """Horizontal field of view from the real focal length and the sensor's long side (the photo's long
    side spans it; a portrait photo's width is the sensor's short side)."""
    film_width = sensor_width_mm * width / max(width, height)
    return math.degrees(2.0 * math.atan(film_width / (2.0 * float(focal_mm))))


def sensor_width_mm(model: str) -> float | None:
    model = " ".join(model.upper().split())
    for key in sorted(SENSOR_WIDTH_MM, key=len, reverse=True):
        if model.startswith(key) and not model[len(key):len(key) + 1].isdigit():
            return SENSOR_WIDTH_MM[key]
    return None


def exif_focal_and_model(path: Path) -> tuple[float | None, str]:
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return None, ""
    try:
        spec = inp.spec()
        focal = spec.getattribute("Exif:FocalLength")
        model = str(spec.getattribute("Model") or "").strip()
    finally:
        inp.close()
    return plausible_focal_mm(focal), model


# A focal length a photo's EXIF may give, in mm (35 mm equivalent or real): a fisheye's few mm to a
# super-telephoto's few thousand. A value outside (zero, negative, text, 1e30) is data from elsewhere gone wrong.
