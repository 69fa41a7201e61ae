"""A batch's summary: summary.json, summary.md (a table of each job's outcome and quality figures) and the
contact sheet of each job's composite or best preview."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..core.base.atomic import write_json_atomic, write_text_atomic
from ..core.pipeline.layout import RunLayout
from .jobs import JobsFile


SUMMARY_JSON, SUMMARY_MD, CONTACT_SHEET = "summary.json", "summary.md", "contact_sheet.png"
RESERVED_NAMES = (SUMMARY_JSON, SUMMARY_MD, CONTACT_SHEET)
# What a job's contact-sheet cell shows, the first that exists (the composite once compose runs).
SHEET_IMAGES = ("composite.png", RunLayout.relative("compose", "composite"), RunLayout.relative("light", "preview"),
                RunLayout.relative("convert", "base_color"))


@dataclass
class JobOutcome:
    name: str
    status: str                 # done | failed | skipped (done by an earlier run)
    attempts: int = 0
    seconds: float = 0.0
    quality: dict = field(default_factory=dict)
    error: str | None = None
    reused: tuple[str, ...] = ()   # the stages taken from an earlier run, not run again
    skipped: dict = field(default_factory=dict)   # {stage: why, in a few words} of the stages the job skipped

    @property
    def status_words(self) -> str:
        """The status and what it hides: "done, adapt skipped: no weights"."""
        return ", ".join([self.status, *(f"{name} skipped: {why}" for name, why in self.skipped.items())])


def summary_table(outcomes: list[JobOutcome]) -> str:
    keys = sorted({k for o in outcomes for k in o.quality})
    head = "| job | status | attempts | seconds | reused | " + " | ".join(keys) + (" |" if keys else "") + " error |"
    rule = "|" + "---|" * (6 + len(keys))
    rows = []
    for o in outcomes:
        cells = [o.name, o.status_words.replace("|", "/"), str(o.attempts), f"{o.seconds:.1f}", ", ".join(o.reused)]
        cells += ["" if o.quality.get(k) is None else _cell(o.quality[k]) for k in keys]
        cells.append((o.error or "").replace("|", "/"))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, rule, *rows])


def _cell(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return str(value)


def write_summary(out_dir: Path, outcomes: list[JobOutcome], jobs: JobsFile) -> None:
    counts = {s: sum(o.status == s for o in outcomes) for s in ("done", "skipped", "failed")}
    if any(o.status == "interrupted" for o in outcomes):
        counts["interrupted"] = sum(o.status == "interrupted" for o in outcomes)
    write_json_atomic(out_dir / SUMMARY_JSON, {
        "jobs_file": str(jobs.path), "counts": counts,
        "jobs": [{"name": o.name, "status": o.status, "attempts": o.attempts, "seconds": o.seconds,
                  "reused": list(o.reused), "skipped_stages": o.skipped, "quality": o.quality, "error": o.error}
                 for o in outcomes]})
    stopped = f", {counts['interrupted']} not run (the batch was interrupted)" if "interrupted" in counts else ""
    text = (f"# Batch {jobs.path.name}\n\n{counts['done']} done, {counts['skipped']} skipped (done before), "
            f"{counts['failed']} failed{stopped}.\n\n{summary_table(outcomes)}\n")
    write_text_atomic(out_dir / SUMMARY_MD, text)
    sheet = contact_sheet_image(out_dir, [o.name for o in outcomes if o.status in ("done", "skipped")])
    if sheet is not None:
        from ..core.data.imageio import write_image

        write_image(out_dir / CONTACT_SHEET, sheet)


def contact_sheet_image(out_dir: Path, names: list[str], cell: int = 192, columns: int = 4):
    """A grid of each job's composite (or its best preview), labelled with the job's name; sRGB [0, 1]."""
    import cv2
    import numpy as np

    from ..core.data.imageio import read_image

    cells = []
    for name in names:
        path = next((out_dir / name / p for p in SHEET_IMAGES if (out_dir / name / p).is_file()), None)
        if path is None:
            continue
        image = read_image(path)[..., :3]
        if image.shape[2] == 1:
            image = np.repeat(image, 3, axis=2)
        h, w = image.shape[:2]
        scale = cell / max(h, w)
        image = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
        canvas = np.full((cell + 22, cell, 3), 0.12, np.float32)
        canvas[22:22 + image.shape[0], :image.shape[1]] = np.clip(image, 0.0, 1.0)
        cv2.putText(canvas, name[:24], (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0.95, 0.95, 0.95), 1, cv2.LINE_AA)
        cells.append(canvas)
    if not cells:
        return None
    while len(cells) % columns and len(cells) > columns:
        cells.append(np.full_like(cells[0], 0.12))
    rows = [np.concatenate(cells[i:i + columns], axis=1) for i in range(0, len(cells), columns)]
    return np.concatenate(rows, axis=0)
