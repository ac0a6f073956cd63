"""Pair tracker points with joint readings by header stamp.

Rule: every point is paired with the joint reading whose header stamp equals the point's
stamp. When there is none and ``tolerance_ns > 0``, it is paired with the joint reading
nearest in time if that one is at most ``tolerance_ns`` away (on a tie, the earlier one).
A joint reading may serve several points. Points left without a partner are reported
(their indices), never silently paired further away.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import InputError

__all__ = ["pair_by_stamp"]


def pair_by_stamp(
    joint_stamps_ns: NDArray[np.int64],
    point_stamps_ns: NDArray[np.int64],
    tolerance_ns: int = 0,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Return, for each pairable point, its index and the index of its joint reading.

    Parameters
    ----------
    joint_stamps_ns : ndarray of int64, shape (n_joint_msgs,) [ns]
        Header stamps of the joint readings, unique, any order.
    point_stamps_ns : ndarray of int64, shape (n_point_msgs,) [ns]
        Header stamps of the points, any order.
    tolerance_ns : int
        Largest stamp difference [ns] accepted when no exact match exists (0: exact only).

    Returns
    -------
    point_index : ndarray of intp, shape (n_pairs,)
        Indices into `point_stamps_ns` of the paired points, in increasing order.
    joint_index : ndarray of intp, shape (n_pairs,)
        Index into `joint_stamps_ns` of the partner of each paired point.

    Raises
    ------
    InputError
        If `tolerance_ns` is negative or joint stamps repeat.
    """
    if tolerance_ns < 0:
        msg = f"stamp tolerance must be >= 0 ns, got {tolerance_ns}"
        raise InputError(msg)
    joints = np.asarray(joint_stamps_ns, dtype=np.int64)
    points = np.asarray(point_stamps_ns, dtype=np.int64)
    if joints.size == 0 or points.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty.copy()
    order = np.argsort(joints, kind="stable")
    sorted_joints = joints[order]
    repeated = np.flatnonzero(np.diff(sorted_joints) == 0)
    if repeated.size:
        msg = f"several joint readings share the stamp {int(sorted_joints[repeated[0]])} ns"
        raise InputError(msg)
    right = np.searchsorted(sorted_joints, points, side="left").clip(0, joints.size - 1)
    left = (right - 1).clip(0, joints.size - 1)
    gap_right = np.abs(sorted_joints[right] - points)
    gap_left = np.abs(sorted_joints[left] - points)
    nearest = np.where(gap_left <= gap_right, left, right)
    gap = np.minimum(gap_left, gap_right)
    point_index = np.flatnonzero(gap <= tolerance_ns).astype(np.intp)
    return point_index, order[nearest[point_index]].astype(np.intp)
