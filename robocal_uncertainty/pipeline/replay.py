"""Offline replay of a raw recording through the collector and the calibration pipeline.

The raw bag (one MCAP file or a rosbag2 directory) holds ``sensor_msgs/msg/JointState`` on
the joint topic and ``geometry_msgs/msg/PointStamped`` on the tracker topic, or, for a 6-DOF
tracker, ``geometry_msgs/msg/PoseStamped`` (or ``PoseWithCovarianceStamped``) on a tracker
pose topic. Messages are fed in recorded (log-time) order to a
:class:`~robocal_uncertainty.pipeline.collector.StaticPoseCollector` by
:func:`feed_joint_state` and :func:`feed_tracker_message`, the functions the collector node
feeds its messages with; its samples go to a
:class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`.

A replay turns a bag into samples, a campaign and (optionally) a calibration. The
uncertainty of a replayed bag is evaluated by ``robocal_uncertainty.app.replay``, which
hands this campaign to the same ``app.evaluate`` as the command line's ``evaluate``.
"""

from __future__ import annotations

import dataclasses
import functools
import gc
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from robocal_uncertainty.bagio.bag import Bag, open_bag
from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.bagio.pose_messages import POSE_STAMPED
from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, POINT_STAMPED
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import BagError, CampaignError
from robocal_uncertainty.pipeline.auto_window import AutoWindowCollector
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.pipeline.collector import CollectorSettings, LogCallback
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = [
    "POSE_WITH_COVARIANCE_STAMPED",
    "TRACKER_POSE_TYPES",
    "ReplayResult",
    "StillIntervals",
    "auto_collector_settings",
    "feed_joint_state",
    "feed_tracker_message",
    "replay_bag",
    "still_intervals",
]

_NS_PER_S = 1_000_000_000
POSE_WITH_COVARIANCE_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TRACKER_POSE_TYPES: tuple[str, ...] = (POSE_STAMPED, POSE_WITH_COVARIANCE_STAMPED)
"""Message types accepted on a tracker pose topic (6-DOF tracker)."""


@dataclass(frozen=True)
class StillIntervals:
    """Intervals in which no joint moved by more than the motion threshold.

    Attributes
    ----------
    starts_ns, ends_ns : ndarray of int64, shape (n,) [ns]
        Stamps of the first and last joint state of each interval (maximal, in time order).
    """

    starts_ns: np.ndarray
    ends_ns: np.ndarray

    @property
    def durations_s(self) -> np.ndarray:
        """Durations, shape (n,) [s]."""
        return np.asarray((self.ends_ns - self.starts_ns) / _NS_PER_S, dtype=np.float64)

    def typical_dwell_s(self) -> float:
        """Median duration of the dwells: the intervals at least a quarter as long as the
        longest (short still spells at the ends of moves are not dwells); 0 when none."""
        d = self.durations_s
        if d.size == 0 or d.max() <= 0:
            return 0.0
        return float(np.median(d[d >= 0.25 * d.max()]))


def still_intervals(stamps_ns: np.ndarray, positions: np.ndarray, threshold: float) -> StillIntervals:
    """Split a joint stream into maximal still intervals (greedy, in time order).

    Parameters
    ----------
    stamps_ns : ndarray of int64, shape (n,) [ns]
        Increasing stamps of the joint states.
    positions : ndarray, shape (n, n_joints) [rad]
    threshold : float [rad]
        Largest peak-to-peak range of any joint inside an interval.
    """
    starts: list[int] = []
    ends: list[int] = []
    if len(stamps_ns):
        lo = hi = positions[0].copy()
        first = 0
        for i in range(1, len(stamps_ns)):
            q = positions[i]
            lo_i, hi_i = np.minimum(lo, q), np.maximum(hi, q)
            if float((hi_i - lo_i).max()) > threshold:
                starts.append(int(stamps_ns[first]))
                ends.append(int(stamps_ns[i - 1]))
                first, lo, hi = i, q.copy(), q.copy()
            else:
                lo, hi = lo_i, hi_i
        starts.append(int(stamps_ns[first]))
        ends.append(int(stamps_ns[-1]))
    return StillIntervals(np.array(starts, dtype=np.int64), np.array(ends, dtype=np.int64))


