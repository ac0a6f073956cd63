"""Offline replay of a raw recording through the collector and the calibration pipeline.

The raw bag (one MCAP file or a rosbag2 directory) holds ``sensor_msgs/msg/JointState`` on
the joint topic and ``geometry_msgs/msg/PointStamped`` on the tracker topic. Messages are
fed in recorded (log-time) order to a :class:`~robocal_uncertainty.pipeline.collector.StaticPoseCollector`,
exactly as the ROS nodes would receive them; its samples go to a
:class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`.

A replay turns a bag into samples, a campaign and (optionally) a calibration. The
uncertainty of a replayed bag is evaluated by ``robocal_uncertainty.app.replay``, which
hands this campaign to the same ``app.evaluate`` as the command line's ``evaluate``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robocal_uncertainty.bagio.bag import open_bag
from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, POINT_STAMPED
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import BagError, CampaignError
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.pipeline.collector import CollectorSettings, LogCallback, StaticPoseCollector
from robocal_uncertainty.uncertainty.options import EvaluationOptions

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
    dropped: dict[str, int]
    rejected_dwells: int
    message_counts: dict[str, int]
    tracker_frame_id: str
    truncated: bool


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def replay_bag(
    path: str | Path,
    model: RobotModel,
    *,
    joint_topic: str = JOINT_TOPIC,
    point_topic: str = POINT_TOPIC,
    tracker_frame_id: str | None = None,
    collector: CollectorSettings | None = None,
    options: EvaluationOptions | None = None,
    min_samples: int | None = None,
    campaign_path: str | Path | None = None,
    calibrate: bool = True,
    log: LogCallback | None = None,
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
    tracker_frame_id : str, optional
        Frame of valid tracker points; default: the most frequent ``frame_id`` on
        `point_topic` (points in other frames are dropped as ``wrong_frame``).
    collector : CollectorSettings, optional
        Static detection settings.
    options, min_samples, campaign_path
        Passed to :class:`~robocal_uncertainty.pipeline.calibration_pipeline.CalibrationPipeline`
        (``options.lambda_`` and ``options.accept_unconverged`` set the identification).
    calibrate : bool
        Identify the parameters.
    log : callable, optional
        ``log(cause, message)`` for dropped messages and rejected dwells (throttled).

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
    bag = open_bag(path, (joint_topic, point_topic))
    bag.topic_messages(joint_topic, JOINT_STATE)
    bag.topic_messages(point_topic, POINT_STAMPED)
    order = sorted(
        (m for m in bag.contents.messages if m.channel.topic in (joint_topic, point_topic)),
        key=lambda m: m.log_time_ns,
    )
    undecodable = 0
    events: list[tuple[bool, Any]] = []
    for message in order:
        is_joint = message.channel.topic == joint_topic
        decoded = bag.try_decode(message, JOINT_STATE if is_joint else POINT_STAMPED)
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
    pipeline = CalibrationPipeline(model, options=options, min_samples=min_samples, campaign_path=campaign_path)
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
        campaign = pipeline.campaign
    dropped = pose_collector.dropped
    dropped["undecodable"] = undecodable
    return ReplayResult(
        samples=tuple(samples),
        campaign=campaign,
        calibration=calibration,
        dropped=dropped,
        rejected_dwells=pose_collector.rejected_dwells,
        message_counts=counts,
        tracker_frame_id=tracker_frame_id,
        truncated=bag.truncated,
    )
