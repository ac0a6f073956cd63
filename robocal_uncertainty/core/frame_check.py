"""Has the measurement frame moved? A rigid fit of predicted to measured positions.

A calibration predicts where the tool will be in the measurement frame of its campaign. A
second series measured with the instrument set up elsewhere (another day, the tracker moved,
the same frame name) is predicted in the old frame: every point is off by one rigid
transform. :func:`compare_frames` fits that transform (``measured ~ R predicted + t``,
Kabsch, no scale) and says whether it moves the measured points by more than the stated
uncertainty allows, so a validation, a verification or any comparison with a new series can
refuse instead of printing errors of metres as if they were the calibration's.

The criterion is the displacement the fitted transform makes at the measured points (RMS
over the points of ``|R p + t - p|``), against a limit the caller states (e.g. the expanded
3-D uncertainty of a predicted point, or the calibration's residual RMS, whichever is
larger): a move smaller than that cannot be told from the model error, a larger one
dominates every comparison. It is a move only when the rigid fit also explains the error
(the RMS error after the fit at most :data:`EXPLAINED_RATIO` of the RMS error before it):
errors the fit does not explain (another robot, a wrong model, an over-confident statement)
are no frame move and are left for the comparison itself to show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import fit_rigid_base
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.errors import InputError

__all__ = ["EXPLAINED_RATIO", "FrameComparison", "compare_frames"]

Array = NDArray[np.float64]
EXPLAINED_RATIO = 0.5
"""A rigid transform is a frame move only when it leaves at most this fraction of the RMS error."""


@dataclass(frozen=True)
class FrameComparison:
    """Rigid transform between predicted and measured positions, and whether it is a move.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        ``R`` of ``measured ~ R predicted + t``.
    translation : ndarray, shape (3,) [m]
        ``t`` of the same; its size depends on the frame's origin, so the move is stated by
        :attr:`shift` (at the points' centroid) instead.
    shift : float [m]
        How far the fitted transform moves the centroid of the predicted points.
    angle : float [rad]
        Rotation angle of ``R``.
    displacement_rms : float [m]
        RMS over the points of ``|R p + t - p|``: how much the transform moves the points.
    limit : float [m]
        The caller's stated uncertainty the displacement is compared with.
    rms_before, rms_after : float [m]
        RMS of the 3-D difference measured - predicted before and after the fit.
    n_points : int
    """

    rotation: Array
    translation: Array
    shift: float
    angle: float
    displacement_rms: float
    limit: float
    rms_before: float
    rms_after: float
    n_points: int

    @property
    def moved(self) -> bool:
        """Whether the frame moved by more than the stated uncertainty (and the move explains the error)."""
        return self.displacement_rms > self.limit and self.rms_after <= EXPLAINED_RATIO * self.rms_before

    def describe(self) -> str:
        """One line: the move in mm and mrad, and what it is compared with."""
        return (
            f"the measured points sit {self.shift * 1e3:.2f} mm and {self.angle * 1e3:.2f} mrad from the "
            f"predicted ones (rigid fit over {self.n_points} points: RMS displacement "
            f"{self.displacement_rms * 1e3:.3f} mm against the stated {self.limit * 1e3:.3f} mm; "
            f"RMS error {self.rms_before * 1e3:.3f} mm before the fit, {self.rms_after * 1e3:.3f} mm after)"
        )


def compare_frames(predicted: Array, measured: Array, limit: float) -> FrameComparison:
    """Fit ``measured ~ R predicted + t`` and compare the displacement with `limit`.

    Parameters
    ----------
    predicted : ndarray, shape (n, 3) [m]
        Positions the calibration predicts, in the frame it was calibrated in.
    measured : ndarray, shape (n, 3) [m]
        The same positions measured, in the frame of the series under test.
    limit : float [m]
        Stated uncertainty of the displacement (> 0): a larger RMS displacement is a move.

    Returns
    -------
    FrameComparison

    Raises
    ------
    InputError
        Mismatched shapes, fewer than 3 points, non-finite values or a limit that is not
        positive.
    """
    p = np.asarray(predicted, dtype=np.float64)
    m = np.asarray(measured, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape != m.shape:
        msg = f"frame comparison needs two (n, 3) arrays of positions, got {p.shape} and {m.shape}"
        raise InputError(msg)
    if p.shape[0] < 3:
        msg = f"frame comparison needs at least 3 points, got {p.shape[0]}"
        raise InputError(msg)
    if not (np.isfinite(p).all() and np.isfinite(m).all()):
        raise InputError("frame comparison: positions must be finite")
    if not (np.isfinite(limit) and limit > 0):
        msg = f"frame comparison: the stated limit must be a positive length, got {limit!r}"
        raise InputError(msg)
    xyz, rpy = fit_rigid_base(p, m)
    rot = rpy_to_matrix(rpy)
    moved = p @ rot.T + xyz
    centroid = p.mean(axis=0)
    return FrameComparison(
        rotation=rot,
        translation=xyz,
        shift=float(np.linalg.norm(rot @ centroid + xyz - centroid)),
        angle=float(np.linalg.norm(rotation_log(rot))),
        displacement_rms=float(np.sqrt(np.mean(np.sum((moved - p) ** 2, axis=1)))),
        limit=float(limit),
        rms_before=float(np.sqrt(np.mean(np.sum((m - p) ** 2, axis=1)))),
        rms_after=float(np.sqrt(np.mean(np.sum((m - moved) ** 2, axis=1)))),
        n_points=int(p.shape[0]),
    )