def auto_collector_settings(settings: CollectorSettings, still: StillIntervals) -> CollectorSettings:
    """`settings` with the window and guards shortened for a recording with short dwells.

    The window becomes at most 0.4 and each guard at most 0.25 of the typical dwell (see
    :meth:`StillIntervals.typical_dwell_s`), so that a dwell holds a static window and
    averaged data between its guards; recordings whose dwells are long enough keep
    `settings` unchanged (with the defaults: dwells of 1.25 s and more).
    """
    dwell = still.typical_dwell_s()
    if dwell <= 0:
        return settings
    window = min(settings.window_s, round(0.4 * dwell, 3))
    guard = min(settings.guard_s, round(0.25 * dwell, 3))
    if window <= 0:
        return settings
    return dataclasses.replace(settings, window_s=window, guard_s=guard)


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """What a replay produced.

    Attributes
    ----------
    samples : tuple of CalibrationSample
        One per static dwell found, in time order.
    campaign : Campaign or None
        The campaign built from the samples (None when no dwell was found).
    calibration : IdentificationResult or None
        None when ``calibrate=False``.
    dropped : dict of str to int
        Dropped messages per cause: the collector's causes plus ``undecodable``.
    rejected_dwells : int
        Static dwells with too few data to average.
    message_counts : dict of str to int
        Messages read per topic.
    tracker_frame_id : str
        Tracker frame used.
    truncated : bool
        The bag ended without its footer (recorded by a process that was killed).
    collector : CollectorSettings
        The static detection settings used (with ``auto_window``: as adapted).
    diagnosis : str
        When no static pose was found: the likely cause in one line (naming the option to
        change); empty otherwise.
    """

    samples: tuple[CalibrationSample, ...]
    campaign: Campaign | None
    calibration: IdentificationResult | None
    dropped: dict[str, int]
    rejected_dwells: int
    message_counts: dict[str, int]
    tracker_frame_id: str
    truncated: bool
    collector: CollectorSettings = dataclasses.field(default_factory=CollectorSettings)
    diagnosis: str = ""


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def feed_joint_state(collector: Any, message: Any) -> Any:
    """Hand one ``sensor_msgs/JointState`` (a rosbags or an rclpy message) to `collector`.

    `collector` is a :class:`StaticPoseCollector` (returns the sample of a dwell the message
    ended, or None) or an :class:`~robocal_uncertainty.pipeline.auto_window.AutoWindowCollector`
    (returns the list of samples completed).
    """
    return collector.add_joint_state(
        _stamp(message.header), [str(n) for n in message.name], np.asarray(message.position, dtype=np.float64)
    )


def feed_tracker_message(collector: Any, message: Any) -> Any:
    """Hand one tracker message (a rosbags or an rclpy message) to `collector`.

    ``geometry_msgs/PointStamped`` goes to :meth:`StaticPoseCollector.add_tracker_point`;
    ``PoseStamped`` and ``PoseWithCovarianceStamped`` (6-DOF) go, position [m] and
    orientation ``(x, y, z, w)``, to :meth:`StaticPoseCollector.add_tracker_pose`, which
    drops a NaN (``nan``) or non-unit (``bad_quaternion``) orientation and counts it. The
    covariance of a ``PoseWithCovarianceStamped`` is not used: a sample's covariances are
    those of the mean over its dwell, from the scatter of the readings averaged.

    Returns what the collector's method returns (see :func:`feed_joint_state`).
    """
    stamp, frame_id = _stamp(message.header), str(message.header.frame_id)
    if hasattr(message, "pose"):
        pose = message.pose.pose if hasattr(message.pose, "covariance") else message.pose
        p, o = pose.position, pose.orientation
        return collector.add_tracker_pose(stamp, frame_id, (p.x, p.y, p.z), (o.x, o.y, o.z, o.w))
    point = message.point
    return collector.add_tracker_point(stamp, frame_id, (point.x, point.y, point.z))


