"""Expected time per stage for each preset, from `make bench` (benchmarks/results/bench.json).

Measured on: AMD EPYC, 2 cores, no GPU (llvm_ad_rgb, torch CPU). tests/test_panel_data.py checks the
conversion numbers against bench.json so they cannot drift from the measurement silently. None:
not measured with real weights on that machine (adapt and light use diffusion models).
"""

BENCH_MACHINE = "2-core AMD EPYC, no GPU"

# stage -> preset -> seconds for the bundled example (Suzanne, 512² maps)
EXPECTED_SECONDS: dict[str, dict[str, float | None]] = {
    "convert": {"draft": 11.2, "balanced": 45.0, "final": None},
    "light": {"draft": None, "balanced": None, "final": None},
    "adapt": {"draft": None, "balanced": None, "final": None},
}


def expected_line(stage: str, preset: str) -> str:
    seconds = EXPECTED_SECONDS.get(stage, {}).get(preset)
    return f"{stage}: about {seconds:.0f} s" if seconds is not None else f"{stage}: not measured yet"
