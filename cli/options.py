"""What several commands share: loading an asset, the progress display, the lighting options, the
model options. Declared once so an option means the same thing in every command."""
from __future__ import annotations

import argparse
import math

from ..core.base.names import PRESETS, SCENE_TYPES


# -- option types: a bad value is refused by argparse (one line, exit 2) before any work ---------------
def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def render_side(text: str) -> int:
    """An image side in pixels, at most what SceneFit renders (core/base/limits.py says why)."""
    from ..core.base.limits import MAX_RENDER_SIDE

    value = positive_int(text)
    if value > MAX_RENDER_SIDE:
        raise argparse.ArgumentTypeError(f"--size {value} is larger than {MAX_RENDER_SIDE} px, the most SceneFit "
                                         "renders (memory grows with its square); give a smaller size")
    return value


def count_up_to(most: int, what: str):
    """An argparse type: a whole number from 1 to `most` (a count the run makes that many of)."""
    def count(text: str) -> int:
        value = positive_int(text)
        if value > most:
            raise argparse.ArgumentTypeError(f"at most {most} {what}, got {value}")
        return value

    return count


MAX_VIEWS = 360        # one view per degree around the asset
MAX_SPP = 65536        # as compose's samples: past it the noise no longer shows at 8 bits


def finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def nonnegative_float(text: str) -> float:
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be zero or more, got {text!r}")
    return value


def positive_float(text: str) -> float:
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be more than zero, got {text!r}")
    return value


def placement_point(text: str) -> tuple[float, float]:
    """--at X,Y: where the object stands (every command; core/scene/placement.py parse_point says what is taken)."""
    from ..core.base.errors import InputError
    from ..core.scene.placement import parse_point

    try:
        return parse_point(text)
    except InputError as error:
        raise argparse.ArgumentTypeError(str(error).removeprefix("--at ").rstrip(".")) from None


def add_output_args(p: argparse.ArgumentParser, default: str | None = None, help: str = "output folder",
                    required: bool = True) -> None:
    """--out and --replace: the run's folder is written whole (see core/base/output_folder.py). `required`
    False: the command checks it itself (its --dry-run needs none)."""
    if default is None:
        p.add_argument("--out", required=required, help=help)
    else:
        p.add_argument("--out", default=default, help=f"{help} (default {default})")
    p.add_argument("--replace", action="store_true",
                   help="replace the output folder when it already holds files (default: refuse)")


# Every option that names a file or folder the command reads: an --out may never be or hold one.
INPUT_OPTIONS = ("asset", "photo", "texture", "light", "envmap", "jobs", "fspy", "base_model", "inpaint_model",
                 "depth_model", "cache_dir")


def input_paths(args) -> list[str]:
    return [str(getattr(args, name)) for name in INPUT_OPTIONS if getattr(args, name, None)]


def output(args, resume: bool = False, reuse: bool = False):
    """The run's output folder as a context manager yielding the folder to write into."""
    from ..core.base.output_folder import output_folder

    args.resumable = resume
    return output_folder(args.out, replace=args.replace, resume=resume, inputs=input_paths(args), reuse=reuse)


def load_asset(path: str, object_name: str | None = None):
    """(Mesh, PBRMaps) from an asset folder, or from a file Blender reads (needs bpy)."""
    from ..blender_io.asset_file import load_asset as load

    return load(path, object_name)


def progress(args):
    from ..core.base.progress import TerminalProgress

    return None if getattr(args, "quiet", False) else TerminalProgress()


def environment(args):
    """(environment map, label) from --envmap, --studiolight or --ambient."""
    from ..core.render.photo import studiolight_path
    from ..core.render.environment import constant_environment, load_environment

    if getattr(args, "envmap", None):
        return load_environment(args.envmap), f"environment map {args.envmap}"
    if getattr(args, "studiolight", None):
        return load_environment(studiolight_path(args.studiolight)), f"Blender studio light '{args.studiolight}'"
    value = float(getattr(args, "ambient", 1.0))
    return constant_environment([value] * 3), f"constant environment of radiance {value}"


def add_asset_args(p: argparse.ArgumentParser, optional: bool = False) -> None:
    """The asset argument; `optional` for commands whose --dry-run needs none."""
    p.add_argument("asset", nargs="?" if optional else None,
                   help="a SceneFit asset folder (mesh.npz + maps), a .blend/.glb/.gltf/.obj/.fbx file, or the folder "
                        "a downloaded asset came in (its one such file)")
    p.add_argument("--object", help="the object (a mesh, or a node such as an empty) to take from the asset "
                                    "file, with every mesh under it (default: every mesh object of the file, as "
                                    "one asset)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and nothing printed but errors")


def add_lighting_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--envmap", help="equirectangular HDR map (EXR/HDR) to light the asset")
    p.add_argument("--studiolight", help="one of Blender's bundled HDR maps (studio, interior, city, forest, ...)")
    p.add_argument("--ambient", type=nonnegative_float, default=1.0, help="constant environment radiance when no map is given")


