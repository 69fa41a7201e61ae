"""Where a bench writes what it measured: STEM.md (the table) and STEM.json (the rows), with the load."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path


def machine_load() -> str:
    """`uptime`'s line: every absolute time in a table is quoted with the load it was measured under."""
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def write_results(out: str | Path, stem: str, markdown: str, data: dict) -> Path:
    """out/STEM.md and out/STEM.json; returns the .md path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.md").write_text(markdown)
    (out / f"{stem}.json").write_text(json.dumps(data, indent=1) + "\n")
    return out / f"{stem}.md"
