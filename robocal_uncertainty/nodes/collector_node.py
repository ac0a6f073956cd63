"""Collector node: joint states + tracker points -> one calibration sample per static pose.

Subscribes ``/joint_states`` (``sensor_msgs/JointState``) and ``/tracker/point``
(``geometry_msgs/PointStamped``), both with the sensor-data QoS (remap them in the launch
file). With ``tracker_pose_topic`` set (a 6-DOF tracker), that topic
(``geometry_msgs/PoseStamped``, or ``PoseWithCovarianceStamped`` with
``tracker_pose_with_covariance``) is subscribed instead of ``/tracker/point``: the collector
checks the orientation scatter (``orientation_scatter_threshold_rad``) and averages the
orientations (chordal mean) of each dwell, and the published samples carry the mean
orientation and its covariance. Messages are merged back into publication order
(:mod:`.stream_merge`) and fed, by the functions ``replay`` feeds a bag with
(:func:`~robocal_uncertainty.pipeline.replay.feed_joint_state`,
:func:`~robocal_uncertainty.pipeline.replay.feed_tracker_message`), to a
:class:`~robocal_uncertainty.pipeline.collector.StaticPoseCollector`. Each sample is first
appended to the campaign MCAP (flushed and fsynced per pose; a restart resumes from the
file, so no sample taken before a crash is lost), then published on ``robocal/samples``.

Bad messages (NaN, unknown or missing joints, wrong frame, stamps going backwards, ...) are
counted per cause, logged at most once per cause per ``log_throttle_s`` and dropped; the
counts are on ``robocal/collector_status`` (JSON in a ``std_msgs/String``, transient local)
and, with OK/WARN/ERROR and the time since the last sample and input, on ``/diagnostics``
(``diagnostic_msgs/DiagnosticArray`` every ``diagnostics_period_s``; rules in
:mod:`robocal_uncertainty.pipeline.diagnostics`).

Static detection is the one ``replay`` uses, with the same defaults: with ``auto_window``
(default) the window and guards are learnt from the first dwells of the stream
(:class:`~robocal_uncertainty.pipeline.auto_window.AutoWindowCollector`; ``window_s`` and
``guard_s`` are then upper bounds), so a recording played to the node gives the samples
``robocal-uncertainty replay`` finds in it; the first samples come out when the fifth dwell
ends. After a restart the window is learnt again from the new stream; set ``auto_window``
false for fixed settings.

Lost messages: each input's stamps are checked against its rate (:mod:`.input_gaps`); the
gaps and the messages missing in them are on ``/diagnostics`` and in the status JSON.

A static dwell gives its sample as soon as it is complete (static through ``guard_s +
average_s + guard_s``), so the last pose of a campaign is taken while the arm is still
there, exactly as ``replay`` takes it.

Services (``std_srvs/Trigger``): ``~/capture_now`` takes the current static pose at once;
``~/clear`` forgets the data of the current window/dwell (e.g. after the arm was bumped;
the recorded campaign is never erased by a service); ``~/save_copy`` writes a finished copy
of the campaign to ``save_copy_path`` (a file, or a directory for a timestamped name; ""
= timestamped next to the campaign).
"""

from __future__ import annotations

from robocal_uncertainty._threads import limit_threads

# The command line's thread policy, so the node computes the command line's numbers; before
# numpy loads its BLAS.
limit_threads()


import dataclasses
import json
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, ReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robocal_uncertainty.bagio.messages import sample_to_msg
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import CalibError
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from robocal_uncertainty.nodes.common import (
    CauseLogger,
    campaign_file,
    diagnostic_array,
    load_model,
    run_node,
    stamp_ns,
    to_ros,
)
from robocal_uncertainty.nodes.parameters import (
    DIAGNOSTICS_PERIOD,
    ParamSpec,
    declare_parameters,
    non_empty,
    one_of,
    positive,
)
from robocal_uncertainty.nodes.qos import DIAGNOSTICS_QOS, SAMPLE_QOS, latched_qos, sensor_qos
from robocal_uncertainty.pipeline.auto_window import AutoWindowCollector
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.pipeline.collector import CollectorSettings
from robocal_uncertainty.pipeline.diagnostics import DiagnosticStatus, DiagnosticThresholds, collector_status
from robocal_uncertainty.pipeline.input_gaps import GapCounter
from robocal_uncertainty.pipeline.replay import feed_joint_state, feed_tracker_message
from robocal_uncertainty.pipeline.stream_merge import StreamMerger

