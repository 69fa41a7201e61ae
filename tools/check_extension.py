"""`make check-extension`: the real platform zip, installed the way users install it, runs the pipeline.

    python tools/check_extension.py [--platform linux-x64] [--zip dist/scenefit-...zip] [--bpy 4.2.0] [--keep]

1. builds dist/scenefit-<version>-<platform>.zip with its wheels (unless --zip is given);
2. makes a fresh virtual environment holding only the `bpy` module (the version this checkout
   tests with, or --bpy: 4.2.0 is the oldest the manifest allows, whose compositor API differs), so
   nothing of the development environment can stand in for a missing wheel;
3. installs the zip into a throwaway Blender user folder with Blender's own extension installer;
4. on a scene made there (textured sphere, a photo), runs convert -> estimate light -> compose
   (-> bake_asset when the extension has it) through EXEC_DEFAULT and checks each finishes, that the
   artist's scene (their engine, resolution, colour management, camera and compositor with a Glare
   node, set up as that Blender version stores it) is as it was, and that Open Image Denoise (pyoidn,
   the core composite's denoiser) loads where it is bundled.

Slow (downloads a few hundred MB once, then minutes): not part of `make test`.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import build_extension  # noqa: E402

# Runs inside the bare bpy environment: nothing of SceneFit is importable except the installed zip.
SCRIPT = r"""
import json, sys, time
from pathlib import Path
import numpy as np
import bpy

zip_path, work = sys.argv[-2], Path(sys.argv[-1])
module = "bl_ext.user_default.scenefit"
report = {"steps": {}}
t = time.perf_counter()
bpy.ops.extensions.package_install_files(repo="user_default", filepath=zip_path, enable_on_install=True)
report["enabled"] = module in bpy.context.preferences.addons
report["install_s"] = round(time.perf_counter() - t, 1)
common = __import__(module + ".operators.dependencies", fromlist=["missing_modules"])
report["missing_modules"] = common.missing_modules()
report["oidn"] = __import__(module + ".core.render.denoise", fromlist=["oidn_available"]).oidn_available()
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
obj = bpy.context.active_object
image = bpy.data.images.new("color", 64, 64)
pixels = np.ones((64, 64, 4), np.float32)
pixels[..., :3] = np.random.default_rng(0).uniform(0.1, 0.9, (64, 64, 3))
image.pixels.foreach_set(pixels.ravel())
mat = bpy.data.materials.new("Asset")
if mat.node_tree is None:   # Blender 4.x makes a material without nodes
    mat.use_nodes = True
