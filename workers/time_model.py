"""The time model of SceneFit's jobs, without bpy: expected seconds per stage and preset from `make bench`
(benchmarks/results/trade_run.json: the whole `scenefit run` on the bundled example in a 320x240 photo),
adapt's projection from its seconds per iteration with models of Stable Diffusion 2's size (on the bench CPU,
benchmarks/results/adapt_sd2.json: hours to days; on one H200, benchmarks/results/gpu.json: minutes to hours),
and a job's time left from its first moment. benchmarks/ is not shipped in the extension, so the numbers are
copied here; tests/blender/test_placement.py checks them against the measurements. None: not measured.
The panel (panels/quality.py) says these in words, through Blender's translation.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


def _same(text: str) -> str:
    return text


BENCH_MACHINE = "2-core AMD EPYC, no GPU"

# stage -> preset -> seconds for the bundled example (Suzanne) in a 320x240 photo
EXPECTED_SECONDS: dict[str, dict[str, float | None]] = {
    "convert": {"draft": 0.082, "balanced": 0.112, "final": 0.24},
    "light": {"draft": 0.031, "balanced": 0.032, "final": 0.03},
    "compose": {"draft": 3.248, "balanced": 3.609, "final": 4.144},
}

# Adapt with random-weight models of Stable Diffusion 2's size on the same CPU (bf16, each view's constant
# work cached): seconds per iteration once the step's views have been met. None: not measured.
ADAPT_SECONDS_PER_ITERATION: dict[str, float | None] = {"draft": 63.47, "balanced": 143.78, "final": 403.5}
# The same on one GPU (`make gpu-check`: fp16, Mitsuba cuda_ad_rgb), the step without its constant work.
GPU_BENCH_MACHINE = "one NVIDIA H200"
ADAPT_GPU_SECONDS_PER_ITERATION: dict[str, float | None] = {"draft": 0.856, "balanced": 1.885, "final": 4.96}
# Local work projected longer than this asks before it starts (and offers the worker environment).
LONG_LOCAL_SECONDS = 3600.0


@dataclass(frozen=True)
class LocalWork:
    """Projected seconds of a job that would run in this Blender, and the measurement they come from."""
    seconds: float
    on_gpu: bool

    def where(self, iface_: Callable[[str], str] = _same) -> str:
        return (iface_("on this GPU for about {} (measured on {} with models of Stable Diffusion 2's size; smaller "
                       "GPUs take longer)").format(duration_text(self.seconds, iface_), GPU_BENCH_MACHINE) if self.on_gpu else
                iface_("on this CPU for about {} (measured with models of Stable Diffusion 2's size on a 2-core "
                       "CPU)").format(duration_text(self.seconds, iface_)))


def adapt_projection(preset: str, iterations: int | None = None, gpu: bool = False) -> float | None:
    """Seconds an adaptation at `preset` (and `iterations`, else the preset's) takes on the bench CPU, or
    on the bench GPU."""
    per_iteration = (ADAPT_GPU_SECONDS_PER_ITERATION if gpu else ADAPT_SECONDS_PER_ITERATION).get(preset)
    if per_iteration is None:
        return None
    return per_iteration * (iterations or preset_iterations(preset))


def preset_iterations(preset: str) -> int:
    """The adapt preset's iterations, from the table the pipeline resolves them from (read at each draw:
    resolving the whole AdaptConfig would load torch into Blender the first time the panel is drawn)."""
    from ..core.pipeline.preset_tables import TABLES

    return int(TABLES["adapt"][preset]["iterations"])


def duration_text(seconds: float, iface_: Callable[[str], str] = _same) -> str:
    """`seconds` as the panel says a duration; iface_: Blender's translation of the words (the panel's)."""
    if seconds < 90:
        return iface_("{:.0f} s").format(seconds)
    if seconds < 5400:
        return iface_("{:.0f} min").format(seconds / 60)
    if seconds < 2 * 86400:
        return iface_("{:.1f} h").format(seconds / 3600)
    return iface_("{:.1f} days").format(seconds / 86400)


# The run's own pace fully replaces the bench's projection once this much of it is done.
OWN_PACE_FROM = 0.1


def eta_from_start(expected_total: float | None, elapsed: float, fraction: float,
                   measured_left: float | None = None) -> float | None:
    """Seconds left of a job from its first moment: the bench's projection of the whole (`expected_total`)
    for what is not done yet, weighed against the job's own pace (the time so far over the fraction done,
    or the stage's own `measured_left`) as more of it is done, wholly its own from OWN_PACE_FROM on.
    None when there is neither a projection nor a pace yet."""
    fraction = min(max(fraction, 0.0), 1.0)
    own = measured_left if measured_left is not None else (
        elapsed * (1.0 - fraction) / fraction if fraction > 0.0 else None)
    if expected_total is None or expected_total <= 0.0:
        return own
    projected = expected_total * (1.0 - fraction)
    if own is None:
        return projected
    weight = min(fraction / OWN_PACE_FROM, 1.0)
    return (1.0 - weight) * projected + weight * own
