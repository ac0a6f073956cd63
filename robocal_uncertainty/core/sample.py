"""One calibration pose as the static-pose collector emits it (a plain value type: numpy only).

It sits in ``core`` because every layer above uses it: the collector in ``pipeline`` makes
it, ``bagio.messages`` converts it to and from the ``CalibrationSample`` message.
"""

from __future__ import annotations

import numbers
import operator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import InputError

__all__ = ["CalibrationSample"]


def _array(name: str, value: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    array = np.array(value, dtype=np.float64)
    if array.shape != shape:
        msg = f"{name} must have shape {shape}, got {array.shape}"
        raise InputError(msg)
    if not np.isfinite(array).all():
        msg = f"{name} contains NaN or inf"
        raise InputError(msg)
    array.setflags(write=False)
    return array


def _integer(name: str, value: object) -> int:
    """`value` as an int when it is an integral number (not a bool), or a one-line InputError."""
    if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
        return operator.index(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    msg = f"{name} must be an integer, got {value!r}"
    raise InputError(msg)


@dataclass(frozen=True, eq=False)
class CalibrationSample:
    """Joint readings and tracker points averaged over one static dwell of the arm.

    Parameters
    ----------
    stamp_ns : int
        Middle of the averaged window [ns since the epoch].
    frame_id : str
        Frame of `point` (the tracker's ``header.frame_id``).
    joint_names : tuple of str, length n_joints
        Joint names, in the order of `joint_positions` and `joint_position_std`.
    joint_positions : ndarray, shape (n_joints,) [rad]
        Mean joint reading over the window.
    joint_position_std : ndarray, shape (n_joints,) [rad]
        Standard deviation (ddof=1) of the individual readings over the window.
    point : ndarray, shape (3,) [m]
        Mean measured point over the window, in `frame_id`.
    point_covariance : ndarray, shape (3, 3) [m^2]
        Covariance of the MEAN point: scatter covariance (ddof=1) of the individual
        points divided by `tracker_point_count`.
    joint_state_count : int
        Number of joint states averaged.
    tracker_point_count : int
        Number of tracker points averaged.
    orientation : ndarray, shape (4,), optional
        6-DOF trackers: chordal L2 mean of the measured orientations over the window, unit
        quaternion ``(x, y, z, w)`` in `frame_id`; None for points.
    orientation_covariance : ndarray, shape (3, 3) [rad^2], optional
        Covariance of the MEAN orientation: scatter covariance (ddof=1) of the individual
        rotation deviations ``log(R_i R_mean^T)`` (about the fixed x, y, z axes) divided by
        the number of poses; given with `orientation`.

    Raises
    ------
    InputError
        Wrong shapes, NaN/inf, negative std, repeated joint names or counts below 1.
    """

    stamp_ns: int
    frame_id: str
    joint_names: tuple[str, ...]
    joint_positions: NDArray[np.float64]
    joint_position_std: NDArray[np.float64]
    point: NDArray[np.float64]
    point_covariance: NDArray[np.float64]
    joint_state_count: int
    tracker_point_count: int
    orientation: NDArray[np.float64] | None = None
    orientation_covariance: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        if not names or len(set(names)) != len(names):
            msg = f"joint_names must be unique and non-empty, got {list(names)}"
            raise InputError(msg)
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "stamp_ns", _integer("stamp_ns", self.stamp_ns))
        n = len(names)
        q = _array("joint_positions", self.joint_positions, (n,))
        q_std = _array("joint_position_std", self.joint_position_std, (n,))
        if (q_std < 0).any():
            raise InputError("joint_position_std must be non-negative")
        object.__setattr__(self, "joint_positions", q)
        object.__setattr__(self, "joint_position_std", q_std)
        object.__setattr__(self, "point", _array("point", self.point, (3,)))
        cov = _array("point_covariance", self.point_covariance, (3, 3))
        if (np.diag(cov) < 0).any():
            raise InputError("point_covariance has a negative variance")
        object.__setattr__(self, "point_covariance", cov)
        if (self.orientation is None) != (self.orientation_covariance is None):
            raise InputError("orientation and orientation_covariance must be given together")
        if self.orientation is not None and self.orientation_covariance is not None:
            quat = _array("orientation", self.orientation, (4,))
            if abs(float(np.linalg.norm(quat)) - 1.0) > 1e-6:
                msg = f"orientation is not a unit quaternion: norm {float(np.linalg.norm(quat)):.6g}"
                raise InputError(msg)
            object.__setattr__(self, "orientation", quat)
            rot_cov = _array("orientation_covariance", self.orientation_covariance, (3, 3))
            if (np.diag(rot_cov) < 0).any():
                raise InputError("orientation_covariance has a negative variance")
            object.__setattr__(self, "orientation_covariance", rot_cov)
        for name in ("joint_state_count", "tracker_point_count"):
            value = _integer(name, getattr(self, name))
            if value < 1:
                msg = f"{name} must be a positive integer, got {value!r}"
                raise InputError(msg)
            object.__setattr__(self, name, value)

    def __eq__(self, other: object) -> bool:
        """Exact equality of every field (arrays element by element)."""
        if not isinstance(other, CalibrationSample):
            return NotImplemented
        return (self.stamp_ns, self.frame_id, self.joint_names, self.joint_state_count, self.tracker_point_count) == (
            other.stamp_ns,
            other.frame_id,
            other.joint_names,
            other.joint_state_count,
            other.tracker_point_count,
        ) and all(
            np.array_equal(getattr(self, name), getattr(other, name))
            for name in (
                "joint_positions",
                "joint_position_std",
                "point",
                "point_covariance",
                "orientation",
                "orientation_covariance",
            )
        )

    __hash__ = None  # type: ignore[assignment]  # holds arrays: not hashable

    @property
    def point_std(self) -> NDArray[np.float64]:
        """Standard uncertainty of each coordinate of the mean point, shape (3,) [m]."""
        return np.sqrt(np.diag(self.point_covariance))
