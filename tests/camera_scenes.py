"""Photos with known cameras for the camera tests: EXIF-tagged JPEGs and box rooms whose lines a camera sees."""
from __future__ import annotations

import numpy as np

from scenefit.core.scene.camera import PhotoCamera


def jpeg_with_exif(path, size, **attributes):
    import OpenImageIO as oiio

    w, h = size
    spec = oiio.ImageSpec(w, h, 3, oiio.UINT8)
    for name, value in attributes.items():
        spec.attribute(name, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.full((h, w, 3), 128, np.uint8))
    out.close()
    return path


def box_room(camera: PhotoCamera, n: int = 140, seed: int = 0) -> np.ndarray:
    """Dark straight edges along the world's X, Y and Z axes, drawn where `camera` sees them."""
    import cv2

    rng = np.random.default_rng(seed)
    forward = camera.basis()[0]
    img = np.full((camera.height, camera.width, 3), 0.8, np.float32)
    drawn = 0
    while drawn < n:
        start = forward * rng.uniform(3, 12) + rng.uniform(-6, 6, 3)
        end = start.copy()
        end[rng.integers(3)] += rng.uniform(1, 4)
        pts = np.stack([start, end])
        px = camera.project(pts)
        if np.any(pts @ forward < 0.5) or np.any(np.abs(px - [camera.width / 2, camera.height / 2]) >
                                                  [camera.width, camera.height]):
            continue
        a, b = (tuple(int(v) for v in np.round(p * 16)) for p in px)
        cv2.line(img, a, b, (0.1, 0.1, 0.1), 2, cv2.LINE_AA, shift=4)
        drawn += 1
    return img


def lineless_photo(path, size=(96, 64), seed=0):
    """A smooth, lineless photo: a vertical gradient with faint noise."""
    from scenefit.core.data.imageio import write_image

    w, h = size
    rng = np.random.default_rng(seed)
    ramp = np.linspace(0.2, 0.8, h, dtype=np.float32)[:, None, None] * np.ones((h, w, 3), np.float32)
    write_image(path, np.clip(ramp + rng.normal(0, 0.01, (h, w, 3)), 0, 1))
    return path


def fspy_project_bytes(camera: PhotoCamera, image: bytes = b"\x89PNG fake", principal=(0.0, 0.0),
                       **overrides) -> bytes:
    """An fSpy project as fSpy documents it: 'fspy', version 1, state length, image length (uint32 LE),
    the state JSON, the image. The camera-to-world matrix's columns are right, up and -forward;
    `principal` is the solved principal point (fSpy's units: half the longer side, y up)."""
    import json
    import math
    import struct

    forward, right, up, _, _ = camera.basis()
    rotation = np.stack([right, up, -forward], axis=1)
    rows = np.eye(4)
    rows[:3, :3] = rotation
    rows[:3, 3] = (1.0, -4.0, 1.5)
    params = {"principalPoint": {"x": principal[0], "y": principal[1]},
              "horizontalFieldOfView": math.radians(camera.fov_deg),
              "verticalFieldOfView": 1.0, "cameraTransform": {"rows": rows.tolist()},
              "viewTransform": {"rows": np.linalg.inv(rows).tolist()}, "imageWidth": camera.width,
              "imageHeight": camera.height, "relativeFocalLength": 1.0}
    state = json.dumps({"cameraParameters": params, "calibrationSettingsBase": {}, **overrides}).encode()
    return struct.pack("<4sIII", b"fspy", 1, len(state), len(image)) + state + image
