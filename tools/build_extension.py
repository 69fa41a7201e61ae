"""Build SceneFit's Blender extension zip, with or without the runtime wheels.

    python tools/build_extension.py wheels   --platform linux-x64   # download wheels, write manifest
    python tools/build_extension.py build    --platform linux-x64   # build dist/scenefit-<v>-<platform>.zip
    python tools/build_extension.py nowheels                       # dist/scenefit-<v>-nowheels.zip
    python tools/build_extension.py validate                       # Blender's own manifest check

Wheels are binary only, for CPython 3.11, unmodified from the registry. Dependencies are resolved
here rather than by `pip download`, because pip evaluates environment markers against the machine
it runs on, not the target platform (a Windows build would otherwise ask for Linux-only triton).
Each wheel is fetched with `pip download --no-deps`, its Requires-Dist read, markers evaluated for
the target, and the closure downloaded the same way. Where the development environment has a
version installed that satisfies the requirement, that version is taken, so the extension runs
what the tests ran.

Left out: numpy (Blender ships it, and a second copy breaks bpy's own modules). OpenImageIO IS
bundled: Blender ships its Python module, but the `bpy` module from PyPI does not, and baking failed
there without it (the development environment runs the same wheel beside bpy).
"""
from __future__ import annotations

import argparse
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path

from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name, parse_wheel_filename
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
WHEELS = ROOT / "wheels"
DIST = ROOT / "dist"

# What the extension needs at run time (not bpy, pytest or matplotlib: development only).
RUNTIME = [
    "mitsuba", "drjit", "torch", "diffusers", "transformers", "peft", "accelerate",
    "opencv-contrib-python-headless", "OpenImageIO", "openai", "pyoidn", "meshopt", "xatlas",
]
LEFT_OUT = {"numpy": "Blender ships numpy"}
# Bundled on every platform the registry has a wheel for, left out (said so) where it has none: the
# composite is then made without denoising's help (pyoidn 2.5.1.0 has no Linux arm64 wheel).
# Without meshopt, EXT_meshopt_compression files are refused; without xatlas (no Linux arm64 wheel), adaptation
# on UVs that share texels stays in them (said in its report).
WHERE_PUBLISHED = {"pyoidn", "meshopt", "xatlas"}

# Blender platform -> pip platform tags (pip does not expand manylinux_2_x to older glibc tags itself)
# and the marker environment of that platform.
PLATFORMS: dict[str, tuple[list[str], dict[str, str]]] = {
    "linux-x64": (
        [f"manylinux_2_{m}_x86_64" for m in range(28, 16, -1)] + ["manylinux2014_x86_64", "linux_x86_64"],
        {"sys_platform": "linux", "platform_system": "Linux", "platform_machine": "x86_64", "os_name": "posix"},
    ),
    "linux-arm64": (
        [f"manylinux_2_{m}_aarch64" for m in range(28, 16, -1)] + ["manylinux2014_aarch64", "linux_aarch64"],
        {"sys_platform": "linux", "platform_system": "Linux", "platform_machine": "aarch64", "os_name": "posix"},
    ),
    "windows-x64": (
        ["win_amd64"],
        {"sys_platform": "win32", "platform_system": "Windows", "platform_machine": "AMD64", "os_name": "nt"},
    ),
    "macos-arm64": (
        ["macosx_12_0_arm64", "macosx_11_0_arm64"],   # pyoidn's arm64 wheel is for macOS 12
        {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "arm64", "os_name": "posix"},
    ),
    "macos-x64": (
        ["macosx_10_15_x86_64"],
        {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "x86_64", "os_name": "posix"},
    ),
}


