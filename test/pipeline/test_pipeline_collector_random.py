"""Randomised streams (joint rates 50-1000 Hz, tracker dropouts, NaN messages, swapped
stamps, ending in a dwell or in motion): the live path (no flush) emits the same samples as
the replay (flush at the end) apart from a last, incomplete dwell; no sample averages
moving data, and every long dwell yields its sample live."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.pipeline import StaticPoseCollector

NAMES = ("a", "b", "c")
T0 = 1_700_000_000_000_000_000
SETTINGS = {
    "window_s": 0.2,
    "guard_s": 0.05,
    "average_s": 0.5,
    "min_points": 5,
    "joint_motion_threshold": 3e-4,
    "tracker_scatter_threshold": 1e-4,
}
COMPLETE_S = 0.2 + 0.05 + 0.5 + 0.05


def _stream(seed: int):
    rng = np.random.default_rng(seed)
    segments = []  # (moving, start, end, q0, q1)
    t, q = 0.0, rng.uniform(-1.0, 1.0, 3)
    for _ in range(int(rng.integers(2, 6))):
        move, q_next = rng.uniform(0.05, 0.6), q + rng.uniform(-0.3, 0.3, 3)
        segments.append((True, t, t + move, q, q_next))
        t, q = t + move, q_next
        dwell = rng.uniform(0.2, 2.5)
        segments.append((False, t, t + dwell, q, q))
        t += dwell
    if rng.random() < 0.5:
        move, q_next = rng.uniform(0.05, 0.5), q + rng.uniform(-0.3, 0.3, 3)
        segments.append((True, t, t + move, q, q_next))
        t += move

    def truth(time: float) -> np.ndarray:
        for _, a, b, q0, q1 in segments:
            if a <= time <= b:
                return q0 + (q1 - q0) * (time - a) / (b - a)
        return segments[-1][4]

    dropouts = [(a, a + rng.uniform(0.05, 0.8)) for a in rng.uniform(0.0, t, int(rng.integers(0, 3)))]
    events = []
    for time in np.arange(0.0, t, 1.0 / rng.uniform(50.0, 1000.0)):
        value = truth(time) + rng.normal(0.0, 2e-5, 3)
        if rng.random() < 0.01:
            value[rng.integers(3)] = np.nan
        events.append((time, 0, round(time * 1e9), value))
    for time in np.arange(3e-4, t, 1.0 / rng.uniform(20.0, 300.0)):
        if any(a <= time <= b for a, b in dropouts):
            continue
        xyz = 0.5 * truth(time) + rng.normal(0.0, 5e-6, 3)
        if rng.random() < 0.01:
            xyz[0] = np.nan
        events.append((time + rng.uniform(0.0, 0.004), 1, round(time * 1e9), xyz))
    events.sort(key=lambda e: e[0])
    for _ in range(int(rng.integers(0, 5))):  # out-of-order stamps
        i = int(rng.integers(1, len(events)))
        events[i - 1], events[i] = events[i], events[i - 1]
    return events, segments


@pytest.mark.parametrize("seed", range(20))
def test_random_streams_live_equals_replay_and_no_sample_from_motion(seed: int) -> None:
    events, segments = _stream(seed)
    collector = StaticPoseCollector(NAMES, tracker_frame_id="trk", **SETTINGS)
    live = []
    for _, stream, stamp, value in events:
        if stream == 0:
            sample = collector.add_joint_state(T0 + stamp, NAMES, value)
        else:
            sample = collector.add_tracker_point(T0 + stamp, "trk", value)
        if sample is not None:
            live.append(sample)
    last = collector.flush()
    replay = [*live, last] if last is not None else live
    dwells = [(a, b, q0) for moving, a, b, q0, _ in segments if not moving]
    for sample in replay:
        assert any(np.abs(sample.joint_positions - q0).max() < 1e-4 for _, _, q0 in dwells), "joints moved"
        assert any(np.abs(sample.point - 0.5 * q0).max() < 5e-5 for _, _, q0 in dwells), "tracker moved"
    rejected = collector.rejected_dwells
    for a, b, _ in dwells:
        if b - a > COMPLETE_S + 0.1:
            n = sum(1 for s in live if a * 1e9 <= s.stamp_ns - T0 <= b * 1e9)
            # A long dwell yields its sample live, unless a dropout left too few points.
            assert n == 1 or (n == 0 and rejected > 0)
