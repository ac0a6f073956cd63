"""Offline replay of a raw recording through the collector and the calibration pipeline.

The raw bag (one MCAP file or a rosbag2 directory) holds ``sensor_msgs/msg/JointState`` on
the joint topic and ``geometry_msgs/msg/PointStamped`` on the tracker topic. Messages are
fed in recorded (log-time) order to a :class:`~robocal_uncertainty.pipeline.collector.StaticPoseCollector`,
exactly as the ROS nodes would receive them; its samples go to a
:class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.bagio.mcap_stream import McapContents, RawMessage, is_mcap, read_mcap_file
from robocal_uncertainty.bagio.ros_messages import DECODE_ERRORS, JOINT_STATE, POINT_STAMPED, ros_typestore
from robocal_uncertainty.bagio.rosbag2_dir import is_rosbag2_dir, read_rosbag2_dir
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import BagError, CampaignError
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.pipeline.collector import CollectorSettings, LogCallback, StaticPoseCollector
from robocal_uncertainty.uncertainty.calibration_mc import CalibrationUncertainty
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = ["ReplayResult", "replay_bag"]

_NS_PER_S = 1_000_000_000


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
    uncertainty : CalibrationUncertainty or None
        None without test joints or with ``calibrate=False``.
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
    """

    samples: tuple[CalibrationSample, ...]
    campaign: Campaign | None
    calibration: IdentificationResult | None
    uncertainty: CalibrationUncertainty | None
    dropped: dict[str, int]
    rejected_dwells: int
    message_counts: dict[str, int]
    tracker_frame_id: str
    truncated: bool


def _load(path: Path, topics: tuple[str, str]) -> McapContents:
    if not path.exists():
        msg = f"bag not found: {path}"
        raise BagError(msg)
    try:
        if is_rosbag2_dir(path):
            return read_rosbag2_dir(path, topics)
        if path.is_file() and is_mcap(path):
            return read_mcap_file(path)
    except OSError as err:
        msg = f"cannot read bag {path}: {err.strerror or err}"
        raise BagError(msg) from err
    msg = f"not a bag: {path} is neither an MCAP file nor a rosbag2 directory"
    raise BagError(msg)


def _topic(contents: McapContents, topic: str, typename: str, path: Path) -> None:
    channels = [c for c in contents.channels if c.topic == topic]
    if not channels:
        known = sorted({c.topic for c in contents.channels})
        msg = f"{path}: topic {topic} not found (topics: {known})"
        raise BagError(msg)
    for channel in channels:
        if channel.schema_name != typename or channel.message_encoding != "cdr":
            msg = (
                f"{path}: topic {topic} has type {channel.schema_name!r} "
                f"({channel.message_encoding!r}), expected {typename} (cdr)"
            )
            raise BagError(msg)


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def _decode(message: RawMessage, typename: str) -> Any | None:
    try:
        return ros_typestore().deserialize_cdr(message.data, typename)
    except DECODE_ERRORS:
        return None


def replay_bag(
    path: str | Path,
    model: RobotModel,
    *,
    joint_topic: str = JOINT_TOPIC,
    point_topic: str = POINT_TOPIC,
    tracker_frame_id: str | None = None,
    collector: CollectorSettings | None = None,
    lambda_: str | float = "auto",
    min_samples: int | None = None,
    uncertainty: UncertaintySettings | None = None,
    test_joints: ArrayLike | None = None,
    trials: int | str = 10_000,
    seed: int = 0,
    coverage: float = 0.95,
    campaign_path: str | Path | None = None,
    calibrate: bool = True,
    log: LogCallback | None = None,
    workers: int = 1,
) -> ReplayResult:
    """Replay a raw bag: detect static poses, calibrate, evaluate the uncertainty.

    Parameters
    ----------
    path : str or Path
        Raw recording: one MCAP file or a rosbag2 directory.
    model : RobotModel
        Nominal model; its joint names are collected.
    joint_topic, point_topic : str
        Topics of the joint states and tracker points.
    tracker_frame_id : str, optional
        Frame of valid tracker points; default: the most frequent ``frame_id`` on
        `point_topic` (points in other frames are dropped as ``wrong_frame``).
    collector : CollectorSettings, optional
        Static detection settings.
    lambda_, min_samples, uncertainty, test_joints, trials, seed, coverage, campaign_path
        Passed to :class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`.
    calibrate : bool
        Identify the parameters (and, with `test_joints`, evaluate the uncertainty).
    log : callable, optional
        ``log(cause, message)`` for dropped messages and rejected dwells (throttled).
    workers : int
        Monte Carlo processes (never changes the result).

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
    contents = _load(path, (joint_topic, point_topic))
    _topic(contents, joint_topic, JOINT_STATE, path)
    _topic(contents, point_topic, POINT_STAMPED, path)
    order = sorted(
        (m for m in contents.messages if m.channel.topic in (joint_topic, point_topic)),
        key=lambda m: m.log_time_ns,
    )
    undecodable = 0
    events: list[tuple[bool, Any]] = []
    for message in order:
        is_joint = message.channel.topic == joint_topic
        decoded = _decode(message, JOINT_STATE if is_joint else POINT_STAMPED)
        if decoded is None:
            undecodable += 1
        else:
            events.append((is_joint, decoded))
    counts = dict(Counter(m.channel.topic for m in order))
    if tracker_frame_id is None:
        frames = Counter(str(m.header.frame_id) for is_joint, m in events if not is_joint)
        if not frames:
            msg = f"{path}: no decodable message on {point_topic}"
            raise BagError(msg)
        tracker_frame_id = frames.most_common(1)[0][0]
    pose_collector = StaticPoseCollector.from_settings(
        model.joint_names, tracker_frame_id, collector or CollectorSettings(), log=log
    )
    pipeline = CalibrationPipeline(
        model,
        lambda_=lambda_,
        min_samples=min_samples,
        uncertainty=uncertainty,
        test_joints=test_joints,
        trials=trials,
        seed=seed,
        coverage=coverage,
        campaign_path=campaign_path,
    )
    with pipeline:
        samples: list[CalibrationSample] = []
        for is_joint, message in events:
            if is_joint:
                sample = pose_collector.add_joint_state(
                    _stamp(message.header), message.name, np.asarray(message.position, dtype=np.float64)
                )
            else:
                point = message.point
                sample = pose_collector.add_tracker_point(
                    _stamp(message.header), str(message.header.frame_id), (point.x, point.y, point.z)
                )
            if sample is not None:
                samples.append(sample)
                pipeline.add_sample(sample)
        last = pose_collector.flush()
        if last is not None:
            samples.append(last)
            pipeline.add_sample(last)
        calibration = pipeline.calibrate() if calibrate else None
        result_uncertainty = (
            pipeline.evaluate(workers=workers) if calibrate and pipeline.options.test_joints is not None else None
        )
        campaign = pipeline.campaign
    dropped = pose_collector.dropped
    dropped["undecodable"] = undecodable
    return ReplayResult(
        samples=tuple(samples),
        campaign=campaign,
        calibration=calibration,
        uncertainty=result_uncertainty,
        dropped=dropped,
        rejected_dwells=pose_collector.rejected_dwells,
        message_counts=counts,
        tracker_frame_id=tracker_frame_id,
        truncated=contents.truncated,
    )