def blender_ext() -> Path:
    import importlib.util

    # Locate the bpy wheel without importing it (that starts Blender); the builder is plain Python.
    spec = importlib.util.find_spec("bpy")
    roots = list(spec.submodule_search_locations or []) if spec else []
    path = next((p for r in roots for p in Path(r).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py")), None)
    if path is None:
        sys.exit("Blender's extension builder (bl_pkg/cli/blender_ext.py) was not found in the bpy wheel.")
    return path


def marker_env(platform: str, extra: str = "") -> dict[str, str]:
    env = {"python_version": "3.11", "python_full_version": "3.11.7", "implementation_name": "cpython",
           "platform_python_implementation": "CPython", "platform_release": "", "platform_version": "",
           "extra": extra}
    env.update(PLATFORMS[platform][1])
    return env


def wheel_requirements(wheel: Path) -> list[Requirement]:
    with zipfile.ZipFile(wheel) as z:
        name = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
        text = z.read(name).decode("utf-8")
    return [Requirement(line.split(":", 1)[1].strip()) for line in text.splitlines()
            if line.startswith("Requires-Dist:")]


def applies(req: Requirement, platform: str, extras: set[str]) -> bool:
    if req.marker is None:
        return True
    return any(req.marker.evaluate(marker_env(platform, e)) for e in ({""} | extras))


def preferred(req: Requirement) -> str:
    """`name==installed` when the dev environment's version satisfies the requirement, else the spec."""
    try:
        installed = importlib.metadata.version(req.name)
    except importlib.metadata.PackageNotFoundError:
        installed = None
    if installed and req.specifier.contains(Version(installed), prereleases=True):
        # The public version: a local build label (torch's "+cpu") names a build of this machine's
        # index, not one the registry has for every platform.
        return f"{req.name}=={Version(installed).public}"
    return f"{req.name}{req.specifier}"


def pip_download(spec: str, platform: str) -> Path:
    tags, _ = PLATFORMS[platform]
    WHEELS.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(dir=WHEELS) as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
               "--python-version", "3.11", "--implementation", "cp", "--abi", "cp311", "-d", tmp]
        for tag in tags:
            cmd += ["--platform", tag]
        subprocess.run(cmd + [spec], check=True)
        (wheel,) = Path(tmp).glob("*.whl")
        target = WHEELS / wheel.name
        os.replace(wheel, target)
    return target


def download(platform: str) -> list[Path]:
    """Download the runtime wheels and their dependency closure for `platform`; returns them."""
    if platform not in PLATFORMS:
        sys.exit(f"Unknown platform '{platform}'; choose one of {', '.join(PLATFORMS)}.")
    got: dict[str, Path] = {}
    extras: dict[str, set[str]] = {}
    todo = [Requirement(name) for name in RUNTIME]
    while todo:
        req = todo.pop(0)
        key = canonicalize_name(req.name)
        if key in LEFT_OUT:
            continue
        extras.setdefault(key, set()).update(req.extras)
        if key in got:
            version = parse_wheel_filename(got[key].name)[1]
            if not req.specifier.contains(version, prereleases=True):
                sys.exit(f"Conflict: {got[key].name} does not satisfy '{req}'; pin it in RUNTIME.")
            if not req.extras:
                continue
        else:
            spec = preferred(req)
            print(f"  {platform}: {spec}", flush=True)
            try:
                got[key] = pip_download(spec, platform)
            except subprocess.CalledProcessError:
                if key not in WHERE_PUBLISHED:
                    raise
                print(f"  {platform}: {spec} has no wheel for this platform; left out", flush=True)
                continue
        for dep in wheel_requirements(got[key]):
            if applies(dep, platform, extras[key]):
                todo.append(dep)
    return sorted(got.values())


def set_manifest_list(text: str, key: str, values: list[str]) -> str:
    """Replace the top-level `key = [...]` (one or many lines) in the manifest text."""
    body = "[]" if not values else "[\n" + "".join(f'  "{v}",\n' for v in values) + "]"
    pattern = re.compile(rf"^{key} = \[.*?\]", re.MULTILINE | re.DOTALL)
    if not pattern.search(text):
        sys.exit(f"blender_manifest.toml has no top-level '{key} = [...]' to update.")
    return pattern.sub(lambda _: f"{key} = {body}", text, count=1)


def write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)


def write_wheels_into_manifest(wheels: list[Path], platform: str, manifest: Path = MANIFEST) -> None:
    text = manifest.read_text(encoding="utf-8")
    text = set_manifest_list(text, "wheels", [f"./wheels/{w.name}" for w in wheels])
    text = set_manifest_list(text, "platforms", [platform])
    tomllib.loads(text)  # never leave a manifest Blender cannot parse
    write_atomic(manifest, text)


def version() -> str:
    return tomllib.loads(MANIFEST.read_text(encoding="utf-8"))["version"]


def build(source: Path, out: Path) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, str(blender_ext()), "build", "--source-dir", str(source),
                    "--output-filepath", str(out)], check=True)
    return out


def build_without_wheels(out: Path | None = None) -> Path:
    """A pure-Python zip (empty wheels list) from a staged copy; the repository is left untouched."""
    out = out or DIST / f"scenefit-{version()}-nowheels.zip"
    ignore = shutil.ignore_patterns(".*", "dist", "out", "build", "wheels", "tests", "devtools", "example",
                                    "__pycache__", "*.egg-info", ".pytest_cache")
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "scenefit"
        shutil.copytree(ROOT, stage, ignore=ignore)
        manifest = stage / "blender_manifest.toml"
        write_atomic(manifest, set_manifest_list(manifest.read_text(encoding="utf-8"), "wheels", []))
        return build(stage, out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("command", choices=["wheels", "build", "nowheels", "validate"])
    parser.add_argument("--platform", default="linux-x64", choices=list(PLATFORMS))
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.command == "wheels":
        wheels = download(args.platform)
        write_wheels_into_manifest(wheels, args.platform)
        print(f"{len(wheels)} wheels, {sum(w.stat().st_size for w in wheels) / 2**20:.0f} MiB; manifest updated")
    elif args.command == "build":
        print(build(ROOT, args.out or DIST / f"scenefit-{version()}-{args.platform}.zip"))
    elif args.command == "validate":
        subprocess.run([sys.executable, str(blender_ext()), "validate", str(ROOT)], check=True)
    else:
        print(build_without_wheels(args.out))


if __name__ == "__main__":
    main()
