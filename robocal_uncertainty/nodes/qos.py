"""Quality of service of every topic, chosen per role.

* Raw inputs (``/joint_states``, ``/tracker/point``): the sensor-data profile (best effort,
  volatile, keep last): a late or lost reading is better dropped than retransmitted and
  delivered out of its time; the collector's static windows tolerate gaps.
* Samples (``robocal/samples``): reliable, volatile, keep last 100: every calibration pose
  matters, and 100 absorbs a slow subscriber; late joiners recover the earlier samples from
  the campaign file instead (see :mod:`robocal_uncertainty.nodes.common`).
* Results (``robocal/calibration``, ``robocal/uncertainty``, ``robocal/pose_with_covariance``)
  and status: reliable, transient local, keep last: a subscriber started later still gets
  the latest result. Depth 1 for one message per result; the per-test-configuration
  uncertainty topics keep one message per configuration (the latest full set); the RViz
  markers (``robocal/uncertainty_markers``) are one latched MarkerArray.
* ``/diagnostics``: reliable, volatile, depth 10, as diagnostic_updater publishes it.
"""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

__all__ = ["DIAGNOSTICS_QOS", "SAMPLE_QOS", "SAMPLE_QUEUE_DEPTH", "latched_qos", "sensor_qos"]

SAMPLE_QUEUE_DEPTH = 100

SAMPLE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=SAMPLE_QUEUE_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""``/diagnostics``: what diagnostic_updater uses (reliable, volatile, depth 10); periodic, so
no need for transient local."""


def sensor_qos(depth: int | None = None) -> QoSProfile:
    """The sensor-data profile (best effort, volatile), optionally with a deeper queue."""
    profile = QoSProfile(
        history=qos_profile_sensor_data.history,
        depth=qos_profile_sensor_data.depth,
        reliability=qos_profile_sensor_data.reliability,
        durability=qos_profile_sensor_data.durability,
    )
    if depth is not None:
        profile.depth = depth
    return profile


def latched_qos(depth: int = 1) -> QoSProfile:
    """Reliable + transient local, keep last `depth`: late joiners get the latest result."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(1, int(depth)),
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