def add_model_args(p: argparse.ArgumentParser) -> None:
    """Where the diffusion models come from (adapt, light, ...)."""
    p.add_argument("--base-model", help="hub id or folder (default stabilityai/stable-diffusion-2-base)")
    p.add_argument("--inpaint-model", help="hub id or folder (default stabilityai/stable-diffusion-2-inpainting)")
    p.add_argument("--cache-dir", help="Hugging Face cache folder to look in")
    p.add_argument("--offline", action="store_true",
                   help="never use the network: no model downloads (also HF_HUB_OFFLINE=1), template prompts")


def model_config(args):
    from ..core.guidance import ModelConfig

    return ModelConfig(**{k: v for k, v in (("base_model", args.base_model), ("inpaint_model", args.inpaint_model),
                                            ("cache_dir", args.cache_dir)) if v}, local_files_only=args.offline)



def add_preset_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", choices=PRESETS, default="balanced",
                   help="draft / balanced / final (the paper's values); core/pipeline/presets.py says what each changes")


def add_elevation_arg(p: argparse.ArgumentParser, default: float | None = None) -> None:
    """--elevation: the orbit camera's angle above the object's horizon (render, export, adapt's views).
    The photo's camera is another angle with its own name and sign: --pitch (add_photo_camera_args)."""
    p.add_argument("--elevation", type=finite_float, default=default,
                   help="degrees above the horizon from which the camera sees the object"
                        + (f" (default {default:g})" if default is not None else " (default: the stage's)"))


def add_orbit_camera_args(p: argparse.ArgumentParser, size: int, spp: int) -> None:
    """The orbit camera of `render` and `export`: --elevation (default 15), --size (pixels), --spp."""
    add_elevation_arg(p, default=15.0)
    p.add_argument("--size", type=render_side, default=size, help=f"image side in pixels (default {size})")
    p.add_argument("--spp", type=count_up_to(MAX_SPP, "samples per pixel"), default=spp,
                   help=f"samples per pixel (default {spp})")


def add_photo_camera_args(p: argparse.ArgumentParser) -> None:
    """The photo's camera (core/stages/camera.py): estimated from fSpy, EXIF or the photo's lines unless
    given; each value given wins over the estimate (`scenefit camera` shows what is found)."""
    p.add_argument("--fspy", help="an fSpy project of the photo: its solved camera is used")
    p.add_argument("--fov", type=positive_float, help="the photo's horizontal field of view, degrees (default: estimated)")
    p.add_argument("--pitch", type=finite_float,
                   help="where the camera looks above the horizon, degrees; negative looks down (default: estimated)")
    p.add_argument("--roll", type=finite_float, help="how far the camera is turned counter-clockwise about its view "
                                                     "axis, degrees (default: estimated)")


def sun_angles(text: str) -> tuple[float, float]:
    """--sun AZ,EL: two angles in degrees, the elevation within +-90."""
    try:
        az, el = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sun takes two angles in degrees as AZ,EL, got '{text}'; "
                                         f"give e.g. --sun 30,45.") from None
    if not (math.isfinite(az) and math.isfinite(el) and -90.0 <= el <= 90.0):
        raise argparse.ArgumentTypeError(f"--sun's elevation must be within +-90 degrees (and both angles "
                                         f"finite), got '{text}'; give e.g. --sun 30,45.")
    return az, el


def add_scene_arg(p: argparse.ArgumentParser, default: str | None = None) -> None:
    p.add_argument("--scene", choices=SCENE_TYPES, default=default,
                   help="the photo's scene type for the light stage (default: decided from the photo)")


def add_sun_args(p: argparse.ArgumentParser) -> None:
    """The artist's dominant light (core/stages/light/cues.py trusts it: a narrower lobe than the guess's)."""
    sun = p.add_mutually_exclusive_group()
    sun.add_argument("--sun", type=sun_angles, metavar="AZ,EL",
                     help="the dominant light's direction in degrees: azimuth from the photo's view direction, "
                          "positive to the right (90: from the right, 180: from behind the camera), elevation above "
                          "the horizon; the unseen light is centred there (default: guessed from the photo)")
    sun.add_argument("--sun-from-shadow", nargs=3, metavar=("FOOT", "TOP", "TIP"),
                     help="the sun from a shadow in the photo: the foot of something upright on the floor, its top, "
                          "and the tip of its shadow, each X,Y as --at takes it")


def photo_pitch(args) -> float | None:
    """--pitch, or the old --elevation of light and compose (how far the camera looks down: -pitch)."""
    if getattr(args, "pitch", None) is not None:
        return args.pitch
    old = getattr(args, "photo_elevation", None)
    return None if old is None else -old


def add_old_photo_elevation_arg(p: argparse.ArgumentParser) -> None:
    """light and compose once called the photo's down-tilt --elevation, which render, export and adapt
    use for the orbit camera: still read (as -pitch), no longer shown."""
    p.add_argument("--elevation", dest="photo_elevation", type=finite_float, help=argparse.SUPPRESS)


