"""The tracker move between two sessions' registrations, with its first-order uncertainty.

A check re-registers the new session's tracker pose; set against the calibration session's
registration it says where the tracker was moved, which helps tell a moved tracker from a
changed robot when a check fails.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.core.session import TrackerMove

__all__ = ["tracker_move"]

Array = NDArray[np.float64]


def _tracker_pose(registration: Array) -> tuple[Array, Array]:
    """Tracker position [m] and orientation matrix in the robot base frame from world_T_base."""
    r_wb = rpy_to_matrix(registration[3:6])
    r_bw = r_wb.T
    return -r_bw @ registration[:3], r_bw


def _move_vector(new: Array, old: Array) -> Array:
    t_new, r_new = _tracker_pose(new)
    t_old, r_old = _tracker_pose(old)
    return np.concatenate((t_new - t_old, rotation_log(r_new @ r_old.T)))


def tracker_move(new: Array, new_cov: Array, old: Array, old_cov: Array) -> TrackerMove:
    """The tracker move between two registrations with its first-order uncertainty.

    Parameters
    ----------
    new, old : ndarray, shape (6,) [m, rad]
        ``world_T_base`` (x, y, z, roll, pitch, yaw) of the two sessions.
    new_cov, old_cov : ndarray, shape (6, 6)
        Their covariances (independent of each other).
    """
    v = _move_vector(new, old)
    jac_new = np.empty((6, 6))
    jac_old = np.empty((6, 6))
    for k in range(6):
        h = 1e-7
        e = np.zeros(6)
        e[k] = h
        jac_new[:, k] = (_move_vector(new + e, old) - _move_vector(new - e, old)) / (2 * h)
        jac_old[:, k] = (_move_vector(new, old + e) - _move_vector(new, old - e)) / (2 * h)
    cov = jac_new @ new_cov @ jac_new.T + jac_old @ old_cov @ jac_old.T
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))

    def norm_std(vec: Array, block: Array) -> tuple[float, float]:
        n = float(np.linalg.norm(vec))
        if n == 0.0:
            return 0.0, float(np.sqrt(np.trace(block)))
        g = vec / n
        return n, float(np.sqrt(max(float(g @ block @ g), 0.0)))

    distance, distance_std = norm_std(v[:3], cov[:3, :3])
    angle, angle_std = norm_std(v[3:], cov[3:, 3:])
    return TrackerMove(
        translation=v[:3],
        translation_std=std[:3],
        distance=distance,
        distance_std=distance_std,
        rotation=v[3:],
        rotation_std=std[3:],
        angle=angle,
        angle_std=angle_std,
        covariance=cov,
    )
