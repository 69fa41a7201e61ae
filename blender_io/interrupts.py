"""A Ctrl-C during a Blender operator that runs Python inside it (Cycles' bake calls its engine's
Python methods) raises KeyboardInterrupt in that Python, where Blender prints it and carries on: the
operator finishes as if nothing had happened and the interrupt is lost. Held here instead, and
raised once the operator has returned."""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def interrupt_held():
    """While the block runs a Ctrl-C (SIGINT) is only noted; after it, KeyboardInterrupt is raised.
    Off the main thread (where Python cannot set signal handlers) nothing changes."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield   # (another thread, or a handler of the caller's own: theirs to keep)
        return
    noted: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if noted:
        raise KeyboardInterrupt