__all__ = ["PARAMETERS", "CollectorNode", "main"]

_JOINTS, _POINTS = 0, 1
RELIABLE_HOLD_S = 1.0
"""With reliable inputs, the least wall time [s] a message waits for the other stream (see reorder_window_s)."""
# rclpy >= 4 (Iron, Jazzy) hands a subscription callback taking two arguments the message
# info with the DDS source timestamp; Humble's rclpy cannot.
_HAS_MESSAGE_INFO = hasattr(Subscription, "CallbackType")

PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "robot_config",
        "paper_arm",
        "Robot model: a YAML file or a shipped model name (paper_arm, ur10); its joints are collected",
        read_only=True,
        check=non_empty,
    ),
    ParamSpec(
        "tracker_frame_id",
        "",
        "header.frame_id of valid tracker points (others are dropped as wrong_frame); "
        "empty = the robot model's base frame (tracker reporting base coordinates)",
        read_only=True,
    ),
    ParamSpec(
        "tracker_pose_topic",
        "",
        "6-DOF tracker: geometry_msgs/PoseStamped topic subscribed instead of /tracker/point; empty = points",
        read_only=True,
    ),
    ParamSpec(
        "tracker_pose_with_covariance",
        False,
        "6-DOF tracker: tracker_pose_topic carries geometry_msgs/PoseWithCovarianceStamped (its covariance is not "
        "used: a sample's covariances come from the scatter over its dwell)",
        read_only=True,
    ),
    ParamSpec(
        "orientation_scatter_threshold_rad",
        2e-3,
        "6-DOF tracker: largest peak-to-peak range of any rotation-matrix entry over a static window",
        "rad",
        True,
        1e-9,
        3.2,
    ),
    ParamSpec(
        "campaign_path",
        "",
        "Campaign MCAP every sample is appended to (resumed when it exists); empty = $ROS_HOME/robocal/campaign.mcap",
        read_only=True,
    ),
    ParamSpec("fsync", True, "fsync the campaign file after every sample (survives power loss)", read_only=True),
    ParamSpec(
        "auto_window",
        True,
        "Learn the window and guards from the first dwells (as replay does without --window-s); window_s and guard_s "
        "are then upper bounds",
        read_only=True,
    ),
    ParamSpec("window_s", 0.5, "Sliding window deciding whether the arm is static", "s", True, 0.001, 60.0, positive),
    ParamSpec(
        "joint_motion_threshold_rad",
        5e-4,
        "Largest peak-to-peak joint motion in a static window",
        "rad",
        True,
        1e-9,
        1.0,
        positive,
    ),
    ParamSpec(
        "tracker_scatter_threshold_m",
        1e-4,
        "Largest peak-to-peak tracker coordinate scatter in a static window",
        "m",
        True,
        1e-9,
        1.0,
        positive,
    ),
    ParamSpec("min_points", 10, "Fewest tracker points a dwell must average", "", True, 2, 1_000_000),
    ParamSpec("guard_s", 0.1, "Data dropped at each end of a dwell before averaging", "s", True, 0.0, 60.0),
    ParamSpec(
        "average_s",
        1.0,
        "Span of a dwell averaged after the settle guard; a dwell static for guard + average + guard is complete "
        "and its sample taken at once (the last pose of a campaign included)",
        "s",
        True,
        0.001,
        3600.0,
        positive,
    ),
    ParamSpec(
        "ignore_extra_joints",
        False,
        "Ignore joints beyond the model's in joint states (else such messages are dropped as unknown_joint)",
        read_only=True,
    ),
    ParamSpec(
        "log_throttle_s",
        5.0,
        "At most one log line per drop cause per this time (message time and wall time)",
        "s",
        True,
        0.0,
        3600.0,
    ),
    ParamSpec(
        "reorder_window_s",
        0.05,
        "Wall time a message waits for the other stream so both are fed in publication order; 0 = arrival order",
        "s",
        True,
        0.0,
        5.0,
    ),
    ParamSpec(
        "input_reliability",
        "best_effort",
        "QoS reliability of the two input subscriptions: best_effort (sensor-data profile, live sensors: a late "
        "reading is dropped, not retransmitted) or reliable (keep all; replaying a recording with ros2 bag play: "
        "nothing lost, the player is slowed down if the node falls behind; messages wait at least 1 s for the "
        "other stream)",
        read_only=True,
        check=one_of("best_effort", "reliable"),
    ),
    ParamSpec(
        "input_queue_depth",
        100,
        "Subscription queue of each input (sensor-data QoS); >= rate x longest pause (e.g. an fsync)",
        "messages",
        True,
        1,
        100_000,
    ),
    ParamSpec(
        "save_copy_path",
        "",
        "Destination of ~/save_copy: a file, a directory (timestamped name) or empty (timestamped, next to the "
        "campaign)",
    ),
    ParamSpec("status_period_s", 1.0, "Period of the collector_status update (when changed)", "s", True, 0.05, 3600.0),
    DIAGNOSTICS_PERIOD,
    ParamSpec(
        "input_timeout_s",
        2.0,
        "An input stream silent for longer is reported on /diagnostics (WARN)",
        "s",
        True,
        0.01,
        3600.0,
    ),
)


