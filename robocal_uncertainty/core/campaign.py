"""The measurement campaign: joint readings paired with measured values, one pair per pose.

The values are tracker points by default; the campaign's ``measurement`` type says what they
are (see :mod:`robocal_uncertainty.core.measurement`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.errors import InputError

__all__ = ["Campaign", "PointFrame"]

PointFrame = Literal["base", "tracker"]
"""``base``: points are expressed in the robot base frame (base transform known, identity).
``tracker``: points are in the measurement (laser-tracker) frame; the base transform is
unknown and identified with the kinematic parameters."""


def _finite_array(name: str, value: object, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != len(shape) or any(want is not None and got != want for got, want in zip(array.shape, shape)):
        expected = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        msg = f"{name} must have shape {expected}, got {array.shape}"
        raise InputError(msg)
    bad = ~np.isfinite(array)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        msg = f"{name} contains NaN or inf (first at pose index {row})"
        raise InputError(msg)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class Campaign:
    """Joint readings and measured values (tool points by default) of one calibration campaign.

    Parameters
    ----------
    joint_names : tuple of str, length n_joints
        Names of the joints in the order of the columns of `joint_positions`.
    joint_positions : ndarray, shape (n_poses, n_joints) [rad]
        Joint readings (encoder values) at each measured pose.
    points : ndarray, shape (n_poses, measurement.value_size) [m for points]
        Measured value at each pose (the tool point for the default point measurement), in
        the frame named by `frame`.
    frame : {"base", "tracker"}
        Whether `points` are in the robot base frame or in the tracker frame.
    frame_id : str
        Name of the frame of `points` (``header.frame_id`` in bags).
    point_std : ndarray, shape (n_poses, measurement.dimension) [m for points], optional
        Standard deviation of each measured component, when the instrument reports one.
    stamps_ns : ndarray of int64, shape (n_poses,), optional
        Acquisition time of each pose (ns since the epoch).
    metadata : dict
        Free-form provenance (source file, simulator seed, ...). JSON-serialisable.
    measurement : MeasurementType
        What `points` hold and how they enter the identification; unweighted tool points
        (:data:`~robocal_uncertainty.core.measurement.POINT`) by default.
    """

    joint_names: tuple[str, ...]
    joint_positions: NDArray[np.float64]
    points: NDArray[np.float64]
    frame: PointFrame = "base"
    frame_id: str = "base_link"
    point_std: NDArray[np.float64] | None = None
    stamps_ns: NDArray[np.int64] | None = None
    metadata: dict[str, object] = field(default_factory=dict)
    measurement: MeasurementType = POINT

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        if len(set(names)) != len(names) or not names:
            msg = f"joint_names must be unique and non-empty, got {names}"
            raise InputError(msg)
        object.__setattr__(self, "joint_names", names)
        q = _finite_array("joint_positions", self.joint_positions, (None, len(names)))
        n = q.shape[0]
        if n == 0:
            raise InputError("campaign has no poses")
        object.__setattr__(self, "joint_positions", q)
        if not isinstance(self.measurement, MeasurementType):
            msg = f"measurement must be a MeasurementType, got {type(self.measurement).__name__}"
            raise InputError(msg)
        size, dim = self.measurement.value_size, self.measurement.dimension
        object.__setattr__(self, "points", _finite_array("points", self.points, (n, size)))
        self.measurement.check_values(self.points)
        if self.frame not in ("base", "tracker"):
            msg = f"frame must be 'base' or 'tracker', got {self.frame!r}"
            raise InputError(msg)
        if self.point_std is not None:
            std = _finite_array("point_std", self.point_std, (n, dim))
            if (std < 0).any():
                raise InputError("point_std must be non-negative")
            object.__setattr__(self, "point_std", std)
        if self.stamps_ns is not None:
            stamps = np.asarray(self.stamps_ns, dtype=np.int64)
            if stamps.shape != (n,):
                msg = f"stamps_ns must have shape ({n},), got {stamps.shape}"
                raise InputError(msg)
            stamps.setflags(write=False)
            object.__setattr__(self, "stamps_ns", stamps)

    @property
    def n_poses(self) -> int:
        """Number of measured poses."""
        return int(self.joint_positions.shape[0])

    def subset(self, indices: NDArray[np.intp] | list[int] | slice) -> Campaign:
        """Return the campaign restricted to the poses `indices` (order kept as given)."""
        idx = np.arange(self.n_poses)[indices]
        return Campaign(
            joint_names=self.joint_names,
            joint_positions=self.joint_positions[idx],
            points=self.points[idx],
            frame=self.frame,
            frame_id=self.frame_id,
            point_std=None if self.point_std is None else self.point_std[idx],
            stamps_ns=None if self.stamps_ns is None else self.stamps_ns[idx],
            metadata=dict(self.metadata),
            measurement=self.measurement,
        )

    def reorder_joints(self, joint_names: tuple[str, ...]) -> Campaign:
        """Return the campaign with joint columns in the order of `joint_names`.

        Raises
        ------
        InputError
            If the campaign's joints are not exactly the names asked for.
        """
        if set(joint_names) != set(self.joint_names) or len(joint_names) != len(self.joint_names):
            missing = sorted(set(joint_names) - set(self.joint_names))
            extra = sorted(set(self.joint_names) - set(joint_names))
            msg = (
                f"campaign joints {list(self.joint_names)} do not match the robot's "
                f"{list(joint_names)} (missing {missing}, unknown {extra})"
            )
            raise InputError(msg)
        if tuple(joint_names) == self.joint_names:
            return self
        order = [self.joint_names.index(n) for n in joint_names]
        return Campaign(
            joint_names=tuple(joint_names),
            joint_positions=self.joint_positions[:, order],
            points=self.points,
            frame=self.frame,
            frame_id=self.frame_id,
            point_std=self.point_std,
            stamps_ns=self.stamps_ns,
            metadata=dict(self.metadata),
            measurement=self.measurement,
        )
