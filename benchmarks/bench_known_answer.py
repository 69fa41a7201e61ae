"""Known-answer adaptation: does the adapt stage drive a texture where the prompt or the scene says?

The models are the known-answer prior (devtools/prior, taught by devtools/prior_data.py) and, as the
control, the random tiny models of the same loading path (devtools/tiny_models.py). Everything else is a
user's run: a corpus asset the prior never saw, photos cut from corpus HDR panoramas (the prior saw no
photo at all), a jobs file's whole pipeline through `scenefit batch` (convert, light, adapt, compose), the
critic chosen by each job's `overrides = { adapt = { critic = { critic_type = ... } } }`, at the draft
preset with the models swapped and the stage overrides given on the command line (`--adapt`, `--light`,
JSON), which the results page states.

Measured on the adapted asset, against devtools/known_prior.answer():
- text rule (a colour word): the mean colour of the asset rendered under a constant white environment
  (every pixel it covers, 8 views around it) falls to <= 35 % of the start's distance to the word's colour;
- scene rule (no colour word, scene mode): the mean base colour over the texels the views show moves
  its chroma toward the photo's hue: its hue within 30 deg of the photo's, moved >= 0.05 (sRGB) toward it.

`python benchmarks/bench_known_answer.py [--quick] [--adapt JSON] [--light JSON]` writes
results/known_answer.md and .json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_files import machine_load, write_results  # noqa: E402

CORPUS = ROOT.parent / "shared" / "corpus"
PRIOR = ROOT / "devtools" / "prior"
SCENEFIT = Path(sys.executable).parent / "scenefit"
TEXT_LIMIT, ANGLE_LIMIT, MOVE_LIMIT = 0.35, 30.0, 0.05
# (corpus asset, its file, the noun prompts name it by: held out of the prior's training prompts)
ASSETS = (("khronos_Fox", "Fox.glb", "fox"),)
# (corpus HDR panorama, yaw of the photo cut from it)
PHOTOS = (("aristea_wreck_puresky_1k.hdr", 0.0), ("noon_grass_1k.hdr", 90.0))


@dataclass(frozen=True)
class Case:
    name: str
    mode: str             # scene | generate | edit
    critic: str           # sds | vsd
    prompt: str = ""
    object_prompt: str = ""
    instruction: str = ""

    @property
    def rule(self) -> str:
        from scenefit.devtools.known_prior import colour_word

        words = colour_word(self.prompt) or colour_word(self.instruction)
        return "text" if words else "scene"


def cases(noun: str) -> list[Case]:
    """Every mode with SDS and VSD; nouns the prior's training prompts never held."""
    return [
        Case("scene-text-sds", "scene", "sds", prompt=f"a red {noun}"),
        Case("scene-text-vsd", "scene", "vsd", prompt=f"a blue {noun}"),
        Case("scene-rule-sds", "scene", "sds", prompt=f"a {noun}"),
        Case("scene-rule-vsd", "scene", "vsd", prompt=f"a {noun}"),
        Case("generate-sds", "generate", "sds", prompt=f"a green {noun}"),
        Case("generate-vsd", "generate", "vsd", prompt=f"a green {noun}"),
        Case("edit-sds", "edit", "sds", object_prompt=f"a {noun}", instruction="make it yellow"),
        Case("edit-vsd", "edit", "vsd", object_prompt=f"a {noun}", instruction="make it blue"),
    ]


def make_photo(hdr_name: str, yaw: float, out: Path) -> Path:
    import cv2

    from scenefit.core.data.imageio import read_image
    from scenefit.core.render.photo import develop_photo, perspective_view
    from scenefit.core.scene.camera import PhotoCamera

    hdr = read_image(CORPUS / "hdri" / hdr_name)[..., :3]
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=-10.0, fov_deg=60.0, width=320, height=240)
    photo = develop_photo(perspective_view(hdr, camera))
    cv2.imwrite(str(out), photo[..., ::-1])
    return out


