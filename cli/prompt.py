"""scenefit prompt: a scene-conditional prompt written by a language model (the paper's GPT-4 step),
or the paper's manually combined template when offline."""
from __future__ import annotations

import json
import sys

from .options import add_prompt_service_args, write_prompt_from_args


def run(args) -> int:
    result = write_prompt_from_args(args, args.object, args.scene, args.mode, args.photo, stream=args.stream,
                                    follow_up=args.follow_up)
    report = result.to_report()
    if args.report:
        from pathlib import Path

        from ..core.base.atomic import write_json_atomic

        write_json_atomic(Path(args.report), report)
    # The prompt alone on stdout (for scripts); how it was made on stderr.
    if result.model_written:
        how = f"written by '{result.model}'" + (" (cached answer)" if result.cached else "")
        if result.analysis and not args.quiet:
            print(f"analysis:\n{result.analysis}\n", file=sys.stderr)
    else:
        how = f"template prompt, not model-written: {result.reason}"
    for note in result.repairs + result.warnings:
        print(f"note: {note}", file=sys.stderr)
    print(f"scenefit prompt: {how}", file=sys.stderr)
    print(json.dumps(report, indent=2) if args.json else result.prompt)
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("prompt", help="write a scene-conditional prompt with a language model (or a template offline)")
    p.add_argument("--object", required=True, help="the object, e.g. 'a leather sofa'")
    p.add_argument("--scene", default="", help="the scene, e.g. 'a swamp' (optional with --photo and a vision model)")
    p.add_argument("--mode", choices=("describe", "instruct"), default="describe",
                   help="describe: 25-35-word appearance description (adapt's scene mode); "
                        "instruct: 20-30-word edit instructions")
    p.add_argument("--photo", default="", help="the scene photo, sent to vision-capable models")
    p.add_argument("--follow-up", default="", metavar="TEXT",
                   help="a further instruction after the first answer, as in the paper's appendix, e.g. "
                        "\"Let's suppose the sofa has been placed there for decades. Consider the consequences "
                        "and give me another description.\"")
    add_prompt_service_args(p)
    p.add_argument("--stream", action="store_true", help="ask for a streamed answer")
    p.add_argument("--offline", action="store_true", help="never use the network: the manually combined template")
    p.add_argument("--report", help="write the full record (analysis, raw answers, repairs) to this JSON file")
    p.add_argument("--json", action="store_true", help="print the record as JSON instead of the prompt")
    p.add_argument("--quiet", action="store_true", help="do not print the model's analysis")
    p.set_defaults(func=run)