def _refuse_poses_as_points(bag: Bag, point_topic: str) -> None:
    """A one-line BagError when the point topic is absent or carries poses and the bag has a
    6-DOF tracker pose topic (to be replayed as the tracker pose topic)."""
    schemas = {c.topic: c.schema_name for c in bag.contents.channels}
    if schemas.get(point_topic, POINT_STAMPED) == POINT_STAMPED and point_topic in schemas:
        return
    poses = sorted(topic for topic, schema in schemas.items() if schema in TRACKER_POSE_TYPES)
    if not poses:
        return  # the usual missing-topic or wrong-type error follows
    found = "carries poses" if point_topic in schemas else "not found"
    msg = (
        f"{bag.path}: tracker point topic {point_topic} {found}; {', '.join(poses)} carries 6-DOF tracker poses: "
        "give it as the tracker pose topic (--tracker-pose-topic)"
    )
    raise BagError(msg)


def _tracker_type(bag: Bag, topic: str) -> str:
    """The pose type on `topic` (one of :data:`TRACKER_POSE_TYPES`), or a one-line BagError."""
    schemas = {c.schema_name for c in bag.contents.channels if c.topic == topic}
    found = [s for s in TRACKER_POSE_TYPES if s in schemas]
    if len(schemas) != 1 or not found:
        if not schemas:
            known = sorted({c.topic for c in bag.contents.channels})
            msg = f"{bag.path}: tracker pose topic {topic} not found (topics: {known})"
        else:
            expected = " or ".join(TRACKER_POSE_TYPES)
            msg = f"{bag.path}: tracker pose topic {topic} has type {', '.join(sorted(schemas))}, expected {expected}"
        raise BagError(msg)
    return found[0]


_F = TypeVar("_F", bound=Callable[..., Any])


def _cyclic_gc_paused(function: _F) -> _F:
    """Run `function` with Python's cyclic garbage collector paused (restored afterwards).

    A replay holds every decoded message (hundreds of thousands of small objects, none in a
    reference cycle) until the samples are built; each automatic collection walks all of
    them, which made a third of a replay's time. Reference counting still frees everything;
    cycles made meanwhile are collected once the collector runs again.
    """

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if not gc.isenabled():
            return function(*args, **kwargs)
        gc.disable()
        try:
            return function(*args, **kwargs)
        finally:
            gc.enable()

    return wrapper  # type: ignore[return-value]


@dataclass(frozen=True)
class _DecodedBag:
    """The joint and tracker messages of a raw recording, decoded, in log-time order."""

    bag: Bag
    tracker_topic: str
    events: list[tuple[bool, Any]]
    """(is a joint state, message) in log-time order."""
    counts: dict[str, int]
    undecodable: int

    def majority_frame(self) -> str:
        """The most frequent ``frame_id`` of the tracker messages."""
        frames = Counter(str(m.header.frame_id) for is_joint, m in self.events if not is_joint)
        if not frames:
            msg = f"{self.bag.path}: no decodable message on {self.tracker_topic}"
            raise BagError(msg)
        return frames.most_common(1)[0][0]


def _decode_bag(path: Path, joint_topic: str, tracker_topic: str, *, pose: bool) -> _DecodedBag:
    """Open the recording, check its topics' types, and decode them in log-time order."""
    bag = open_bag(path, (joint_topic, tracker_topic))
    bag.topic_messages(joint_topic, JOINT_STATE)
    if not pose:
        _refuse_poses_as_points(bag, tracker_topic)
    tracker_type = _tracker_type(bag, tracker_topic) if pose else POINT_STAMPED
    bag.topic_messages(tracker_topic, tracker_type)
    order = sorted(
        (m for m in bag.contents.messages if m.channel.topic in (joint_topic, tracker_topic)),
        key=lambda m: m.log_time_ns,
    )
    undecodable = 0
    events: list[tuple[bool, Any]] = []
    for message in order:
        is_joint = message.channel.topic == joint_topic
        decoded = bag.try_decode(message, JOINT_STATE if is_joint else tracker_type)
        if decoded is None:
            undecodable += 1
        else:
            events.append((is_joint, decoded))
    counts = dict(Counter(m.channel.topic for m in order))
    return _DecodedBag(bag, tracker_topic, events, counts, undecodable)


