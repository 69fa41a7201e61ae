"""A Ctrl-C that stops a batch within seconds, whatever the running job's libraries do with it.

A Ctrl-C inside a render reaches the job as Dr.Jit's RuntimeError (or, inside a conversion, as
nanobind's TypeError), which the batch took for a failed attempt and retried: it went on for 45 s
after Ctrl-C, job after job. Here a Ctrl-C is also remembered and cancels the running job (its cancel
event, which the stages check between steps); the batch raises KeyboardInterrupt at its next step, so
the jobs already finished stay whole in their folders and nothing further runs."""
from __future__ import annotations

import signal
import threading



class CtrlCStops:
    """A dispatcher (workers.batch.Dispatcher) whose batch a Ctrl-C stops: installed over the main
    thread's SIGINT handler (only the default one: a caller's own handler is theirs) until close()."""

    def __init__(self, dispatcher) -> None:
        self.dispatcher = dispatcher
        self.workers = getattr(dispatcher, "workers", 1)
        self.pressed = threading.Event()
        self.previous = None
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self.previous = signal.signal(signal.SIGINT, self._on_ctrl_c)

    def _on_ctrl_c(self, signum, frame) -> None:
        self.pressed.set()
        worker = getattr(self.dispatcher, "worker", None)   # the in-process worker: its job stops at its next check
        if worker is not None:
            worker.cancel()
        raise KeyboardInterrupt

    def _stop_if_pressed(self) -> None:
        if self.pressed.is_set():
            raise KeyboardInterrupt

    def submit(self, payload) -> None:
        self._stop_if_pressed()
        self.dispatcher.submit(payload)

    def next_done(self):
        self._stop_if_pressed()
        payload, result = self.dispatcher.next_done()
        if self.pressed.is_set() and isinstance(result, BaseException):   # (Cancelled: the job it stopped)
            raise KeyboardInterrupt   # (a job that finished whole is handed on, and the next step stops)
        return payload, result

    def close(self) -> None:
        try:
            self.dispatcher.close()
        finally:
            if self.previous is not None:
                signal.signal(signal.SIGINT, self.previous)
                self.previous = None
