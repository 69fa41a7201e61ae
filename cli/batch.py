"""scenefit batch: many asset x scene jobs from a jobs file, in this process or on a Ray cluster."""
from __future__ import annotations

import sys
from pathlib import Path


def run(args) -> int:
    from ..workers.batch import InProcessDispatcher, check_batch, run_batch
    from ..workers.batch_ray import RayDispatcher, connect, ray_available
    from ..workers.jobs import load_jobs

    jobs = load_jobs(args.jobs)
    reuse_from = Path(args.reuse_from) if args.reuse_from else None
    listed = check_batch(jobs, args.out, reuse_from)

    def say(name: str, message: str) -> None:
        if not args.quiet:
            print(f"[{name}] {message}", file=sys.stderr, flush=True)

    started_ray = False
    mode = args.ray
    if mode == "auto" and not ray_available():
        print("scenefit: Ray is not installed; running the jobs here, one after another.", file=sys.stderr)
        mode = None
    dispatcher: InProcessDispatcher | RayDispatcher
    try:
        if mode is None:
            dispatcher = InProcessDispatcher(jobs.settings, progress_sink=EventLines() if args.events else None)
            where = "in this process"
        else:
            started_ray = connect(mode, where_else=", or leave --ray out to run the jobs in this process")
            dispatcher = RayDispatcher(jobs.settings, len(jobs.jobs))
            where = f"on Ray ({dispatcher.workers} worker(s), each {dispatcher.options})"
        say("batch", f"{len(jobs.jobs)} job(s) from {jobs.path} {where}")
        outcomes = run_batch(jobs, args.out, dispatcher, on_event=say, redo=args.replace, reuse_from=reuse_from,
                             listed=listed)
    finally:
        if started_ray:
            import ray

            ray.shutdown()
    failed = [o.name for o in outcomes if o.status == "failed"]
    done = sum(o.status == "done" for o in outcomes)
    skipped = sum(o.status == "skipped" for o in outcomes)
    partial = [o.name for o in outcomes if o.skipped]
    print(f"batch: {done} done, {skipped} skipped (done before), {len(failed)} failed -> {args.out}/summary.md"
          + (f"; {', '.join(partial)} skipped stages (summary.md says which and why)" if partial else ""))
    if failed:
        print(f"scenefit: {len(failed)} job(s) failed ({', '.join(failed)}); their report.json says why; "
              f"run the same command again to retry them.", file=sys.stderr)
        return 1
    return 0


class EventLines:
    """Progress events as JSON lines on stdout (`--events`): how a caller in another process, such as
    the Blender add-on driving a local install with CUDA torch, follows the jobs. A preview becomes
    a PNG file beside the outputs, named in the line."""

    def __init__(self, stream=None) -> None:
        self.stream = stream or sys.stdout
        self.previews = 0

    def put_nowait(self, event: dict) -> None:
        import json
        import tempfile

        event = dict(event)
        preview = event.pop("preview", None)
        if preview is not None:
            from ..core.data.imageio import write_image

            self.previews += 1
            path = f"{tempfile.gettempdir()}/scenefit-preview-{__import__('os').getpid()}-{self.previews % 4}.png"
            event["preview_png"] = str(write_image(path, preview / 255.0))
        self.stream.write(json.dumps({"event": "progress", **event}, default=str) + "\n")
        self.stream.flush()


def add_parser(sub) -> None:
    p = sub.add_parser("batch", help="run many asset x scene jobs from a jobs file (in-process or on Ray)")
    p.add_argument("jobs", help="the jobs file (TOML, [[job]] tables; see docs/technical/jobs-file.md)")
    p.add_argument("--out", required=True, help="output folder: DIR/<job name>/, summary.md, contact_sheet.png")
    p.add_argument("--ray", nargs="?", const="auto", metavar="auto|local|ADDRESS",
                   help="run the jobs as Ray tasks: auto (a running cluster, else a local one; here without Ray "
                        "installed), local (a new local cluster) or a cluster address; absent: in this process")
    p.add_argument("--events", action="store_true",
                   help="in-process: print each progress event as a JSON line on stdout (for a calling program)")
    p.add_argument("--replace", action="store_true",
                   help="run the jobs an earlier batch into DIR finished again, replacing their folders (default: skip them)")
    p.add_argument("--reuse-from", metavar="EARLIER",
                   help="an earlier batch's --out folder: each job to run takes the finished stages of "
                        "EARLIER/<job name>/ along and reuses those whose inputs and settings are the same")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)