def _feed(
    pipeline: CalibrationPipeline,
    pose_collector: AutoWindowCollector,
    events: list[tuple[bool, Any]],
    *,
    calibrate: bool,
) -> tuple[tuple[CalibrationSample, ...], IdentificationResult | None, Campaign | None]:
    """Feed the messages to the collector and its samples to the pipeline; calibrate when asked."""
    with pipeline:
        samples: list[CalibrationSample] = []
        for is_joint, message in events:
            feed = feed_joint_state if is_joint else feed_tracker_message
            for sample in feed(pose_collector, message):
                samples.append(sample)
                pipeline.add_sample(sample)
        for sample in pose_collector.flush():
            samples.append(sample)
            pipeline.add_sample(sample)
        calibration = pipeline.calibrate() if calibrate else None
        campaign = pipeline.campaign
    return tuple(samples), calibration, campaign


@_cyclic_gc_paused
def replay_bag(
    path: str | Path,
    model: RobotModel,
    *,
    joint_topic: str = JOINT_TOPIC,
    point_topic: str = POINT_TOPIC,
    tracker_pose_topic: str | None = None,
    tracker_frame_id: str | None = None,
    collector: CollectorSettings | None = None,
    options: EvaluationSettings | None = None,
    min_samples: int | None = None,
    campaign_path: str | Path | None = None,
    calibrate: bool = True,
    log: LogCallback | None = None,
    auto_window: bool = False,
) -> ReplayResult:
    """Replay a raw bag: detect static poses, build the campaign, optionally calibrate.

    Parameters
    ----------
    path : str or Path
        Raw recording: one MCAP file or a rosbag2 directory.
    model : RobotModel
        Nominal model; its joint names are collected.
    joint_topic, point_topic : str
        Topics of the joint states and tracker points.
    tracker_pose_topic : str, optional
        6-DOF tracker: topic of its ``geometry_msgs/msg/PoseStamped`` (or
        ``PoseWithCovarianceStamped``), read instead of `point_topic`; the samples then carry
        the mean orientation and its covariance, and the campaign is a 6-DOF one.
    tracker_frame_id : str, optional
        Frame of valid tracker points; default: the most frequent ``frame_id`` on the
        tracker topic (points in other frames are dropped as ``wrong_frame``).
    collector : CollectorSettings, optional
        Static detection settings.
    options, min_samples, campaign_path
        Passed to :class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`
        (``options.lambda_`` and ``options.accept_unconverged`` set the identification).
    calibrate : bool
        Identify the parameters.
    log : callable, optional
        ``log(cause, message)`` for dropped messages and rejected dwells (throttled).
    auto_window : bool
        Shorten the window and guards of `collector` to the dwells of the recording, learnt
        from its first dwells as the collector node does live
        (:class:`~robocal_uncertainty.pipeline.auto_window.AutoWindowCollector`,
        :func:`auto_collector_settings`).

    Returns
    -------
    ReplayResult

    Raises
    ------
    BagError
        Missing, corrupt or non-bag file; missing topics or wrong message types.
    CampaignError
        `campaign_path` exists already (replay never resumes a campaign).
    IdentifiabilityError
        With `calibrate`, too few static poses found to identify the model.
    """
    path = Path(path)
    if campaign_path is not None and Path(campaign_path).exists():
        msg = f"campaign file {campaign_path} exists already; replay writes a new one"
        raise CampaignError(msg)
    tracker_topic = point_topic if tracker_pose_topic is None else tracker_pose_topic
    decoded = _decode_bag(path, joint_topic, tracker_topic, pose=tracker_pose_topic is not None)
    tracker_frame_id = decoded.majority_frame() if tracker_frame_id is None else tracker_frame_id
    # The collector node's detector: with auto_window, the window is learnt from the first
    # dwells as they arrive (pipeline.auto_window), so a live run finds the same samples.
    pose_collector = AutoWindowCollector(
        model.joint_names, tracker_frame_id, collector or CollectorSettings(), auto=auto_window, log=log
    )
    pipeline = CalibrationPipeline(model, options=options, min_samples=min_samples, campaign_path=campaign_path)
    fed = _feed(pipeline, pose_collector, decoded.events, calibrate=calibrate)
    return _replay_result(decoded, model, pose_collector, fed, tracker_frame_id)


