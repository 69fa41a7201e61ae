"""What a run of the adapt stage measures and shows as it goes: seconds per phase of a step (PhaseTimer),
one history entry per step, the peak memory, and when a preview goes out."""
from __future__ import annotations

import time

import numpy as np
import torch

# "trace": the loop renderer's G-buffers, traced the first time a view comes up (once per view and run).
PHASES = ("constants", "trace", "render", "vae", "unet", "vae_backward", "render_backward", "lora", "step")

# A preview also goes out when this long has passed since the last one (one a step at most), so a slow
# machine shows the texture changing about this often, not only every preview_every steps.
PREVIEW_SECONDS = 30.0


def preview_due(done: int, every: int, iterations: int, since_last: float) -> bool:
    """Whether step `done` sends a preview: every `every` steps, the last step, or PREVIEW_SECONDS after the
    last one; never with previews off (every = 0)."""
    return bool(every) and (done % every == 0 or done == iterations or since_last >= PREVIEW_SECONDS)


class PhaseTimer:
    """Seconds per phase, summed; waits for the GPU so a phase is charged its own kernels."""

    def __init__(self, device) -> None:
        self.totals: dict[str, float] = {}
        self.cuda = getattr(device, "type", "") == "cuda"
        self.last = time.perf_counter()

    def lap(self, name: str) -> None:
        if self.cuda:
            torch.cuda.synchronize()
        now = time.perf_counter()
        self.totals[name] = self.totals.get(name, 0.0) + now - self.last
        self.last = now

    def restart(self) -> None:
        self.last = time.perf_counter()

    def move(self, seconds: float, source: str, target: str) -> None:
        """Charge `seconds` of the phase `source` (just lapped) to `target` instead."""
        if seconds > 0:
            self.totals[source] = self.totals.get(source, 0.0) - seconds
            self.totals[target] = self.totals.get(target, 0.0) + seconds


def mean_metrics(per_view: list[dict]) -> dict:
    """One history entry: numbers averaged over the views (t listed per view, nonfinite summed)."""
    out: dict = {"t": [m["t"] for m in per_view]}
    for key in per_view[0]:
        if key == "t":
            continue
        values = [m[key] for m in per_view if key in m]
        if key == "nonfinite":
            out[key] = int(sum(values))
        elif key in ("lambda", "stage_size"):
            out[key] = values[0]
        else:
            out[key] = round(float(np.mean(values)), 6)
    if len(out["t"]) == 1:
        out["t"] = out["t"][0]
    return out


def peak_memory_mb(device) -> float | None:
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated() / 2**20
    try:
        import resource  # Unix only

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    except (ImportError, OSError):
        return None