def import_asset(name: str, file: str, out: Path) -> Path:
    """The corpus asset read by the project's importer (Blender) into a SceneFit asset folder, once."""
    if (out / "mesh.npz").is_file():
        return out
    code = ("from scenefit.blender_io.asset_file import load_asset\n"
            "from scenefit.core.data.asset_io import save_asset_folder\n"
            f"mesh, maps = load_asset({str(CORPUS / 'assets' / name / file)!r})\n"
            f"save_asset_folder(mesh, maps, {str(out)!r})\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
    return out


def _toml(value) -> str:
    """A TOML value (strings, numbers, lists and inline tables)."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    return json.dumps(value)


def jobs_file(cases_: list[Case], asset: Path, photos: list[Path], models: tuple[Path, Path], adapt: dict,
              light: dict, out: Path) -> Path:
    """One jobs file: every case on every photo, the critic (and `adapt`'s settings) as the job's stage
    overrides, the models in its [models] table."""
    lines = ["[models]", f"base_model = {_toml(str(models[0]))}", f"inpaint_model = {_toml(str(models[1]))}",
             "local_files_only = true", ""]
    for photo in photos:
        for case in cases_:
            if case.mode != "scene" and photo != photos[0]:
                continue   # generate and edit do not look at the photo: once is enough
            fields = {"name": f"{case.name}-{photo.stem}", "asset": str(asset), "photo": str(photo),
                      "at": [0.5, 0.75], "preset": "draft", "mode": case.mode,
                      "stages": ["convert", "light", "adapt", "compose"]}
            fields.update({k: getattr(case, k) for k in ("prompt", "object_prompt", "instruction") if getattr(case, k)})
            overrides = {"adapt": {**adapt, "critic": {"critic_type": case.critic}}}
            if light:
                overrides["light"] = light
            lines += ["[[job]]", *(f"{k} = {_toml(v)}" for k, v in fields.items()), f"overrides = {_toml(overrides)}", ""]
    out.write_text("\n".join(lines))
    return out


def run_batch(jobs: Path, out: Path) -> float:
    """`scenefit batch` as a user runs it; returns its seconds."""
    t = time.perf_counter()
    proc = subprocess.run([str(SCENEFIT), "batch", str(jobs), "--out", str(out), "--quiet"], capture_output=True,
                          text=True, cwd=jobs.parent)
    if proc.returncode != 0:
        raise RuntimeError(f"scenefit batch {jobs} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return time.perf_counter() - t


def _adapt_seconds(folder: Path) -> float:
    """The adapt stage's own seconds, from its stage.json."""
    report = json.loads((folder / "adapt" / "stage.json").read_text()).get("report", {})
    return float(report.get("seconds", float("nan")))


# -- measuring ------------------------------------------------------------------------------------------

def _maps_of(folder: Path) -> np.ndarray:
    """(H, W, 5) linear base colour, roughness, metallic from a stage's maps/ folder."""
    from scenefit.core.data.imageio import read_image
    from scenefit.core.data.imageio import srgb_to_linear

    base = srgb_to_linear(read_image(folder / "base_color.png")[..., :3].astype(np.float32))
    h, w = base.shape[:2]
    channels = [base]
    for name, default in (("roughness", 0.5), ("metallic", 0.0)):
        path = folder / f"{name}.png"
        channels.append(read_image(path)[..., :1].astype(np.float32) if path.is_file()
                        else np.full((h, w, 1), default, np.float32))
    return np.concatenate(channels, axis=2)


def measure_maps(mesh, maps: np.ndarray, views: int = 8, size: int = 96, spp: int = 16) -> dict:
    """Mean sRGB colour of the asset rendered under a constant white environment, and mean sRGB base colour
    of the texels the views show, over `views` orbit views at 20 deg elevation."""
    import torch

    from scenefit.core.data.mesh import normalize_to_unit_sphere
    from scenefit.core.data.imageio import linear_to_srgb
    from scenefit.core.render.orbit_camera import orbit_cameras
    from scenefit.core.render.renderer import AssetRenderer, SceneOptions

    mesh, _ = normalize_to_unit_sphere(mesh)
    white = np.ones((16, 32, 3), np.float32)
    renderer = AssetRenderer(mesh, maps.shape[:2], white, SceneOptions(hide_emitters=True))
    stack = torch.from_numpy(np.ascontiguousarray(maps, np.float32))
    rendered, albedo = [], []
    for camera in orbit_cameras(views, 20.0, size=size):
        with torch.no_grad():
            out = renderer.render(camera, stack[..., 0:3], stack[..., 3:4], stack[..., 4:5], torch.from_numpy(white),
                                  spp=spp, seed=0)
        alpha = out.alpha[..., 0].numpy()
        rgb = out.rgb.numpy() / np.maximum(alpha[..., None], 1e-6)
        rendered.append(linear_to_srgb(np.clip(rgb, 0, 1))[alpha > 0.99])
        seen = renderer.render_albedo(camera, maps)
        albedo.append(linear_to_srgb(np.clip(seen[..., :3], 0, 1))[seen[..., 3] > 0])
    return {"rendered": np.concatenate(rendered).mean(axis=0).tolist(),
            "base_colour": np.concatenate(albedo).mean(axis=0).tolist()}


def judge(case: Case, start: dict, end: dict, photo_srgb: np.ndarray) -> dict:
    from scenefit.devtools.known_prior import answer, distance, photo_hue, toward_hue
    from scenefit.core.stages.adapt import edit_prompt

    prompt = case.prompt or edit_prompt(case.object_prompt, case.instruction)
    if case.rule == "text":
        target = answer(prompt)
        before, after = distance(start["rendered"], target), distance(end["rendered"], target)
        ratio = after / before
        return {"target": list(target), "start_distance": round(before, 4), "end_distance": round(after, 4),
                "ratio": round(ratio, 3), "reached": ratio <= TEXT_LIMIT}
    hue = photo_hue(photo_srgb)
    angle, moved = toward_hue(start["base_colour"], end["base_colour"], hue)
    return {"photo_hue_deg": round(hue, 1), "angle_deg": round(angle, 1), "chroma_move": round(moved, 4),
            "reached": angle <= ANGLE_LIMIT and moved >= MOVE_LIMIT}


def generate_start(mesh, maps_shape: tuple[int, int]) -> np.ndarray:
    """What generate mode starts from: the draft preset's fresh neural texture (seed 0), baked."""
    from scenefit.core.data.uv_raster import rasterize_uv
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.texture import NeuralTexture
    from scenefit.core.texture.bake import bake_texture

    config = stage_config("adapt", "draft", mode_type="generate", prompt="x")
    raster = rasterize_uv(mesh, maps_shape[0])
    from dataclasses import replace

    texture = NeuralTexture(replace(config.texture, resolution=maps_shape[0]), seed=config.seed)
    return bake_texture(texture, raster.position, raster.border, raster.fill_index)


def bench_known_answer(results: Path, quick: bool = False, adapt: dict | None = None, light: dict | None = None,
                       control: bool = True) -> dict:
    from scenefit.core.data.asset_io import load_asset_folder
    from scenefit.core.data.imageio import read_image
    from scenefit.devtools.tiny_models import build_tiny_pair

    adapt = dict(adapt or {})
    light = dict(light or {})
    load = [machine_load()]
    rows = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="scenefit-known-answer-") as tmp:
        tmp = Path(tmp)
        model_sets = {"prior": (PRIOR / "base", PRIOR / "inpaint")}
        if control:
            model_sets["control (random tiny)"] = build_tiny_pair(tmp / "tiny")
        for asset_name, file, noun in ASSETS:
            asset = import_asset(asset_name, file, tmp / "assets" / asset_name)
            mesh, _ = load_asset_folder(asset)
            photos = [make_photo(hdr, yaw, tmp / f"{Path(hdr).stem}.png") for hdr, yaw in PHOTOS[:1 if quick else None]]
            chosen = [c for c in cases(noun) if not quick or c.name in ("scene-text-sds", "scene-rule-sds")]
            for label, models in model_sets.items():
                key = label.split()[0]
                jobs = jobs_file(chosen, asset, photos, models, adapt, light, tmp / f"jobs-{key}.toml")
                batch_s = run_batch(jobs, tmp / f"batch-{key}")
                load.append(machine_load())
                for photo in photos:
                    photo_srgb = read_image(photo)[..., :3].astype(np.float32)
                    for case in chosen:
                        folder = tmp / f"batch-{key}" / f"{case.name}-{photo.stem}"
                        if not folder.is_dir():
                            continue
                        adapted = _maps_of(folder / "adapt" / "maps")
                        start_maps = (generate_start(mesh, adapted.shape[:2]) if case.mode == "generate"
                                      else _maps_of(folder / "convert" / "maps"))
                        start, end = measure_maps(mesh, start_maps), measure_maps(mesh, adapted)
                        row = {"models": label, "asset": asset_name, "photo": photo.stem, "case": case.name,
                               "mode": case.mode, "critic": case.critic, "rule": case.rule, "prompt": case.prompt,
                               "instruction": case.instruction, "start": start, "end": end,
                               **judge(case, start, end, photo_srgb), "adapt_s": round(_adapt_seconds(folder), 1),
                               "batch_s": round(batch_s, 1)}
                        rows.append(row)
                        print(json.dumps(row), flush=True)
    data = {"commit": _commit(), "machine": f"{platform.node()} ({platform.processor() or platform.machine()}, "
                                            f"{os.cpu_count()} cores)",
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "load": load,
            "adapt_overrides": adapt, "light_overrides": light, "seconds": round(time.perf_counter() - started),
            "rows": rows}
    write_results(results, "known_answer", markdown(data), data)
    return data


def _commit() -> str:
    proc = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT)
    return proc.stdout.strip() or "unknown"


