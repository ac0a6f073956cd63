"""The package's own ROS 2 messages, registered in the rosbags type store (no ROS needed).

``robocal_uncertainty/msg/CalibrationSample``, ``CalibrationResult`` and ``PoseUncertainty``
are defined by the ``.msg`` files shipped in ``robocal_uncertainty/msg_definitions/`` (the
repository's ``msg/`` links to them for rosidl). :func:`robocal_typestore` adds them to
the shared :func:`~robocal_uncertainty.bagio.ros_messages.ros_typestore`, so they can be
serialised to CDR, written to and read from MCAP bags, and their schemas generated with
:func:`~robocal_uncertainty.bagio.ros_messages.message_schema`.

The converters return rosbags message objects (plain dataclasses); ROS nodes copy them
field by field into the rosidl-generated classes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from robocal_uncertainty.bagio.ros_messages import DECODE_ERRORS, ros_typestore, stamp_parts
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import BagError, InputError
from robocal_uncertainty.uncertainty.calibration import CalibrationUncertainty, PoseUncertainty

__all__ = [
    "CALIBRATION_RESULT",
    "CALIBRATION_SAMPLE",
    "MESSAGE_NAMES",
    "POSE_UNCERTAINTY",
    "calibration_to_msg",
    "decode_message",
    "encode_message",
    "message_definition",
    "msg_to_sample",
    "pose_uncertainty_to_msg",
    "pose_with_covariance",
    "robocal_typestore",
    "ros_pose_covariance",
    "sample_to_msg",
    "uncertainty_to_msgs",
]

CALIBRATION_SAMPLE = "robocal_uncertainty/msg/CalibrationSample"
CALIBRATION_RESULT = "robocal_uncertainty/msg/CalibrationResult"
POSE_UNCERTAINTY = "robocal_uncertainty/msg/PoseUncertainty"
MESSAGE_NAMES: tuple[str, ...] = (CALIBRATION_SAMPLE, CALIBRATION_RESULT, POSE_UNCERTAINTY)
_DEFINITIONS = "msg_definitions"
_NS_PER_S = 1_000_000_000

# rosbags message classes are generated at run time; they are typed as Any here.
Msg = Any


def message_definition(typename: str) -> str:
    """Return the ``.msg`` text of one of :data:`MESSAGE_NAMES` (read from package data).

    Raises
    ------
    InputError
        Unknown message name.
    BagError
        The definition file is missing from the installation.
    """
    if typename not in MESSAGE_NAMES:
        msg = f"unknown robocal_uncertainty message {typename!r}; known: {', '.join(MESSAGE_NAMES)}"
        raise InputError(msg)
    name = typename.rsplit("/", 1)[-1] + ".msg"
    try:
        return (resources.files("robocal_uncertainty") / _DEFINITIONS / name).read_text(encoding="utf-8")
    except OSError as err:
        msg = f"message definition {_DEFINITIONS}/{name} is missing from the installed package ({err})"
        raise BagError(msg) from err


@cache
def robocal_typestore() -> Typestore:
    """The shared ROS 2 type store with this package's three messages registered."""
    store = ros_typestore()
    types = {}
    for typename in MESSAGE_NAMES:
        types.update(get_types_from_msg(message_definition(typename), typename))
    store.register(types)
    return store


def encode_message(message: Msg, typename: str) -> bytes:
    """Serialise a message of `typename` (any type of :func:`robocal_typestore`) to CDR."""
    return bytes(robocal_typestore().serialize_cdr(message, typename))


def decode_message(data: bytes, typename: str) -> Msg:
    """Deserialise a CDR payload of `typename`.

    Raises
    ------
    BagError
        If the payload is not a valid `typename` message.
    """
    try:
        return robocal_typestore().deserialize_cdr(data, typename)
    except DECODE_ERRORS as err:
        msg = f"cannot decode a {typename} message: {type(err).__name__}: {err}"
        raise BagError(msg) from err


def _header(stamp_ns: int, frame_id: str) -> Msg:
    store = robocal_typestore()
    sec, nanosec = stamp_parts(int(stamp_ns))
    time = store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    return store.types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)


