"""Adapt's previews go out by time as well as by step count, so a slow machine shows the texture change
about every PREVIEW_SECONDS (one a step at most) rather than every preview_every steps (hours on a CPU)."""
from scenefit.core.stages.adapt.metrics import PREVIEW_SECONDS, preview_due


def test_a_preview_every_so_many_steps_at_the_end_and_after_half_a_minute():
    assert preview_due(50, 50, 1500, 0.0) and preview_due(1500, 50, 1500, 0.0)      # by count, and the last
    assert not preview_due(7, 50, 1500, PREVIEW_SECONDS - 1.0)                        # neither: none
    assert preview_due(7, 50, 1500, PREVIEW_SECONDS)                                  # by time
    assert preview_due(1, 50, 1500, 143.78)          # a CPU's Balanced step (bench: 144 s): each step shows
    assert not preview_due(50, 0, 1500, 1e6)         # previews off stay off
