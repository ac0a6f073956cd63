"""``geometry_msgs/msg/PoseStamped`` to and from CDR: the measured pose of a 6-DOF tracker.

The position is in metres, the orientation a unit quaternion ``(x, y, z, w)`` of the
measured (probe) frame in ``header.frame_id``, as in ROS.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.bagio.ros_messages import ros_typestore, stamp_parts

__all__ = ["POSE_STAMPED", "PoseReading", "decode_pose_stamped", "encode_pose_stamped"]

POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
_NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class PoseReading:
    """One decoded ``PoseStamped``.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns since the epoch].
    frame_id : str
    xyz : ndarray, shape (3,) [m]
    quaternion : ndarray, shape (4,)
        ``(x, y, z, w)`` as stored (not normalised or checked here).
    """

    stamp_ns: int
    frame_id: str
    xyz: NDArray[np.float64]
    quaternion: NDArray[np.float64]


def encode_pose_stamped(
    stamp_ns: int, frame_id: str, xyz: NDArray[np.float64], quaternion: NDArray[np.float64]
) -> bytes:
    """Serialise a ``PoseStamped``: position `xyz` (3,) [m], orientation `quaternion` (x, y, z, w)."""
    store = ros_typestore()
    sec, nanosec = stamp_parts(stamp_ns)
    time = store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    header = store.types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)
    point = store.types["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    q = [float(v) for v in quaternion]
    orientation = store.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
    pose = store.types["geometry_msgs/msg/Pose"](position=point, orientation=orientation)
    message = store.types[POSE_STAMPED](header=header, pose=pose)
    return bytes(store.serialize_cdr(message, POSE_STAMPED))


def decode_pose_stamped(data: bytes) -> PoseReading:
    """Decode a CDR ``PoseStamped`` (decode errors: ``ros_messages.DECODE_ERRORS``)."""
    message: Any = ros_typestore().deserialize_cdr(data, POSE_STAMPED)
    p, o = message.pose.position, message.pose.orientation
    stamp = int(message.header.stamp.sec) * _NS_PER_S + int(message.header.stamp.nanosec)
    return PoseReading(
        stamp,
        str(message.header.frame_id),
        np.array([p.x, p.y, p.z], dtype=np.float64),
        np.array([o.x, o.y, o.z, o.w], dtype=np.float64),
    )
