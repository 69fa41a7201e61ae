"""Progress reporting and cancellation shared by every stage, the CLI and the Blender operators."""
from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .errors import Cancelled


@dataclass(frozen=True)
class ProgressEvent:
    stage: str
    step: int
    total: int
    message: str = ""
    metrics: dict | None = None
    preview: np.ndarray | None = None  # (h, w, 3) sRGB uint8, occasionally

    @property
    def fraction(self) -> float:
        return self.step / self.total if self.total else 1.0


class ProgressCallback(Protocol):
    def __call__(self, event: ProgressEvent) -> None: ...


def check_cancel(cancel: threading.Event | None) -> None:
    """Raise Cancelled between iterations when the user asked to stop."""
    if cancel is not None and cancel.is_set():
        raise Cancelled("Cancelled by the user; nothing was written after the last checkpoint.")


def emit(progress: ProgressCallback | None, stage: str, step: int, total: int, message: str = "",
         metrics: dict | None = None, preview: np.ndarray | None = None) -> None:
    if progress is not None:
        progress(ProgressEvent(stage, step, total, message, metrics, preview))


class TerminalProgress:
    """A one-line progress bar on stderr, redrawn at most every `interval` seconds."""

    def __init__(self, stream=None, interval: float | None = None, width: int = 28) -> None:
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        # On a terminal redraw often in place; in a log (CI, make demo | tee) write a line every few seconds.
        self.interval = interval if interval is not None else (0.2 if self.tty else 5.0)
        self.width = width
        self._last = 0.0
        self._stage: str | None = None
        self._start = time.perf_counter()

    def __call__(self, event: ProgressEvent) -> None:
        now = time.perf_counter()
        if event.stage != self._stage:
            if self._stage is not None and self.tty:
                self.stream.write("\n")
            self._stage, self._start, self._last = event.stage, now, 0.0
        done = event.step >= event.total
        if not done and now - self._last < self.interval:
            return
        self._last = now
        filled = int(self.width * event.fraction)
        metrics = " ".join(f"{k}={v:.4g}" for k, v in (event.metrics or {}).items() if isinstance(v, (int, float)))
        elapsed = now - self._start
        line = (f"{event.stage:>10} [{'#' * filled}{'.' * (self.width - filled)}] "
                f"{event.step}/{event.total} {elapsed:5.1f}s {metrics} {event.message}")[:160]
        if self.tty:
            self.stream.write("\r" + line.ljust(100) + ("\n" if done else ""))
        else:
            self.stream.write(line + "\n")
        if done:
            self._stage = None
        self.stream.flush()