def _point(xyz: NDArray[np.float64]) -> Msg:
    return robocal_typestore().types["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def _f64(values: ArrayLike) -> NDArray[np.float64]:
    return np.array(values, dtype=np.float64).reshape(-1)


def sample_to_msg(sample: CalibrationSample) -> Msg:
    """Convert a :class:`CalibrationSample` to a ``CalibrationSample`` message.

    A 6-DOF sample sets ``has_orientation``, its mean ``orientation`` (x, y, z, w) and
    ``orientation_covariance`` (3x3 row-major [rad^2]); a point sample leaves them the
    identity quaternion and zeros. Every float is copied exactly (float64 on the wire).
    """
    types = robocal_typestore().types
    has_orientation = sample.orientation is not None and sample.orientation_covariance is not None
    q = np.array([0.0, 0.0, 0.0, 1.0]) if sample.orientation is None else sample.orientation
    rot_cov = np.zeros(9) if sample.orientation_covariance is None else _f64(sample.orientation_covariance)
    return types[CALIBRATION_SAMPLE](
        header=_header(sample.stamp_ns, sample.frame_id),
        joint_names=list(sample.joint_names),
        joint_positions=_f64(sample.joint_positions),
        joint_position_std=_f64(sample.joint_position_std),
        point=_point(sample.point),
        point_covariance=_f64(sample.point_covariance),
        joint_state_count=int(sample.joint_state_count),
        tracker_point_count=int(sample.tracker_point_count),
        has_orientation=has_orientation,
        orientation=types["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
        orientation_covariance=rot_cov,
    )


def msg_to_sample(message: Msg) -> CalibrationSample:
    """Convert a ``CalibrationSample`` message back to a :class:`CalibrationSample`.

    With ``has_orientation`` the sample carries the orientation and its covariance (6-DOF);
    without, both are None and the message's orientation fields are ignored.

    Raises
    ------
    InputError
        Inconsistent lengths, NaN, a non-unit orientation quaternion, or other invalid content.
    """
    stamp = int(message.header.stamp.sec) * _NS_PER_S + int(message.header.stamp.nanosec)
    point = message.point
    orientation = orientation_cov = None
    if bool(message.has_orientation):
        o = message.orientation
        orientation = np.array([o.x, o.y, o.z, o.w], dtype=np.float64)
        orientation_cov = _f64(message.orientation_covariance).reshape(3, 3)
    return CalibrationSample(
        stamp_ns=stamp,
        frame_id=str(message.header.frame_id),
        joint_names=tuple(str(n) for n in message.joint_names),
        joint_positions=_f64(message.joint_positions),
        joint_position_std=_f64(message.joint_position_std),
        point=np.array([point.x, point.y, point.z], dtype=np.float64),
        point_covariance=_f64(message.point_covariance).reshape(3, 3),
        joint_state_count=int(message.joint_state_count),
        tracker_point_count=int(message.tracker_point_count),
        orientation=orientation,
        orientation_covariance=orientation_cov,
    )


def calibration_to_msg(
    result: IdentificationResult,
    *,
    stamp_ns: int,
    frame_id: str | None = None,
    uncertainty: CalibrationUncertainty | None = None,
) -> Msg:
    """Convert an identification result to a ``CalibrationResult`` message.

    Parameters
    ----------
    result : IdentificationResult
    stamp_ns : int
        Header stamp [ns since the epoch].
    frame_id : str, optional
        Header frame; the calibrated model's ``base_frame_id`` by default.
    uncertainty : CalibrationUncertainty, optional
        When given (a Monte Carlo of this calibration), ``standard_uncertainty`` holds
        the Monte Carlo standard uncertainty of each estimated parameter; otherwise the
        first-order ``result.linearized_std``. NaN where a parameter was not estimated.
    """
    std = _f64(result.linearized_std)
    if uncertainty is not None:
        std = np.full(len(result.parameter_names), np.nan)
        index = {name: k for k, name in enumerate(result.parameter_names)}
        for name, summary in zip(uncertainty.parameter_names, uncertainty.parameters):
            std[index[name]] = summary.standard_uncertainty
    return robocal_typestore().types[CALIBRATION_RESULT](
        header=_header(stamp_ns, result.model.base_frame_id if frame_id is None else frame_id),
        model_name=result.model.name,
        parameter_names=list(result.parameter_names),
        nominal=_f64(result.nominal),
        estimate=_f64(result.estimate),
        standard_uncertainty=std,
        identifiable=np.array(result.identifiable, dtype=np.bool_),
        lambda_value=float(result.lambda_),
        lambda_method=str(result.lambda_method),
        rms_before=float(result.rms_before),
        max_before=float(result.max_before),
        rms_after=float(result.rms_after),
        max_after=float(result.max_after),
        condition_number=float(result.condition_number),
        sample_count=int(result.n_poses),
    )


def ros_pose_covariance(pose: PoseUncertainty, *, undetermined_variance: float = 1e6) -> NDArray[np.float64]:
    """6x6 covariance of ``geometry_msgs/PoseWithCovariance`` for one configuration [m^2, m rad, rad^2].

    Rows and columns x, y, z, rotation about the fixed x, y, z axes. With an orientation
    statement: :meth:`OrientationUncertainty.ros_covariance` (huge `undetermined_variance`
    [rad^2] only along the undetermined rotation directions); without one (no orientation
    evaluated) the rotation block is `undetermined_variance` times the identity.
    """
    if pose.orientation is None:
        out = np.zeros((6, 6))
        out[:3, :3] = pose.covariance
        out[3:, 3:] = np.eye(3) * undetermined_variance
        return out
    return np.asarray(
        pose.orientation.ros_covariance(pose.covariance, undetermined_variance=undetermined_variance), dtype=np.float64
    )


def pose_with_covariance(
    pose: PoseUncertainty, *, undetermined_variance: float = 1e6
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Position (3,) [m], orientation quaternion (x, y, z, w) and the 6x6 ROS covariance.

    The ROS-free content of ``robocal/pose_with_covariance``: the mean orientation when the
    Monte Carlo evaluated one, else the identity (with `undetermined_variance` on the rotation).
    """
    quaternion = (
        np.array([0.0, 0.0, 0.0, 1.0]) if pose.orientation is None else np.asarray(pose.orientation.mean_quaternion)
    )
    return (
        np.asarray(pose.mean, dtype=np.float64),
        quaternion,
        ros_pose_covariance(pose, undetermined_variance=undetermined_variance),
    )


def _orientation_fields(pose: PoseUncertainty, types: Mapping[str, Any]) -> dict[str, Any]:
    """The orientation fields of a PoseUncertainty message (identity and NaN without orientation)."""
    orientation = pose.orientation
    nan3 = np.full(3, np.nan)
    if orientation is None:
        quaternion = types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        rot_cov = np.zeros(9)
        rot = dict.fromkeys(("u", "U", "sl", "sh", "hl", "hh"), nan3)
        undetermined = np.zeros(3, dtype=bool)
        pose_cov = np.zeros(36)
    else:
        q = orientation.mean_quaternion
        quaternion = types["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
        determined = orientation.determined
        pose_cov = ros_pose_covariance(pose).reshape(-1)
        # The rotation block of pose_covariance: the Monte Carlo covariance where determined,
        # the huge variance along undetermined directions (never a finite number there).
        rot_cov = pose_cov.reshape(6, 6)[3:, 3:].reshape(-1).copy()
        rot_axes = orientation.axes

        def rot_axis(values: list[float | None]) -> NDArray[np.float64]:
            return np.array(
                [np.nan if v is None or not ok else v for v, ok in zip(values, determined, strict=True)],
                dtype=np.float64,
            )

        rot = {
            "u": rot_axis([a.standard_uncertainty for a in rot_axes]),
            "U": rot_axis([a.expanded_uncertainty for a in rot_axes]),
            "sl": rot_axis([a.probabilistically_symmetric.low for a in rot_axes]),
            "sh": rot_axis([a.probabilistically_symmetric.high for a in rot_axes]),
            "hl": rot_axis([a.shortest.low for a in rot_axes]),
            "hh": rot_axis([a.shortest.high for a in rot_axes]),
        }
        undetermined = ~np.array(determined, dtype=bool)
    return {
        # A statement about the orientation only where some rotation is determined.
        "has_orientation": orientation is not None and bool(np.any(orientation.determined)),
        "mean_orientation": quaternion,
        "orientation_covariance": rot_cov,
        "orientation_standard_uncertainty": rot["u"],
        "orientation_expanded_uncertainty": rot["U"],
        "orientation_symmetric_low": rot["sl"],
        "orientation_symmetric_high": rot["sh"],
        "orientation_shortest_low": rot["hl"],
        "orientation_shortest_high": rot["hh"],
        "orientation_undetermined": undetermined,
        "pose_covariance": pose_cov,
    }


def pose_uncertainty_to_msg(
    pose: PoseUncertainty,
    *,
    stamp_ns: int,
    frame_id: str,
    joint_names: Sequence[str],
    coverage_probability: float,
    trials: int,
    adaptive_converged: bool,
    sources: Sequence[str],
) -> Msg:
    """Convert one test configuration's :class:`PoseUncertainty` to a message.

    Parameters
    ----------
    pose : PoseUncertainty
    stamp_ns : int
        Header stamp [ns since the epoch].
    frame_id : str
        Robot base frame of the positions.
    joint_names : sequence of str, length n_joints
        Names of ``pose.joint_positions``.
    coverage_probability : float
        p of the intervals.
    trials : int
        Number of Monte Carlo trials.
    adaptive_converged : bool
    sources : sequence of str
        Enabled uncertainty sources.

    Raises
    ------
    InputError
        `joint_names` of the wrong length.
    """
    if len(joint_names) != pose.joint_positions.size:
        msg = f"{len(joint_names)} joint names for {pose.joint_positions.size} joint positions"
        raise InputError(msg)
    axes = pose.axes

    def per_axis(values: list[float | None]) -> NDArray[np.float64]:
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)

    types = robocal_typestore().types
    return types[POSE_UNCERTAINTY](
        **_orientation_fields(pose, types),
        header=_header(stamp_ns, frame_id),
        joint_names=[str(n) for n in joint_names],
        joint_positions=_f64(pose.joint_positions),
        mean=_point(pose.mean),
        covariance=_f64(pose.covariance),
        standard_uncertainty=per_axis([a.standard_uncertainty for a in axes]),
        expanded_uncertainty=per_axis([a.expanded_uncertainty for a in axes]),
        coverage_factor=per_axis([a.coverage_factor for a in axes]),
        coverage_probability=float(coverage_probability),
        symmetric_low=per_axis([a.probabilistically_symmetric.low for a in axes]),
        symmetric_high=per_axis([a.probabilistically_symmetric.high for a in axes]),
        shortest_low=per_axis([a.shortest.low for a in axes]),
        shortest_high=per_axis([a.shortest.high for a in axes]),
        trials=int(trials),
        adaptive_converged=bool(adaptive_converged),
        sources=[str(s) for s in sources],
    )


def uncertainty_to_msgs(
    uncertainty: CalibrationUncertainty, *, stamp_ns: int, frame_id: str | None = None
) -> list[Msg]:
    """One ``PoseUncertainty`` message per test configuration of `uncertainty`.

    `frame_id` defaults to the calibrated model's ``base_frame_id``.
    """
    model = uncertainty.calibration.model
    return [
        pose_uncertainty_to_msg(
            pose,
            stamp_ns=stamp_ns,
            frame_id=model.base_frame_id if frame_id is None else frame_id,
            joint_names=model.joint_names,
            coverage_probability=uncertainty.coverage_probability,
            trials=uncertainty.n_trials,
            adaptive_converged=uncertainty.converged,
            sources=uncertainty.settings.sources,
        )
        for pose in uncertainty.poses
    ]
