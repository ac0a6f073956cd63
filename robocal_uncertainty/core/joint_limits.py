"""Joint readings against the robot's joint limits, with a hint for degrees typed as radians."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import InputError

__all__ = ["DEGREES_HINT", "check_joint_limits"]

DEGREES_HINT = "the values look like degrees given as radians"
"""Default hint added when a configuration fits the limits once read as degrees."""

_TOLERANCE_RAD = 1e-9
"""Slack on each limit for rounding (e.g. limits written in degrees, readings in radians); the
same number in m for a prismatic joint."""


def check_joint_limits(
    model: RobotModel,
    joint_positions: ArrayLike,
    *,
    what: str = "configuration",
    degrees_hint: str | None = DEGREES_HINT,
) -> None:
    """Raise if any joint value lies outside the model's joint limits.

    Parameters
    ----------
    model : RobotModel
        Supplies joint names and ``joint_limits`` [rad; m for its prismatic joints].
    joint_positions : array_like, shape (n_joints,) or (n, n_joints) [rad; m for prismatic joints]
        Configurations, columns in the order of ``model.joint_names``.
    what : str
        What a row is, for the message: row ``i`` is called ``"{what} {i + 1} of {n}"``
        (e.g. ``"campaign pose"``, ``"--joints configuration"``).
    degrees_hint : str or None
        Added to the message when the offending configuration is outside the limits in
        radians but entirely inside them when its values are read as degrees (converted
        with pi/180); None never adds a hint (e.g. when the values were already
        converted from degrees).

    Raises
    ------
    InputError
        One line naming the first offending configuration, the joint, its value (rad and
        deg; m and mm for a prismatic joint), the limits (deg; mm), the number of further
        offending values and, where the rule above applies, `degrees_hint`.
    """
    q = np.atleast_2d(np.asarray(joint_positions, dtype=np.float64))
    if q.ndim != 2 or q.shape[1] != model.n_joints:
        msg = f"{what}: expected {model.n_joints} joint values per configuration, got shape {q.shape}"
        raise InputError(msg)
    lo = model.joint_limits[:, 0] - _TOLERANCE_RAD
    hi = model.joint_limits[:, 1] + _TOLERANCE_RAD
    outside = ~((q >= lo) & (q <= hi))  # NaN counts as outside
    if not outside.any():
        return
    row, col = (int(i) for i in np.argwhere(outside)[0])
    value = float(q[row, col])
    prismatic = np.array(model.prismatic, dtype=bool)
    if prismatic[col]:
        low_mm, high_mm = model.joint_limits[col] * 1e3
        msg = (
            f"{what} {row + 1} of {q.shape[0]}: prismatic joint {model.joint_names[col]} = {value:.6g} m "
            f"({value * 1e3:.6g} mm) is outside its limits [{low_mm:.6g}, {high_mm:.6g}] mm"
        )
    else:
        low_deg, high_deg = np.degrees(model.joint_limits[col])
        msg = (
            f"{what} {row + 1} of {q.shape[0]}: joint {model.joint_names[col]} = {value:.6g} rad "
            f"({np.degrees(value):.6g} deg) is outside its limits [{low_deg:.6g}, {high_deg:.6g}] deg"
        )
    more = int(outside.sum()) - 1
    if more:
        msg += f" ({more} more value{'s' if more > 1 else ''} outside the limits)"
    # Degrees typed as radians: only the revolute readings are converted (a prismatic one is in m).
    as_degrees = np.where(prismatic, q[row], np.radians(q[row]))
    if degrees_hint and not prismatic[col] and bool(((as_degrees >= lo) & (as_degrees <= hi)).all()):
        msg += f"; {degrees_hint}"
    raise InputError(msg)