tex = mat.node_tree.nodes.new("ShaderNodeTexImage"); tex.image = image
mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
obj.data.materials.append(mat)
photo = bpy.data.images.new("photo", 96, 64)
photo.pixels.foreach_set(np.random.default_rng(1).uniform(0.2, 0.8, 96 * 64 * 4).astype(np.float32))
photo.filepath_raw, photo.file_format = str(work / "photo.png"), "PNG"
photo.save()
# The artist's own scene: their engine, resolution, look, camera and compositor (Blender 5 keeps a
# compositor node group per scene; 4.x the scene's own node tree).
scene = bpy.context.scene
engines = [e.identifier for e in type(scene.render).bl_rna.properties["engine"].enum_items]
scene.render.engine = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"
scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
scene.view_settings.view_transform, scene.view_settings.exposure = "AgX", 0.7
camera = bpy.data.objects.new("ArtistCam", bpy.data.cameras.new("ArtistCam"))
scene.collection.objects.link(camera)
camera.location = (4.0, -4.0, 3.0)
scene.camera = camera
if hasattr(scene, "compositing_node_group"):
    tree = bpy.data.node_groups.new("Artist Compositor", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    scene.compositing_node_group = tree
else:
    scene.use_nodes = True
    tree = scene.node_tree
layers, glare = tree.nodes.new("CompositorNodeRLayers"), tree.nodes.new("CompositorNodeGlare")
tree.links.new(layers.outputs["Image"], glare.inputs["Image"])
report["blender"] = bpy.app.version_string

def artist_scene():
    scene = bpy.data.scenes[report["artist_scene"]]
    tree = scene.compositing_node_group if hasattr(scene, "compositing_node_group") else scene.node_tree
    return {"engine": scene.render.engine, "resolution": [scene.render.resolution_x, scene.render.resolution_y],
            "look": [scene.view_settings.view_transform, round(scene.view_settings.exposure, 3)],
            "film_transparent": scene.render.film_transparent, "camera": scene.camera.name if scene.camera else None,
            "compositor": sorted(n.bl_idname for n in tree.nodes) if tree else None,
            "camera_at": [round(v, 4) for v in bpy.data.objects["ArtistCam"].location]}

report["artist_scene"] = scene.name
before = artist_scene()
bpy.ops.wm.save_as_mainfile(filepath=str(work / "check.blend"))
s = bpy.context.scene.scenefit
s.photo_path, s.preset, s.placement = str(work / "photo.png"), "draft", (0.5, 0.8)
steps = [("convert", lambda: bpy.ops.scenefit.convert(iterations=50)),
         ("light", lambda: bpy.ops.scenefit.estimate_light(critic="none", outpaint="prior")),
         ("compose", lambda: bpy.ops.scenefit.compose(samples=4))]
if "bake_asset" in dir(bpy.ops.scenefit):
    steps.append(("bake", lambda: bpy.ops.scenefit.bake_asset()))
for name, run in steps:
    t = time.perf_counter()
    try:
        result = sorted(run())
    except Exception as error:  # the report says which step broke and how
        result = [f"{type(error).__name__}: {error}"]
    report["steps"][name] = {"result": result, "seconds": round(time.perf_counter() - t, 1)}
after = artist_scene()
report["artist_scene_changed"] = {k: [before[k], after[k]] for k in before if before[k] != after[k]}
print("JSON" + json.dumps(report))
"""


def zip_wheels(zip_path: Path) -> list[str]:
    import zipfile

    with zipfile.ZipFile(zip_path) as z:
        return [n for n in z.namelist() if n.endswith(".whl")]


def bare_bpy_env(folder: Path, version: str | None = None) -> Path:
    """A venv with only the bpy module (`version`, else this checkout's); returns its python."""
    version = version or importlib.metadata.version("bpy")
    subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True)
    python = folder / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", f"bpy=={version}"], check=True)
    return python


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--platform", default="linux-x64", choices=list(build_extension.PLATFORMS))
    parser.add_argument("--zip", type=Path, help="an already built platform zip")
    parser.add_argument("--bpy", help="the bpy (Blender) version to install into, e.g. 4.2.0 (default: this checkout's)")
    parser.add_argument("--keep", action="store_true", help="keep the work folder (venv, user folder, outputs)")
    args = parser.parse_args(argv)
    zip_path = args.zip
    if zip_path is None:
        build_extension.main(["wheels", "--platform", args.platform])
        zip_path = build_extension.DIST / f"scenefit-{build_extension.version()}-{args.platform}.zip"
        build_extension.main(["build", "--platform", args.platform, "--out", str(zip_path)])
    work = Path(tempfile.mkdtemp(prefix="scenefit-check-"))
    t = time.perf_counter()
    python = bare_bpy_env(work / "venv", args.bpy)
    print(f"bare bpy environment in {time.perf_counter() - t:.0f} s", flush=True)
    (work / "user").mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["BLENDER_USER_RESOURCES"] = str(work / "user")
    proc = subprocess.run([str(python), "-c", SCRIPT, str(zip_path.resolve()), str(work)], capture_output=True,
                          text=True, env=env, cwd=work)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("JSON")), None)
    if line is None:
        print(proc.stdout[-4000:], proc.stderr[-4000:])
        print(f"check-extension: the run in the bare bpy environment failed (exit {proc.returncode}).")
        return 1
    report = json.loads(line[4:])
    report["zip"], report["zip_mb"] = str(zip_path), round(zip_path.stat().st_size / 2**20)
    print(json.dumps(report, indent=2))
    oidn_bundled = any(Path(w).name.startswith("pyoidn-") for w in zip_wheels(zip_path))
    ok = report["enabled"] and not report["missing_modules"] and not report["artist_scene_changed"] and all(
        step["result"] == ["FINISHED"] for step in report["steps"].values()) and (report["oidn"][0] or not oidn_bundled)
    if not args.keep:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
    print("check-extension:", "passed" if ok else "FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
