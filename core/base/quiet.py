"""Keep native libraries' chatter (libpng, Blender importers, ...) off the user's terminal.

C libraries write to file descriptors 1 and 2 directly, past Python's sys.stdout/sys.stderr, so
the descriptors themselves are pointed at a temp file for the duration; what was said is kept and
can be added to an error message as its reason.
"""
from __future__ import annotations

import os
import sys
import tempfile
from contextlib import contextmanager
from typing import Iterator


class Captured:
    text: str = ""

    def last_line(self) -> str:
        lines = [line.strip() for line in self.text.splitlines() if line.strip()]
        return lines[-1] if lines else ""


@contextmanager
def native_output_captured(streams: tuple[int, ...] = (1, 2)) -> Iterator[Captured]:
    captured = Captured()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, ValueError):
            pass
    with tempfile.TemporaryFile(mode="w+b") as sink:
        saved = {fd: os.dup(fd) for fd in streams}
        try:
            for fd in streams:
                os.dup2(sink.fileno(), fd)
            yield captured
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (AttributeError, ValueError):
                    pass
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            captured.text = sink.read().decode("utf-8", "replace")
