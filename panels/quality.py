"""Expected time per stage for each preset, from `make bench` (benchmarks/results/trade_run.json: the
whole `scenefit run` on the bundled example in a 320x240 photo, seconds per stage).

benchmarks/ is not shipped in the extension, so the numbers are copied here; tests/test_placement.py
checks them against trade_run.json so they cannot drift from the measurement silently. None: not
measured on that machine (adapt needs the Stable Diffusion 2 weights).
"""

BENCH_MACHINE = "2-core AMD EPYC, no GPU"

# stage -> preset -> seconds for the bundled example (Suzanne) in a 320x240 photo
EXPECTED_SECONDS: dict[str, dict[str, float | None]] = {
    "convert": {"draft": 6.397, "balanced": 23.81, "final": 152.077},
    "light": {"draft": 0.036, "balanced": 0.034, "final": 0.033},
    "compose": {"draft": 1.275, "balanced": 4.968, "final": 7.293},
    "adapt": {"draft": None, "balanced": None, "final": None},
}


def expected_line(stage: str, preset: str) -> str:
    seconds = EXPECTED_SECONDS.get(stage, {}).get(preset)
    if seconds is None:
        return f"{stage}: not measured yet"
    return f"{stage}: about {seconds:.0f} s" if seconds >= 1 else f"{stage}: under 1 s"