def markdown(data: dict) -> str:
    head = ["# Known-answer adaptation", "",
            f"Commit {data['commit']}, {data['machine']}, {data['date']}; load before and after the batches: "
            f"{data['load'][0]} ... {data['load'][-1]}. {data['seconds']} s in all.", "",
            f"`scenefit batch` on a jobs file per model set, the draft preset with the models swapped and these "
            f"stage overrides: adapt {json.dumps(data['adapt_overrides'])}, light {json.dumps(data['light_overrides'])} "
            f"(the critic per job). Text rule: the rendered mean colour's distance to the colour word's colour, end / "
            f"start, reached at <= {TEXT_LIMIT}. Scene rule: the mean base colour's hue within {ANGLE_LIMIT:.0f} deg of "
            f"the photo's and its chroma moved >= {MOVE_LIMIT} toward it.", "",
            "| models | photo | case | rule | measure | reached | adapt s |",
            "|---|---|---|---|---|---|---|"]
    body = []
    for r in data["rows"]:
        measure = (f"{r['start_distance']:.3f} -> {r['end_distance']:.3f} ({r['ratio']:.2f})" if r["rule"] == "text"
                   else f"hue {r['angle_deg']:.0f} deg off, moved {r['chroma_move']:+.3f} (photo hue "
                        f"{r['photo_hue_deg']:.0f})")
        body.append(f"| {r['models']} | {r['photo']} | {r['case']} | {r['rule']} | {measure} | "
                    f"{'yes' if r['reached'] else 'no'} | {r['adapt_s']} |")
    return "\n".join(head + body) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="two scene cases, one photo")
    parser.add_argument("--adapt", default="{}", help="adapt stage overrides (JSON), over the draft preset")
    parser.add_argument("--light", default="{}", help="light stage overrides (JSON), over the draft preset")
    parser.add_argument("--no-control", action="store_true", help="skip the random-weight control")
    parser.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results")
    args = parser.parse_args()
    bench_known_answer(args.results, args.quick, json.loads(args.adapt), json.loads(args.light), not args.no_control)
    return 0


if __name__ == "__main__":
    sys.exit(main())
