"""The time model's words in the panel (workers/time_model.py holds the numbers and the model, without bpy):
each stage's expected time at a preset, durations, through Blender's translation."""
from ..workers.time_model import (ADAPT_GPU_SECONDS_PER_ITERATION, ADAPT_SECONDS_PER_ITERATION, BENCH_MACHINE,
                                  EXPECTED_SECONDS, GPU_BENCH_MACHINE, LONG_LOCAL_SECONDS, OWN_PACE_FROM, LocalWork,
                                  adapt_projection, eta_from_start, preset_iterations)
from ..workers.time_model import duration_text as _duration_text

try:   # the panel's words go through Blender's translation; plain text where bpy is absent
    from bpy.app.translations import pgettext_iface as iface_
except ImportError:
    def iface_(text: str) -> str:
        return text

__all__ = ["ADAPT_GPU_SECONDS_PER_ITERATION", "ADAPT_SECONDS_PER_ITERATION", "BENCH_MACHINE", "EXPECTED_SECONDS",
           "GPU_BENCH_MACHINE", "LONG_LOCAL_SECONDS", "OWN_PACE_FROM", "LocalWork", "adapt_projection",
           "duration_text", "eta_from_start", "expected_line", "preset_iterations"]


def duration_text(seconds: float) -> str:
    return _duration_text(seconds, iface_)


def expected_line(stage: str, preset: str) -> str:
    if stage == "adapt":
        cpu, gpu = adapt_projection(preset), adapt_projection(preset, gpu=True)
        if cpu is None or gpu is None:
            return iface_("adapt: not measured yet")
        return iface_("adapt: about {} on a CPU, {} on an H200 (SD2 size)").format(duration_text(cpu),
                                                                                   duration_text(gpu))
    seconds = EXPECTED_SECONDS.get(stage, {}).get(preset)
    if seconds is None:
        return iface_("{}: not measured yet").format(iface_(stage))
    if seconds >= 1:
        return iface_("{}: about {:.0f} s").format(iface_(stage), seconds)
    return iface_("{}: under 1 s").format(iface_(stage))
