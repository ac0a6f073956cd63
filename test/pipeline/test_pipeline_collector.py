"""Static-pose collector on synthetic streams: capture_now, flush, throttled logging, long
dwells, beam dropouts, settings and samples_to_campaign."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.pipeline import CalibrationSample, StaticPoseCollector, samples_to_campaign

NAMES = ("a", "b")
T0 = 1_700_000_000_000_000_000
MS = 1_000_000


class Stream:
    """Feeds a collector: joints at 100 Hz and points at 200 Hz along a given motion."""

    def __init__(self, collector: StaticPoseCollector, seed: int = 0) -> None:
        self.collector = collector
        self.rng = np.random.default_rng(seed)
        self.t = T0
        self.samples: list[CalibrationSample] = []

    def run(self, seconds: float, q_of_t, *, points: bool = True) -> None:
        for _ in range(round(seconds * 200)):
            self.t += 5 * MS
            q = np.asarray(q_of_t(self.t), dtype=float)
            if (self.t // (5 * MS)) % 2 == 0:
                self._keep(self.collector.add_joint_state(self.t, NAMES, q + self.rng.uniform(-1e-5, 1e-5, 2)))
            if points:
                xyz = np.array([q[0], q[1], 1.0]) + self.rng.uniform(-5e-6, 5e-6, 3)
                self._keep(self.collector.add_tracker_point(self.t + 1, "tracker", xyz))

    def _keep(self, sample: CalibrationSample | None) -> None:
        if sample is not None:
            self.samples.append(sample)


def _still(q):
    return lambda t: q


def _moving(q0, q1, start, seconds):
    def q(t):
        s = min(max((t - start) / (seconds * 1e9), 0.0), 1.0)
        return np.asarray(q0) + (np.asarray(q1) - np.asarray(q0)) * s

    return q


def _collector(**kwargs) -> StaticPoseCollector:
    return StaticPoseCollector(NAMES, tracker_frame_id="tracker", window_s=0.2, guard_s=0.05, **kwargs)


def test_one_sample_per_dwell_when_the_arm_moves_on() -> None:
    stream = Stream(_collector())
    stream.run(1.0, _still([0.1, 0.2]))
    assert stream.collector.is_static and not stream.samples
    stream.run(1.0, _moving([0.1, 0.2], [0.5, 0.6], stream.t, 1.0))
    assert len(stream.samples) == 1 and not stream.collector.is_static
    sample = stream.samples[0]
    np.testing.assert_allclose(sample.joint_positions, [0.1, 0.2], atol=5e-6)
    np.testing.assert_allclose(sample.point, [0.1, 0.2, 1.0], atol=3e-6)
    assert sample.joint_names == NAMES and sample.frame_id == "tracker"
    assert 70 <= sample.joint_state_count <= 100 and 140 <= sample.tracker_point_count <= 200
    assert np.all(sample.joint_position_std < 1e-5)
    # Covariance of the MEAN point: about (5 um / sqrt(3))^2 / n per axis.
    expected = (5e-6 / np.sqrt(3)) ** 2 / sample.tracker_point_count
    np.testing.assert_allclose(np.diag(sample.point_covariance), expected, rtol=0.5)
    np.testing.assert_allclose(sample.point_std, np.sqrt(np.diag(sample.point_covariance)))


def test_capture_now_emits_once_per_dwell() -> None:
    logged: list[str] = []
    stream = Stream(_collector(log=lambda cause, message: logged.append(cause)))
    assert stream.collector.capture_now() is None  # nothing yet
    stream.run(0.5, _still([0.3, -0.2]))
    sample = stream.collector.capture_now()
    assert sample is not None and sample.stamp_ns < stream.t
    np.testing.assert_allclose(sample.joint_positions, [0.3, -0.2], atol=5e-6)
    assert stream.collector.capture_now() is None  # the dwell was captured
    stream.run(1.0, _moving([0.3, -0.2], [0.0, 0.0], stream.t, 1.0))
    assert stream.samples == []  # leaving a captured dwell emits nothing more
    assert stream.collector.capture_now() is None  # moving
    assert logged == ["not_static", "already_captured", "not_static"]


def test_flush_emits_the_last_dwell_and_then_nothing() -> None:
    stream = Stream(_collector())
    stream.run(0.6, _still([1.0, 2.0]))
    sample = stream.collector.flush()
    assert sample is not None
    np.testing.assert_allclose(sample.joint_positions, [1.0, 2.0], atol=5e-6)
    assert stream.collector.flush() is None
    assert not stream.collector.is_static


def test_dwell_shorter_than_the_window_is_not_a_pose() -> None:
    stream = Stream(_collector())
    q = _moving([0.0, 0.0], [1.0, 1.0], T0, 1.0)
    stream.run(1.0, q)
    stream.run(0.1, _still([1.0, 1.0]))
    stream.run(1.0, _moving([1.0, 1.0], [0.0, 0.0], stream.t, 1.0))
    assert stream.samples == [] and stream.collector.flush() is None


def test_beam_blocked_for_a_whole_dwell_rejects_it() -> None:
    logged: list[str] = []
    stream = Stream(_collector(log=lambda cause, message: logged.append(cause)))
    stream.run(0.8, _still([0.0, 0.0]), points=False)
    stream.run(0.5, _moving([0.0, 0.0], [1.0, 1.0], stream.t, 0.5), points=False)
    assert stream.samples == []
    assert stream.collector.rejected_dwells == 1
    assert logged == ["rejected_dwell"]


def test_beam_dropout_inside_a_dwell_does_not_split_it() -> None:
    stream = Stream(_collector())
    stream.run(0.5, _still([0.2, 0.2]))
    stream.run(0.4, _still([0.2, 0.2]), points=False)
    stream.run(0.5, _still([0.2, 0.2]))
    stream.run(0.5, _moving([0.2, 0.2], [0.0, 0.0], stream.t, 0.5))
    assert len(stream.samples) == 1


def test_long_dwell_is_averaged_over_average_s_only() -> None:
    stream = Stream(_collector(average_s=1.0))
    stream.run(6.0, _still([0.5, 0.5]))
    # Memory stays bounded by the averaged span plus the window.
    assert len(stream.collector._points) < 2 * 200 * 1.5
    stream.run(0.5, _moving([0.5, 0.5], [0.0, 0.0], stream.t, 0.5))
    (sample,) = stream.samples
    assert 95 <= sample.joint_state_count <= 101 and 195 <= sample.tracker_point_count <= 201


def test_log_is_throttled_per_cause_in_message_time() -> None:
    logged: list[tuple[str, str]] = []
    collector = _collector(log_throttle_s=1.0, log=lambda cause, message: logged.append((cause, message)))
    for k in range(50):  # 5 s of NaN joint states at 10 Hz, interleaved with a wrong frame
        collector.add_joint_state(T0 + k * 100 * MS, NAMES, [np.nan, 0.0])
        collector.add_tracker_point(T0 + k * 100 * MS, "map", [0.0, 0.0, 0.0])
    assert collector.dropped["nan"] == 50 and collector.dropped["wrong_frame"] == 50
    assert [c for c, _ in logged].count("nan") == 5
    assert [c for c, _ in logged].count("wrong_frame") == 5


@pytest.mark.parametrize(
    ("names", "positions", "cause"),
    [
        (("a", "b", "c"), [0.0, 0.0, 0.0], "unknown_joint"),
        (("a",), [0.0], "missing_joint"),
        (("a", "a"), [0.0, 0.0], "duplicate_joint"),
        (("a", "b"), [0.0], "length_mismatch"),
        (("a", "b"), [0.0, np.inf], "nan"),
    ],
)
def test_bad_joint_states_are_dropped(names, positions, cause) -> None:
    collector = _collector()
    assert collector.add_joint_state(T0, names, positions) is None
    assert collector.dropped[cause] == 1
    assert sum(collector.dropped.values()) == 1


def test_extra_joints_can_be_ignored() -> None:
    collector = _collector(ignore_extra_joints=True)
    collector.add_joint_state(T0, ("gripper", "b", "a"), [9.0, 2.0, 1.0])
    assert sum(collector.dropped.values()) == 0
    np.testing.assert_array_equal(collector._joints.values[-1], [1.0, 2.0])


def test_backwards_stamps_are_dropped_per_stream() -> None:
    collector = _collector()
    collector.add_joint_state(T0, NAMES, [0.0, 0.0])
    collector.add_tracker_point(T0 - 5 * MS, "tracker", [0.0, 0.0, 0.0])  # other stream: fine
    collector.add_joint_state(T0, NAMES, [0.0, 0.0])
    collector.add_joint_state(T0 - 1, NAMES, [0.0, 0.0])
    collector.add_tracker_point(T0 - 6 * MS, "tracker", [0.0, 0.0, 0.0])
    assert collector.dropped["backwards_time"] == 3


@pytest.mark.parametrize(
    "kwargs",
    [
        {"window_s": 0.0},
        {"window_s": float("nan")},
        {"guard_s": -1.0},
        {"joint_motion_threshold": 0.0},
        {"tracker_scatter_threshold": float("inf")},
        {"min_points": 1},
        {"average_s": 0.0},
    ],
)
def test_bad_settings_raise_config_error(kwargs) -> None:
    with pytest.raises(ConfigError):
        StaticPoseCollector(NAMES, tracker_frame_id="tracker", **kwargs)


def test_bad_names_or_frame_raise_config_error() -> None:
    with pytest.raises(ConfigError, match="joint_names"):
        StaticPoseCollector(("a", "a"), tracker_frame_id="tracker")
    with pytest.raises(ConfigError, match="tracker_frame_id"):
        StaticPoseCollector(NAMES, tracker_frame_id="")


def _sample(stamp: int, names=NAMES, frame_id="tracker") -> CalibrationSample:
    return CalibrationSample(
        stamp_ns=stamp,
        frame_id=frame_id,
        joint_names=names,
        joint_positions=[0.1, 0.2],
        joint_position_std=[1e-5, 2e-5],
        point=[1.0, 2.0, 3.0],
        point_covariance=np.diag([1e-12, 4e-12, 9e-12]),
        joint_state_count=10,
        tracker_point_count=20,
    )


def test_samples_to_campaign_uses_the_std_of_the_mean() -> None:
    campaign = samples_to_campaign([_sample(T0), _sample(T0 + 1)], frame="tracker", metadata={"x": 1})
    assert campaign.n_poses == 2 and campaign.frame == "tracker" and campaign.frame_id == "tracker"
    np.testing.assert_array_equal(campaign.point_std, [[1e-6, 2e-6, 3e-6]] * 2)
    np.testing.assert_array_equal(campaign.stamps_ns, [T0, T0 + 1])
    assert campaign.metadata == {"x": 1}


def test_samples_to_campaign_rejects_mixed_samples() -> None:
    with pytest.raises(InputError, match="no calibration samples"):
        samples_to_campaign([], frame="base")
    with pytest.raises(InputError, match="joints"):
        samples_to_campaign([_sample(T0), _sample(T0 + 1, names=("b", "a"))], frame="base")
    with pytest.raises(InputError, match="frame"):
        samples_to_campaign([_sample(T0), _sample(T0 + 1, frame_id="other")], frame="base")


def test_sample_validates_its_content() -> None:
    with pytest.raises(InputError, match="joint_positions"):
        CalibrationSample(T0, "t", NAMES, [0.0], [0.0, 0.0], [0, 0, 0], np.eye(3), 1, 1)
    with pytest.raises(InputError, match="NaN"):
        CalibrationSample(T0, "t", NAMES, [0.0, np.nan], [0.0, 0.0], [0, 0, 0], np.eye(3), 1, 1)
    with pytest.raises(InputError, match="tracker_point_count"):
        CalibrationSample(T0, "t", NAMES, [0.0, 0.0], [0.0, 0.0], [0, 0, 0], np.eye(3), 1, 0)