def _replay_result(
    decoded: _DecodedBag,
    model: RobotModel,
    pose_collector: AutoWindowCollector,
    fed: tuple[tuple[CalibrationSample, ...], IdentificationResult | None, Campaign | None],
    tracker_frame_id: str,
) -> ReplayResult:
    """What a replay found, with the collector's drops and, when no sample came, the likely reason."""
    samples, calibration, campaign = fed
    settings = pose_collector.settings
    dropped = pose_collector.dropped
    dropped["undecodable"] = decoded.undecodable
    return ReplayResult(
        samples=samples,
        campaign=campaign,
        calibration=calibration,
        dropped=dropped,
        rejected_dwells=pose_collector.rejected_dwells,
        message_counts=decoded.counts,
        tracker_frame_id=tracker_frame_id,
        truncated=decoded.bag.truncated,
        collector=settings,
        diagnosis=""
        if samples
        else _diagnose(decoded.bag, decoded.events, model, tracker_frame_id, settings, pose_collector),
    )


def _joint_matrix(events: list[tuple[bool, Any]], joint_names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Stamps [ns] and positions [rad] of the joint states that carry every joint of the robot."""
    stamps: list[int] = []
    rows: list[list[float]] = []
    for is_joint, message in events:
        if not is_joint:
            continue
        index = {str(n): i for i, n in enumerate(message.name)}
        if all(n in index for n in joint_names) and len(message.position) == len(message.name):
            stamps.append(_stamp(message.header))
            rows.append([float(message.position[index[n]]) for n in joint_names])
    t = np.array(stamps, dtype=np.int64)
    q = np.array(rows, dtype=np.float64).reshape(len(rows), len(joint_names))
    ok: np.ndarray = np.asarray(np.isfinite(q).all(axis=1))
    if t.size > 1:
        ok[1:] &= np.diff(t) > 0
    return t[ok], q[ok]


def _still_of(events: list[tuple[bool, Any]], joint_names: Sequence[str], threshold: float) -> StillIntervals:
    stamps, positions = _joint_matrix(events, joint_names)
    return still_intervals(stamps, positions, threshold)


def _diagnose(
    bag: Any,
    events: list[tuple[bool, Any]],
    model: RobotModel,
    tracker_frame_id: str,
    settings: CollectorSettings,
    pose_collector: AutoWindowCollector,
) -> str:
    """The likely reason why a replay found no static pose, in one line."""
    from robocal_uncertainty.bagio.campaign_format import METADATA_NAME

    if METADATA_NAME in bag.contents.metadata:
        return "this is a campaign file (one joint reading per pose), not a raw recording: use 'evaluate' on it"
    joints = [m for is_joint, m in events if is_joint]
    points = [m for is_joint, m in events if not is_joint]
    if not joints:
        return "the bag has no joint state"
    names = sorted({str(n) for m in joints for n in m.name})
    missing = [n for n in model.joint_names if n not in names]
    if missing:
        return (
            f"no joint state carries the joints of robot {model.name} ({', '.join(missing)} missing; the bag has "
            f"{', '.join(names)}): wrong --robot?"
        )
    frames = Counter(str(m.header.frame_id) for m in points)
    if frames and tracker_frame_id not in frames:
        seen = ", ".join(f"{f} ({c})" for f, c in frames.most_common())
        return f"no tracker point is in frame {tracker_frame_id!r} (points by frame: {seen}): check --tracker-frame"
    still = _still_of(events, model.joint_names, settings.joint_motion_threshold)
    durations = still.durations_s
    if durations.size == 0:
        return "the joint states cannot be read"
    i = int(np.argmax(durations))
    point_stamps = np.array(sorted(_stamp(m.header) for m in points), dtype=np.int64)
    inside = int(
        np.searchsorted(point_stamps, still.ends_ns[i], side="right")
        - np.searchsorted(point_stamps, still.starts_ns[i], side="left")
    )
    longest = float(durations[i])
    if longest < settings.window_s:
        hint = f"try --window-s {max(round(0.4 * longest, 2), 0.01):g}"
    elif pose_collector.rejected_dwells:
        hint = f"{pose_collector.rejected_dwells} dwells had fewer than --min-points {settings.min_points} points"
    else:
        hint = "the tracker points scatter more than --tracker-scatter-threshold-m; check the points"
    return (
        f"the longest still window of the joints was {longest:.3g} s with {inside} tracker points "
        f"(--window-s {settings.window_s:g}, --joint-motion-threshold-rad {settings.joint_motion_threshold:g}); "
        f"{hint}"
    )
