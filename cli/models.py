"""scenefit models: the models SceneFit uses (Stable Diffusion 2 base and inpainting, the depth model), whether
each is on this machine, how large and where; downloading (resumed after Ctrl-C) and removing them."""
from __future__ import annotations

ACTIONS = ("list", "download", "remove")
KEYS = ("base", "inpaint", "depth")


def run(args) -> int:
    from ..core.base.errors import InputError
    from ..core.guidance import model_store as store
    from ..core.guidance.models import hub_cache
    from .options import model_config

    config = model_config(args)
    specs = store.model_specs(config, args.depth_model)
    cache = hub_cache(config.cache_dir)
    chosen = [store.spec_named(specs, key) for key in (args.models or KEYS)]
    if args.action == "remove":
        if not args.models:
            raise InputError("Name the models to remove (base, inpaint, depth); nothing was removed.")
        for spec in chosen:
            freed = store.remove_model(spec, cache)
            _say(args, f"{spec.key}: removed {store.format_bytes(freed)} from {store.storage_folder(cache, spec.model)}"
                       if freed else f"{spec.key}: was not in {cache}")
    elif args.action == "download":
        from ..core.base.progress import TerminalProgress

        progress = None if args.quiet or args.json else store.in_megabytes(TerminalProgress())
        for spec in chosen:
            if store.model_state(spec, cache).state in (store.FOUND, store.FOLDER):
                _say(args, f"{spec.key}: already here")
                continue
            if config.offline:
                raise InputError(f"Downloading is off (--offline or HF_HUB_OFFLINE). {store.fetch_sentence(spec, cache)}")
            def announce(total: int, here: int, spec=spec) -> None:
                kept = f", {store.format_bytes(here)} of it already here" if here else ""
                _say(args, f"{spec.key}: downloading {spec.model}, {store.format_bytes(total)}{kept}, into {cache}")

            state = store.download_model(spec, cache, progress, announce=announce)
            _say(args, f"{spec.key}: {state.state}, {store.format_bytes(state.bytes_on_disk)} in {state.where}")
    return _list(args, specs, cache, config)


def _say(args, line: str) -> None:
    if not args.json:
        print(line)


def _list(args, specs, cache, config) -> int:
    import json

    from ..core.guidance import model_store as store
    from ..core.guidance.models import found_device, memory_options_for

    states = [store.model_state(spec, cache) for spec in specs]
    device = found_device()
    if args.json:
        print(json.dumps({"cache": str(cache), "offline": config.offline, "device": device,
                          "memory_options": list(memory_options_for(device)),
                          "models": [s.as_dict() for s in states]}, indent=2))
        return 0
    if args.action != "list":
        return 0
    print(f"cache  {cache}\ndevice {device} (memory options: {', '.join(memory_options_for(device))})")
    for s in states:
        about = f" (about {store.format_bytes(s.about_bytes)} to download)" if s.about_bytes and s.state in (
            store.MISSING, store.PARTIAL) else ""
        print(f"{s.key:<8} {s.state:<17} {store.format_bytes(s.bytes_on_disk):>9}  {s.where or '-'}{about}")
        if s.state in (store.MISSING, store.PARTIAL) and not config.offline:
            print(f"         scenefit models download {s.key}")
        elif s.state not in (store.FOUND, store.FOLDER):
            print(f"         {s.fetch}")
    return 0


def add_parser(sub) -> None:
    from .options import add_model_args

    p = sub.add_parser("models", help="the diffusion and depth models: found or missing, size, where; download "
                                      "(resumable) or remove them")
    p.add_argument("action", nargs="?", choices=ACTIONS, default="list",
                   help="list (default), download (the missing ones, or those named), remove (those named)")
    p.add_argument("models", nargs="*", metavar="MODEL",
                   help="base, inpaint or depth (default: all three)")
    add_model_args(p)
    p.add_argument("--depth-model", help="hub id or folder of the depth model (default "
                                         "depth-anything/Depth-Anything-V2-Small-hf)")
    p.add_argument("--json", action="store_true", help="print one JSON object: the cache, the device and each model")
    p.add_argument("--quiet", action="store_true", help="no progress bar and nothing printed but errors")
    p.set_defaults(func=run)