def add_placement_args(p: argparse.ArgumentParser, required: bool = False, object_size: float | None = None) -> None:
    """Where the object goes in the photo (core/scene/placement.py): --at, and --object-size unless the
    command has no use for it (object_size None)."""
    from ..core.scene.placement import DEFAULT_AT

    p.add_argument("--at", required=required, type=placement_point, default=None if required else DEFAULT_AT,
                   help="X,Y of the object in the photo: fractions of its width and height (both <= 1), or pixels of "
                        "the photo as stored" + ("" if required else f" (default {DEFAULT_AT[0]:g},{DEFAULT_AT[1]:g})"))
    if object_size is not None:
        p.add_argument("--object-size", type=positive_float, default=object_size,
                       help=f"the fraction of the photo's height the object spans (default {object_size:g})")


def placement(args, photo_hw: tuple[int, int]):
    """The Placement of --at and --object-size in a photo of photo_hw, as stored (one parser, one error
    message)."""
    from ..core.scene.placement import DEFAULT_OBJECT_SIZE, Placement

    return Placement.parse(args.at, (photo_hw[1], photo_hw[0]), getattr(args, "object_size", DEFAULT_OBJECT_SIZE))


def add_dry_run_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dry-run", action="store_true",
                   help="print the resolved configuration as JSON and exit (nothing is loaded or written)")


def print_config(config: dict) -> int:
    """--dry-run: the resolved configuration, as JSON on stdout."""
    import json

    print(json.dumps(config, indent=2, default=str))
    return 0


def require(args, *names: str) -> None:
    """Options a command needs unless it is a --dry-run: one sentence naming the missing ones."""
    from ..core.base.errors import InputError

    missing = [n for n in names if not getattr(args, n.lstrip("-").replace("-", "_"), None)]
    if missing:
        raise InputError(f"`scenefit {args.command}` needs {' and '.join(missing)} (only --dry-run runs without).")


def add_prompt_service_args(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """The chat endpoint that writes scene-conditional prompts. `prefix` ("prompt-") keeps them apart
    from a command's own --model/--timeout; dests are the same either way."""
    p.add_argument(f"--{prefix}endpoint", dest="prompt_endpoint", default="", metavar="URL",
                   help="OpenAI-compatible base URL, e.g. http://127.0.0.1:8080/v1 (also: config file, OPENAI_BASE_URL)")
    p.add_argument(f"--{prefix}model", dest="prompt_model", default="", metavar="NAME", help="chat model name at that endpoint")
    p.add_argument(f"--{prefix}timeout", dest="prompt_timeout", type=positive_float, metavar="S", help="seconds to wait for the answer (default 60)")
    p.add_argument(f"--{'prompt-' if prefix else ''}vision", dest="prompt_vision", action=argparse.BooleanOptionalAction,
                   help="the model reads images: send the photo (default: guessed from the model name)")
    p.add_argument("--prompt-cache", metavar="DIR", help="folder of cached answers (default ~/.cache/scenefit/prompts)")
    p.add_argument("--no-prompt-cache", action="store_true", help="always ask the model, never reuse an answer")
    p.add_argument("--config", metavar="FILE", help="config file with a [prompting] table (default ~/.config/scenefit/config.toml)")


def write_prompt_from_args(args, object_prompt: str, scene_prompt: str, mode_type: str, photo: str = "",
                           stream: bool = False, follow_up: str = ""):
    """A PromptResult from the prompt-service options (a template one when offline)."""
    from pathlib import Path

    from ..core.guidance.prompting import PromptRequest, resolve_service, write_prompt

    request = PromptRequest(object_prompt=object_prompt or "", scene_prompt=scene_prompt or "", mode_type=mode_type,
                            photo=photo or "", follow_up=follow_up or "")
    vision = {True: "yes", False: "no", None: ""}[args.prompt_vision]
    offline = bool(getattr(args, "offline", False))
    # Offline the config file is not even read: nothing about the service matters then.
    service = None if offline else resolve_service(
        args.prompt_endpoint, args.prompt_model, timeout_s=args.prompt_timeout, vision_type=vision, stream=stream,
        config_path=Path(args.config) if args.config else None)
    # Not bpy.app.online_access: bpy as a module (loaded here only to read .blend files) starts with
    # it off, and on the command line --offline is the user's switch. The Blender operator passes it.
    return write_prompt(request, service, offline=offline,
                        cache_dir=Path(args.prompt_cache) if args.prompt_cache else None,
                        use_cache=not args.no_prompt_cache)


def scene_conditional_prompt(args, mode: str):
    """(prompt, instruction, record) for the run: the user's --prompt/--instruction when given, else
    written from --object-prompt and --scene-prompt (a description; edit mode: an instruction)."""
    prompt, instruction, photo = args.prompt or "", getattr(args, "instruction", None) or "", args.photo or ""
    given = prompt or (instruction if mode == "edit" else "")
    if given or not args.object_prompt or not (args.scene_prompt or (photo and mode == "scene")):
        return prompt, instruction, None
    result = write_prompt_from_args(args, args.object_prompt, args.scene_prompt, "instruct" if mode == "edit" else "describe",
                                    photo if mode == "scene" else "")
    source = f"written by '{result.model}'" if result.model_written else f"template ({result.reason})"
    print(f"prompt ({source}): {result.prompt}")
    if mode == "edit":
        return prompt, result.prompt, result
    return result.prompt, instruction, result