class CollectorNode(Node):
    """The collector as a ROS 2 node (see the module docstring)."""

    def __init__(self, *, node_name: str = "collector_node", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        p = declare_parameters(self, PARAMETERS)
        self.model = load_model(p["robot_config"])
        frame_id = p["tracker_frame_id"] or self.model.base_frame_id
        self._causes = CauseLogger(self, p["log_throttle_s"])
        settings = CollectorSettings(
            window_s=p["window_s"],
            joint_motion_threshold=p["joint_motion_threshold_rad"],
            tracker_scatter_threshold=p["tracker_scatter_threshold_m"],
            min_points=p["min_points"],
            guard_s=p["guard_s"],
            average_s=p["average_s"],
            log_throttle_s=p["log_throttle_s"],
            ignore_extra_joints=p["ignore_extra_joints"],
            orientation_scatter_threshold=p["orientation_scatter_threshold_rad"],
        )
        self.collector = AutoWindowCollector(
            self.model.joint_names, frame_id, settings, auto=p["auto_window"], log=self._causes.warning
        )
        self._gaps = {"joint_states": GapCounter(), "tracker_points": GapCounter()}
        self.campaign_path = campaign_file(p["campaign_path"])
        self.campaign_path.parent.mkdir(parents=True, exist_ok=True)
        self.recorder = CalibrationPipeline(
            self.model,
            campaign_path=self.campaign_path,
            fsync=p["fsync"],
            metadata={"source": "robocal_uncertainty collector_node", "robot": self.model.name},
        )
        for warning in self.recorder.resume_warnings:
            self.get_logger().warning(f"campaign {self.campaign_path}: {warning}")
        if self.recorder.n_samples:
            self.get_logger().info(f"resumed {self.recorder.n_samples} samples from {self.campaign_path}")
        self._learning = self.collector.learning
        self.received = {"joint_states": 0, "tracker_points": 0}
        self.published = 0
        self.record_failures = 0
        hold_s = p["reorder_window_s"]
        if p["input_reliability"] == "reliable":
            # Nothing is lost, but a stream slowed by flow control can lag the other by far more
            # than a sensor's transport latency: wait up to RELIABLE_HOLD_S for it.
            hold_s = max(hold_s, RELIABLE_HOLD_S)
        self._merger = StreamMerger(self._feed, hold_ns=round(hold_s * 1e9))

        self._sample_pub = self.create_publisher(CalibrationSampleMsg, "robocal/samples", SAMPLE_QOS)
        self._status_pub = self.create_publisher(String, "robocal/collector_status", latched_qos())
        input_qos = sensor_qos(p["input_queue_depth"])
        if p["input_reliability"] == "reliable":
            # Keep all: a node that falls behind slows the publisher instead of losing readings.
            input_qos.reliability = ReliabilityPolicy.RELIABLE
            input_qos.history = HistoryPolicy.KEEP_ALL
        pose_topic = p["tracker_pose_topic"]
        pose_type: Any = PoseWithCovarianceStamped if p["tracker_pose_with_covariance"] else PoseStamped
        tracker_type: Any = pose_type if pose_topic else PointStamped
        tracker_topic = pose_topic or "/tracker/point"
        if _HAS_MESSAGE_INFO:
            self.create_subscription(JointState, "/joint_states", self._on_joint_state_info, input_qos)
            self.create_subscription(tracker_type, tracker_topic, self._on_point_info, input_qos)
        else:
            self.create_subscription(JointState, "/joint_states", self._on_joint_state, input_qos)
            self.create_subscription(tracker_type, tracker_topic, self._on_point, input_qos)
        self.create_service(Trigger, "~/capture_now", self._capture_now)
        self.create_service(Trigger, "~/clear", self._clear)
        self.create_service(Trigger, "~/save_copy", self._save_copy)
        if self._merger.hold_ns:
            period = min(max(self._merger.hold_ns / 2e9, 0.005), 0.1)
            self.create_timer(period, lambda: self._merger.release(time.monotonic_ns()))
        self._last_status = ""
        self.create_timer(p["status_period_s"], self._publish_status)
        self._last_input_ns: dict[str, int | None] = {"joint_states": None, "tracker_points": None}
        self._last_sample_ns: int | None = None
        self._thresholds = DiagnosticThresholds(input_timeout_s=p["input_timeout_s"])
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.create_timer(p["diagnostics_period_s"], self._publish_diagnostics)
        self._publish_status()
        self.get_logger().info(
            f"collecting joints {list(self.model.joint_names)} and tracker points in frame {frame_id!r}; "
            f"campaign {self.campaign_path}"
        )

    # -- input -----------------------------------------------------------------------------

    def _on_joint_state_info(self, msg: JointState, info: dict[str, int]) -> None:
        self._push(_JOINTS, msg, info.get("source_timestamp", 0))

    def _on_point_info(self, msg: PointStamped | PoseStamped | PoseWithCovarianceStamped, info: dict[str, int]) -> None:
        self._push(_POINTS, msg, info.get("source_timestamp", 0))

    def _on_joint_state(self, msg: JointState) -> None:
        self._push(_JOINTS, msg, 0)

    def _on_point(self, msg: PointStamped | PoseStamped | PoseWithCovarianceStamped) -> None:
        self._push(_POINTS, msg, 0)

    def _push(self, stream: int, msg: Any, source_ns: int) -> None:
        name = "joint_states" if stream == _JOINTS else "tracker_points"
        self.received[name] += 1
        self._last_input_ns[name] = self.get_clock().now().nanoseconds
        arrival = time.monotonic_ns()
        self._merger.push(stream, source_ns or arrival, arrival, msg)

    def _feed(self, stream: int, msg: Any) -> None:
        """Hand one message (in publication order) to the collector."""
        self._gaps["joint_states" if stream == _JOINTS else "tracker_points"].add(stamp_ns(msg.header))
        try:
            if stream == _JOINTS:
                samples = feed_joint_state(self.collector, msg)
            else:  # a point, or a pose from a 6-DOF tracker
                samples = feed_tracker_message(self.collector, msg)
        except CalibError as err:  # the collector drops bad input itself; this is a last resort
            self._causes.warning("internal", f"message dropped: {err}")
            return
        was_learning = self._learning
        self._learning = self.collector.learning
        if was_learning and not self._learning:
            used = self.collector.settings
            self.get_logger().info(
                f"static window {used.window_s:g} s, guards {used.guard_s:g} s (learnt from the first dwells); "
                f"{len(samples)} held samples follow"
            )
        for sample in samples:
            self._take(sample)

    def _take(self, sample: CalibrationSample) -> bool:
        """Record `sample` to the campaign file, then publish it."""
        try:
            self.recorder.add_sample(sample)
        except CalibError as err:
            self.record_failures += 1
            self.get_logger().error(f"sample at {sample.stamp_ns} ns not recorded, not published: {err}")
            return False
        self._sample_pub.publish(to_ros(sample_to_msg(sample), CalibrationSampleMsg))
        self.published += 1
        self._last_sample_ns = self.get_clock().now().nanoseconds
        point_mm = ", ".join(f"{v * 1e3:.3f}" for v in sample.point)
        what = "points" if sample.orientation is None else "poses"
        self.get_logger().info(
            f"sample {self.recorder.n_samples}: point ({point_mm}) mm from {sample.tracker_point_count} {what}, "
            f"{sample.joint_state_count} joint states"
        )
        self._publish_status()
        return True

    # -- services --------------------------------------------------------------------------

    def _capture_now(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._merger.drain()
        samples = self.collector.capture_now()  # while learning: decides the window first
        self._learning = self.collector.learning
        static = self.collector.is_static
        taken = [self._take(sample) for sample in samples]
        if not samples:
            response.success = False
            response.message = (
                "the arm is not static" if not static else "this dwell was already captured or holds too few data"
            )
        elif all(taken):
            response.success = True
            response.message = f"sample {self.recorder.n_samples} taken at {samples[-1].stamp_ns} ns"
        else:
            response.success = False
            response.message = "a sample could not be recorded (see the log)"
        return response

    def _clear(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._merger.drain()
        was_static = self.collector.is_static
        for sample in self.collector.clear():  # forget the current dwell; finished ones held while learning stay
            self._take(sample)
        self._learning = self.collector.learning
        response.success = True
        response.message = "window cleared" + (" (the current static dwell was discarded)" if was_static else "")
        return response

    def _save_copy(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        from robocal_uncertainty.bagio import write_campaign

        campaign = self.recorder.campaign
        if campaign is None:
            response.success = False
            response.message = "no samples yet"
            return response
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        name = f"{self.campaign_path.stem}-{stamp}.mcap"
        target = str(self.get_parameter("save_copy_path").value).strip()
        destination = self.campaign_path.with_name(name) if not target else Path(target).expanduser()
        if destination.is_dir():
            destination = destination / name
        try:
            write_campaign(destination, campaign)
        except CalibError as err:
            response.success = False
            response.message = str(err)
            return response
        response.success = True
        response.message = f"wrote {campaign.n_poses} samples to {destination}"
        return response

    # -- status ----------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """Counts: samples, messages received and dropped per cause, rejected dwells."""
        return {
            "samples": self.recorder.n_samples,
            "published": self.published,
            "received": dict(self.received),
            "dropped": self.collector.dropped,
            "rejected_dwells": self.collector.rejected_dwells,
            "record_failures": self.record_failures,
            "static": self.collector.is_static,
            "campaign_path": str(self.campaign_path),
            "learning_window": self.collector.learning,
            "window_s": self.collector.settings.window_s,
            "guard_s": self.collector.settings.guard_s,
            "input_gaps": {name: counter.gaps for name, counter in self._gaps.items()},
            "missing": {name: counter.missing for name, counter in self._gaps.items()},
        }

    def _publish_status(self) -> None:
        text = json.dumps(self.status(), sort_keys=True)
        if text != self._last_status:
            self._last_status = text
            self._status_pub.publish(String(data=text))

    def diagnostic_status(self) -> DiagnosticStatus:
        """The collector's health (rules in :mod:`robocal_uncertainty.pipeline.diagnostics`), with the
        input gaps (messages lost in transport, estimated from each stream's stamps and rate)."""
        status = collector_status(
            name=f"{self.get_name()}: static-pose collector",
            hardware_id=self.model.name,
            now_ns=self.get_clock().now().nanoseconds,
            samples=self.recorder.n_samples,
            received=self.received,
            dropped=self.collector.dropped,
            rejected_dwells=self.collector.rejected_dwells,
            record_failures=self.record_failures,
            last_sample_ns=self._last_sample_ns,
            last_input_ns=self._last_input_ns,
            static=self.collector.is_static,
            thresholds=self._thresholds,
        )
        extra = [("learning window", str(self.collector.learning).lower())]
        extra.append(("window [s]", f"{self.collector.settings.window_s:g}"))
        for name, counter in self._gaps.items():
            extra.append((f"{name} gaps", str(counter.gaps)))
            extra.append((f"{name} missing", str(counter.missing)))
        return dataclasses.replace(status, values=tuple(status.values) + tuple(extra))

    def _publish_diagnostics(self) -> None:
        self._diagnostics_pub.publish(diagnostic_array(self, [self.diagnostic_status()]))

    def destroy_node(self) -> None:
        self.recorder.close()
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    """``ros2 run robocal_uncertainty collector_node``."""
    return run_node(CollectorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
