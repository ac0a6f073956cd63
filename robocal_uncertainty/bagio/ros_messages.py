"""ROS 2 messages of a campaign: CDR encoding, decoding and schema text, through rosbags.

Three message types carry a campaign: ``sensor_msgs/msg/JointState`` (joint readings, rad),
``geometry_msgs/msg/PointStamped`` (measured point, m) and ``geometry_msgs/msg/Vector3Stamped``
(per-coordinate standard deviation of the point, m). Header stamps are converted to and from
integer nanoseconds since the epoch.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from robocal_uncertainty.errors import InputError

if TYPE_CHECKING:
    from rosbags.typesys.store import Msg

__all__ = [
    "DECODE_ERRORS",
    "JOINT_STATE",
    "POINT_STAMPED",
    "VECTOR3_STAMPED",
    "JointReading",
    "MessageSchema",
    "VectorReading",
    "decode_joint_state",
    "decode_vector_stamped",
    "encode_joint_state",
    "encode_point_stamped",
    "encode_vector3_stamped",
    "message_schema",
    "ros_typestore",
    "stamp_parts",
]

JOINT_STATE = "sensor_msgs/msg/JointState"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"

_NS_PER_S = 1_000_000_000
_MAX_STAMP_NS = (2**31 - 1) * _NS_PER_S + _NS_PER_S - 1

DECODE_ERRORS: tuple[type[Exception], ...] = (
    SerdeError,
    ValueError,
    IndexError,
    KeyError,
    struct.error,
    UnicodeDecodeError,
)
"""Exceptions a malformed CDR payload can raise while decoding; callers wrap them."""


@dataclass(frozen=True)
class MessageSchema:
    """Schema of one ROS 2 message type as stored in an MCAP ``Schema`` record.

    Parameters
    ----------
    name : str
        Full type name, e.g. ``sensor_msgs/msg/JointState``.
    encoding : str
        Schema encoding, always ``ros2msg``.
    text : str
        Message definition with all dependent definitions appended (ROS 2 concatenated
        ``.msg`` format, as ``ros2 bag record`` stores it).
    rihs01 : str
        ROS 2 type hash (``RIHS01_...``) of the definition.
    """

    name: str
    encoding: str
    text: str
    rihs01: str


@dataclass(frozen=True)
class JointReading:
    """One decoded ``JointState`` message.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns since the epoch].
    names : tuple of str, length n_joints
        Joint names in message order.
    positions : ndarray, shape (n_joints,) [rad]
        Joint positions in the order of `names`.
    """

    stamp_ns: int
    names: tuple[str, ...]
    positions: NDArray[np.float64]


@dataclass(frozen=True)
class VectorReading:
    """One decoded ``PointStamped`` or ``Vector3Stamped`` message.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns since the epoch].
    frame_id : str
        Header frame id.
    xyz : ndarray, shape (3,) [m]
        The point (or vector) coordinates.
    """

    stamp_ns: int
    frame_id: str
    xyz: NDArray[np.float64]


@cache
def ros_typestore() -> Typestore:
    """Return the rosbags type store used for every campaign message (Jazzy, else Humble)."""
    store = getattr(Stores, "ROS2_JAZZY", None) or Stores.ROS2_HUMBLE
    return get_typestore(store)


@cache
def message_schema(typename: str) -> MessageSchema:
    """Return the ``ros2msg`` schema (full definition text and type hash) of `typename`."""
    store = ros_typestore()
    text, _ = store.generate_msgdef(typename, ros_version=2)
    return MessageSchema(typename, "ros2msg", text, store.hash_rihs01(typename))


def stamp_parts(stamp_ns: int) -> tuple[int, int]:
    """Split a stamp [ns] into ROS ``builtin_interfaces/Time`` (sec, nanosec).

    Raises
    ------
    InputError
        If the stamp is negative or beyond the int32 seconds of ROS time.
    """
    if not 0 <= stamp_ns <= _MAX_STAMP_NS:
        msg = f"stamp {stamp_ns} ns is outside the ROS time range [0, {_MAX_STAMP_NS}] ns"
        raise InputError(msg)
    return stamp_ns // _NS_PER_S, stamp_ns % _NS_PER_S


def _header(stamp_ns: int, frame_id: str) -> Msg:
    store = ros_typestore()
    sec, nanosec = stamp_parts(stamp_ns)
    time = store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    return store.types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)


def encode_joint_state(stamp_ns: int, names: tuple[str, ...], positions: NDArray[np.float64]) -> bytes:
    """Serialise a ``JointState`` (positions only, empty velocity and effort) to CDR.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns since the epoch].
    names : tuple of str, length n_joints
        Joint names.
    positions : ndarray, shape (n_joints,) [rad]
        Joint positions.
    """
    store = ros_typestore()
    empty = np.zeros(0, dtype=np.float64)
    message = store.types[JOINT_STATE](
        header=_header(stamp_ns, ""),
        name=list(names),
        position=np.array(positions, dtype=np.float64),
        velocity=empty,
        effort=empty,
    )
    return bytes(store.serialize_cdr(message, JOINT_STATE))


def encode_point_stamped(stamp_ns: int, frame_id: str, xyz: NDArray[np.float64]) -> bytes:
    """Serialise a ``PointStamped`` to CDR; `xyz` is shape (3,) [m]."""
    store = ros_typestore()
    point = store.types["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    message = store.types[POINT_STAMPED](header=_header(stamp_ns, frame_id), point=point)
    return bytes(store.serialize_cdr(message, POINT_STAMPED))


def encode_vector3_stamped(stamp_ns: int, frame_id: str, xyz: NDArray[np.float64]) -> bytes:
    """Serialise a ``Vector3Stamped`` to CDR; `xyz` is shape (3,) [m]."""
    store = ros_typestore()
    vector = store.types["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    message = store.types[VECTOR3_STAMPED](header=_header(stamp_ns, frame_id), vector=vector)
    return bytes(store.serialize_cdr(message, VECTOR3_STAMPED))


def _stamp_ns(header: Any) -> int:  # rosbags message classes are generated at run time
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def decode_joint_state(data: bytes) -> JointReading:
    """Decode a CDR ``JointState``.

    Raises
    ------
    ValueError
        If `name` and `position` differ in length (other decode errors: `DECODE_ERRORS`).
    """
    message: Any = ros_typestore().deserialize_cdr(data, JOINT_STATE)
    names = tuple(str(n) for n in message.name)
    positions = np.array(message.position, dtype=np.float64)
    if positions.shape != (len(names),):
        msg = f"JointState has {len(names)} names but {positions.size} positions"
        raise ValueError(msg)
    positions.setflags(write=False)
    return JointReading(_stamp_ns(message.header), names, positions)


def decode_vector_stamped(data: bytes, typename: str) -> VectorReading:
    """Decode a CDR ``PointStamped`` or ``Vector3Stamped`` (named by `typename`)."""
    message: Any = ros_typestore().deserialize_cdr(data, typename)
    value = message.point if typename == POINT_STAMPED else message.vector
    xyz = np.array([value.x, value.y, value.z], dtype=np.float64)
    xyz.setflags(write=False)
    return VectorReading(_stamp_ns(message.header), str(message.header.frame_id), xyz)
