"""A dwell yields its sample as soon as it is complete, so the live path (no end of stream)
and the replay (which flushes at the end of the bag) give the same samples; the incremental
window statistics decide exactly as recomputing every window does."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from pipeline_data import BASE_BAG, COLLECTOR, TRACKER_BAG

from robocal_uncertainty.bagio.bag import open_bag
from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagTruth
from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, POINT_STAMPED
from robocal_uncertainty.core import RobotModel
from robocal_uncertainty.pipeline import CalibrationSample, StaticPoseCollector, StreamMerger, replay_bag

NAMES = ("a", "b")
T0 = 1_700_000_000_000_000_000
MS = 1_000_000
# The test bags dwell 0.3 s: 0.15 s averaged after a 0.025 s settle guard completes a dwell
# 0.2 s after it starts, inside every dwell of both bags (the last one included).
LIVE = dataclasses.replace(COLLECTOR, average_s=0.15)


def _feed(collector: StaticPoseCollector, t: int, q: Any, xyz: Any) -> list[CalibrationSample]:
    out = [collector.add_joint_state(t, NAMES, q), collector.add_tracker_point(t + 1, "tracker", xyz)]
    return [s for s in out if s is not None]


def _run(collector: StaticPoseCollector, qs: np.ndarray, *, start: int = T0, rng_seed: int = 0) -> list:
    """Feed joints and points at 200 Hz along `qs` (n, 2); the samples emitted."""
    rng = np.random.default_rng(rng_seed)
    samples: list[CalibrationSample] = []
    for k, q in enumerate(qs):
        t = start + k * 5 * MS
        xyz = np.array([q[0], q[1], 1.0]) + rng.uniform(-5e-6, 5e-6, 3)
        samples += _feed(collector, t, q + rng.uniform(-1e-5, 1e-5, 2), xyz)
    return samples


def _collector(**kwargs: Any) -> StaticPoseCollector:
    return StaticPoseCollector(NAMES, tracker_frame_id="tracker", window_s=0.2, guard_s=0.05, **kwargs)


def _move_then_still(still_s: float, then_move_s: float = 0.0) -> np.ndarray:
    move = np.linspace([0.0, 0.0], [0.3, 0.4], 100)
    still = np.repeat([[0.3, 0.4]], round(still_s * 200), axis=0)
    away = np.linspace([0.3, 0.4], [0.0, 0.0], round(then_move_s * 200) or 1)[1:]
    return np.concatenate([move, still, away])


def test_stream_ending_at_a_dwell_yields_its_sample_without_flush() -> None:
    collector = _collector(average_s=0.5)
    samples = _run(collector, _move_then_still(1.5))
    assert len(samples) == 1, "the last pose is emitted while the arm is still there"
    assert collector.is_static
    sample = samples[0]
    np.testing.assert_allclose(sample.joint_positions, [0.3, 0.4], atol=5e-6)
    # 0.5 s averaged at 200 Hz.
    assert 99 <= sample.joint_state_count <= 101 and 99 <= sample.tracker_point_count <= 101
    assert collector.flush() is None, "a complete dwell is emitted once"
    assert collector.emitted == 1


def test_motion_after_a_complete_dwell_does_not_change_its_sample() -> None:
    still = _run(_collector(average_s=0.5), _move_then_still(1.5))
    moved = _run(_collector(average_s=0.5), _move_then_still(1.5, then_move_s=0.5))
    stayed_longer = _run(_collector(average_s=0.5), _move_then_still(4.0, then_move_s=0.5))
    assert len(still) == len(moved) == len(stayed_longer) == 1
    for other in (moved[0], stayed_longer[0]):
        assert other.stamp_ns == still[0].stamp_ns
        assert np.array_equal(other.point, still[0].point)
        assert np.array_equal(other.joint_positions, still[0].joint_positions)
        assert np.array_equal(other.point_covariance, still[0].point_covariance)


def test_sample_is_emitted_when_the_guard_after_the_span_has_passed() -> None:
    collector = _collector(average_s=0.5)
    qs = _move_then_still(1.5)
    rng = np.random.default_rng(0)
    emitted_at = None
    for k, q in enumerate(qs):
        t = T0 + k * 5 * MS
        xyz = np.array([q[0], q[1], 1.0]) + rng.uniform(-5e-6, 5e-6, 3)
        if _feed(collector, t, q + rng.uniform(-1e-5, 1e-5, 2), xyz):
            emitted_at = t
            break
    assert emitted_at is not None
    arrival = T0 + 99 * 5 * MS  # last step of the move
    # dwell start (about the arrival) + guard 0.05 + average 0.5 + guard 0.05 s
    assert arrival + 550 * MS <= emitted_at <= arrival + 700 * MS


def test_short_dwell_is_averaged_up_to_the_departure() -> None:
    collector = _collector(average_s=5.0)
    samples = _run(collector, _move_then_still(1.0, then_move_s=0.5))
    (sample,) = samples
    # [start + 0.05, end - 0.05] of about 1 s: ~0.9 s at 200 Hz.
    assert 150 <= sample.tracker_point_count <= 190


def test_capture_now_on_a_complete_dwell_is_refused() -> None:
    logged: list[str] = []
    collector = _collector(average_s=0.5, log=lambda cause, message: logged.append(cause))
    assert len(_run(collector, _move_then_still(1.5))) == 1
    assert collector.capture_now() is None
    assert logged == ["already_captured"]


class _BruteForce(StaticPoseCollector):
    """The collector recomputing the peak-to-peak ranges over every window (the reference)."""

    def _window_static(self, now: int) -> bool:
        lo = now - self._window_ns
        joints, points = self._joints, self._points
        if not len(joints) or joints.stamps[0] > lo:
            return False
        i0 = joints.index(lo)
        if len(joints) - i0 < 2:
            return False
        q = joints.values[i0:]
        if float(np.max(q.max(axis=0) - q.min(axis=0))) > self.settings.joint_motion_threshold:
            return False
        k0 = points.index(lo)
        if len(points) - k0 >= 2:
            x = points.values[k0:]
            if float(np.max(x.max(axis=0) - x.min(axis=0))) > self.settings.tracker_scatter_threshold:
                return False
        return True


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_incremental_window_statistics_decide_as_recomputing_every_window(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Random piecewise motion: still stretches, slow creeps near the threshold, fast moves,
    # noise close to the thresholds, beam dropouts and irregular stamps.
    q = np.zeros(2)
    rows: list[tuple[int, np.ndarray, np.ndarray | None]] = []
    t = T0
    for _ in range(25):
        kind = rng.integers(4)
        n = int(rng.integers(20, 300))
        speed = (0.0, 2e-5, 3e-3, 0.0)[kind]
        noise = (1e-5, 1e-4, 1e-5, 2.4e-4)[kind]
        direction = rng.normal(size=2)
        dropout = rng.random() < 0.3
        for k in range(n):
            t += int(rng.integers(3 * MS, 7 * MS))
            q = q + speed * direction
            point = None if dropout and k > n // 3 else np.array([*q, 1.0]) + rng.uniform(-noise / 4, noise / 4, 3)
            rows.append((t, q + rng.uniform(-noise, noise, 2), point))
    settings = {"window_s": 0.1, "guard_s": 0.02, "average_s": 0.3, "min_points": 5}
    fast = StaticPoseCollector(NAMES, tracker_frame_id="tracker", **settings)
    slow = _BruteForce(NAMES, tracker_frame_id="tracker", **settings)
    out_fast, out_slow, trace_fast, trace_slow = [], [], [], []
    for stamp, joints, point in rows:
        for collector, out, trace in ((fast, out_fast, trace_fast), (slow, out_slow, trace_slow)):
            if point is not None:
                out.extend(_feed(collector, stamp, joints, point))
            else:
                sample = collector.add_joint_state(stamp, NAMES, joints)
                out.extend([sample] if sample is not None else [])
            trace.append(collector.is_static)
    assert trace_fast == trace_slow
    assert sum(trace_fast) > 100 and len(trace_fast) - sum(trace_fast) > 100  # both states met
    assert len(out_fast) == len(out_slow) > 3
    for a, b in zip(out_fast, out_slow):
        assert a.stamp_ns == b.stamp_ns and np.array_equal(a.point, b.point)
        assert np.array_equal(a.joint_positions, b.joint_positions)
    assert fast.rejected_dwells == slow.rejected_dwells


def _live(bag: Any, model: RobotModel, frame_id: str) -> list[CalibrationSample]:
    """The collector node's path: both streams through the StreamMerger (keyed by log time,
    as DDS source timestamps would be) into the collector; no end of stream, no flush."""
    opened = open_bag(bag, (JOINT_TOPIC, POINT_TOPIC))
    collector = StaticPoseCollector.from_settings(model.joint_names, frame_id, LIVE)
    samples: list[CalibrationSample] = []

    def feed(stream: int, message: Any) -> None:
        header = message.header
        stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
        if stream == 0:
            sample = collector.add_joint_state(stamp, message.name, np.asarray(message.position, dtype=np.float64))
        else:
            p = message.point
            sample = collector.add_tracker_point(stamp, str(header.frame_id), (p.x, p.y, p.z))
        if sample is not None:
            samples.append(sample)

    merger = StreamMerger(feed, hold_ns=50_000_000)
    for raw in sorted(opened.contents.messages, key=lambda m: m.log_time_ns):
        if raw.channel.topic not in (JOINT_TOPIC, POINT_TOPIC):
            continue
        stream = 0 if raw.channel.topic == JOINT_TOPIC else 1
        decoded = opened.try_decode(raw, JOINT_STATE if stream == 0 else POINT_STAMPED)
        merger.push(stream, raw.log_time_ns, raw.log_time_ns, decoded)
    merger.drain()  # messages already received; the stream itself has not ended
    return samples


@pytest.mark.parametrize("which", ["base", "tracker"])
def test_live_path_and_replay_give_the_same_samples(
    which: str,
    paper_arm: RobotModel,
    paper_arm_unknown_base: RobotModel,
    base_truth: RawBagTruth,
    tracker_truth: RawBagTruth,
) -> None:
    bag, model, truth = (
        (BASE_BAG, paper_arm, base_truth) if which == "base" else (TRACKER_BAG, paper_arm_unknown_base, tracker_truth)
    )
    replayed = replay_bag(bag, model, collector=LIVE, calibrate=False)
    live = _live(bag, model, replayed.tracker_frame_id)
    assert len(live) == len(replayed.samples) == len(truth.windows)
    for a, b, window in zip(live, replayed.samples, truth.windows):
        assert window.start_ns < a.stamp_ns == b.stamp_ns < window.end_ns
        for name in ("joint_positions", "point", "point_covariance", "joint_position_std"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_tracker_bag_ends_inside_its_last_dwell(paper_arm_unknown_base: RobotModel, tracker_truth: RawBagTruth) -> None:
    """The stream ends while the robot is still at its last pose: a sample on both paths."""
    live = _live(TRACKER_BAG, paper_arm_unknown_base, "laser_tracker")
    last = tracker_truth.windows[-1]
    assert last.start_ns < live[-1].stamp_ns < last.end_ns
    np.testing.assert_allclose(live[-1].joint_positions, last.joint_positions, atol=1e-4)
