"""Lost messages counted from the stamps (ROS-free part of the collector's diagnostics)."""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.pipeline.input_gaps import GapCounter


def test_gaps_of_a_125_hz_stream_with_known_losses() -> None:
    rng = np.random.default_rng(3)
    period = 8_000_000  # 125 Hz [ns]
    stamps = 1_700_000_000_000_000_000 + period * np.arange(2000) + rng.integers(-200_000, 200_000, 2000)
    lost = np.zeros(2000, dtype=bool)
    lost[rng.choice(np.arange(20, 2000), 150, replace=False)] = True  # 150 of 2000, as seen live
    counter = GapCounter()
    for stamp in stamps[~lost]:
        counter.add(int(stamp))
    assert counter.missing == 150
    runs = np.count_nonzero(np.diff(np.concatenate(([0], lost[20:].astype(int)))) == 1)
    assert counter.gaps == runs
    assert counter.period_s == __import__("pytest").approx(0.008, rel=0.02)
    assert counter.longest_gap_s < 0.008 * 6


def test_no_gap_without_loss_and_none_during_warmup_or_backwards() -> None:
    counter = GapCounter()
    for k in range(100):
        assert counter.add(1_000_000_000 + k * 4_000_000) == 0
    assert counter.add(1_000_000_000) == 0  # backwards: the collector counts it, not a gap
    assert counter.add(1_000_000_000 + 100 * 4_000_000) == 0
    assert (counter.gaps, counter.missing) == (0, 0)
    early = GapCounter()
    early.add(0)
    assert early.add(10**9) == 0  # the period is not known yet
