"""The orientation half of verifying a 6-DOF calibration: the tool frame's rotation error level.

A 6-DOF calibration (positions and T-Mac orientations) states the tool frame's orientation too,
so a check of a later session tests both. The positions go through the point test
(:func:`~.verification.verify_session`, against the point record of the same poses); the
orientations are tested here the same way the positions' error level is: the check is
re-registered (tracker pose, with ``retool`` also the tool point and the tool rotation: a
remounted probe turns as well as moves) by Gauss-Newton on positions and orientations, each
kind's rows scaled by its own error level (two passes), and the mean square rotation error per
component left after it, over the equations the re-registration keeps (``sum(1 - h)`` of the
rotation rows, ``h`` their leverage), is F-tested against the calibration session's own level
on held-out poses (:func:`orientation_validated_level`: the same repeated 5-fold splits as the
positions', each fold predicted by a 6-DOF calibration of the others and re-registered as a
check). Measured, not stated: the orientation residuals of the UR10 series are 1.1 mrad, many
times what the T-Mac's stated noise explains.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import fit_rigid_base, identify
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import BASE_NAMES, TOOL_NAMES, LevelTest, ToleranceCheck, ValidatedLevel
from robocal_uncertainty.errors import IdentifiabilityError, InputError
from robocal_uncertainty.uncertainty.sessions.level import level_test, tolerance_check

__all__ = [
    "ROTATION_NAMES",
    "OrientationCheck",
    "orientation_check",
    "orientation_level",
    "orientation_validated_level",
]

Array = NDArray[np.float64]
ROTATION_NAMES = ("tool.rx", "tool.ry", "tool.rz")
_FIRST_SCALE = np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3])  # first guess of the levels [m, rad]


@dataclass(frozen=True)
class OrientationCheck:
    """A check's tool-orientation error level against the calibration session's.

    Attributes
    ----------
    consistent : bool
        ``level_test.p_value >= significance``.
    significance : float
        The level this half was tested at (half the check's: positions and orientations
        together keep the check's false-alarm rate, Bonferroni).
    level : float [rad^2]
        Mean square rotation error per component after the re-registration.
    level_dof : float
        The rotation equations it is taken over (``sum(1 - h)``).
    rms : float [rad]
        RMS over the poses of the rotation residual's norm.
    level_test : LevelTest
        The F test against the validated orientation level; its ratio is "orientation errors
        1.3x the calibration session's".
    tolerance : ToleranceCheck
        The same level against what the orientation statement tolerates (three ways).
    reregistered : tuple of str
        What the check re-registered.
    """

    consistent: bool
    significance: float
    level: float
    level_dof: float
    rms: float
    level_test: LevelTest
    tolerance: ToleranceCheck
    reregistered: tuple[str, ...]

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (``verify.json``'s ``orientation``)."""
        t = self.level_test
        return {
            "consistent": self.consistent,
            "significance": self.significance,
            "level_rad2": self.level,
            "level_dof": self.level_dof,
            "rms_rad": self.rms,
            "test": t.test,
            "p_value": t.p_value,
            "check_dof": t.check_dof,
            "reference_dof": t.reference_dof,
            "error_ratio": t.ratio,
            "error_ratio_interval_95": list(t.ratio_interval),
            "tolerance": self.tolerance.to_dict(),
            "reregistered": list(self.reregistered),
        }


def orientation_level(model: RobotModel, campaign: Campaign, *, retool: bool) -> tuple[float, float, float, Array]:
    """Re-register a 6-DOF `campaign` on the calibrated `model` (with tool rotation) and measure it.

    Returns
    -------
    level : float [rad^2]
        ``sum(r_rot^2) / sum(1 - h_rot)``.
    kept : float
        ``sum(1 - h_rot)``: the rotation equations the re-registration keeps.
    rms : float [rad]
        RMS of the rotation residual's norm.
    z : ndarray, shape (3 n,)
        The rotation residual components over ``sqrt((1 - h) level)`` (for the kurtosis).

    Raises
    ------
    InputError
        The campaign holds no orientations or the model no tool rotation.
    IdentifiabilityError
        Too few poses to re-register and leave rotation equations.
    """
    meas = campaign.measurement
    if not meas.measures_orientation or meas.dimension != 6:
        msg = f"check campaign holds no orientations ({meas.quantity}): the orientation half needs a 6-DOF check"
        raise InputError(msg)
    if not model.tool_rotation:
        raise InputError("the calibration has no tool rotation: it states no orientations")
    layout = model.layout
    campaign = campaign.reorder_joints(model.joint_names)
    q, y = campaign.joint_positions, campaign.points
    names = [*BASE_NAMES, *((*TOOL_NAMES, *ROTATION_NAMES) if retool else ())]
    if 6 * campaign.n_poses <= len(names) + 3:
        msg = f"{campaign.n_poses} 6-DOF poses cannot re-register {len(names)} parameters and test the orientations"
        raise IdentifiabilityError(msg)
    free = np.array([layout.names.index(n) for n in names], dtype=np.intp)
    p = model.parameter_vector()
    b0 = layout.base_index
    p_kin = p.copy()
    p_kin[b0 : b0 + 6] = 0.0
    xyz, rpy = fit_rigid_base(forward_points(layout, p_kin, q), np.asarray(meas.positions(y), dtype=np.float64))
    p[b0 : b0 + 3], p[b0 + 3 : b0 + 6] = xyz, rpy
    scale = _FIRST_SCALE.copy()
    levels = scale**2
    kept = np.ones(2)
    for _ in range(2):  # the rows' scales from the previous pass's levels
        for _ in range(20):
            pred, jac = meas.predict_and_jacobian(layout, p, q)
            a = (jac[:, :, free] / scale[None, :, None]).reshape(-1, free.size)
            step = np.linalg.lstsq(a, (meas.residual(y, pred) / scale).reshape(-1), rcond=None)[0]
            p[free] += step
            if np.max(np.abs(step)) < 1e-12:
                break
        pred, jac = meas.predict_and_jacobian(layout, p, q)
        r = meas.residual(y, pred)
        a = (jac[:, :, free] / scale[None, :, None]).reshape(-1, free.size)
        h = np.einsum("ij,jk,ik->i", a, np.linalg.pinv(a.T @ a), a).reshape(-1, 6)
        for b, block in enumerate((slice(0, 3), slice(3, 6))):
            kept[b] = float(np.sum(1.0 - h[:, block]))
            levels[block] = float(np.sum(r[:, block] ** 2)) / kept[b]
        scale = np.sqrt(np.maximum(levels, 1e-30))
    rot = r[:, 3:]
    z = rot.reshape(-1) / np.sqrt(np.clip(1.0 - h[:, 3:].reshape(-1), 1e-12, None) * levels[3])
    rms = float(np.sqrt(np.mean(np.sum(rot**2, axis=1))))
    return float(levels[3]), float(kept[1]), rms, np.asarray(z, dtype=np.float64)


def orientation_validated_level(
    model: RobotModel,
    campaign: Campaign,
    *,
    lambda_: str | float = "auto",
    retool: bool = True,
    folds: int = 5,
    repeats: int = 4,
    seed: int = 0,
    weight_std: tuple[float, ...] | None = None,
) -> ValidatedLevel:
    """The 6-DOF calibration session's orientation error level on its own held-out poses.

    As :func:`~.validated_level.validated_level` for the positions (the same fold seeds): each
    fold of `repeats` random splits into `folds` is predicted by a 6-DOF calibration of the
    others and re-registered as a check (:func:`orientation_level`); the levels pool over their
    kept equations, the degrees of freedom are one split's, the dispersion is the fold levels'
    relative variance over ``2 / nu``.

    Parameters
    ----------
    model : RobotModel
        Nominal model with the tool rotation.
    campaign : Campaign
        The 6-DOF calibration campaign.
    weight_std : tuple of 6 float [m, m, m, rad, rad, rad], optional
        The full calibration's weights (its variance components): each fold is calibrated with
        them as stated, one fit instead of re-estimating them (ten fits) on fewer poses.
        None: every fold estimates its own.
    """
    n = campaign.n_poses
    weighting: Literal["stated", "variance_components"] = "variance_components"
    if weight_std is not None and isinstance(campaign.measurement, PoseMeasurement):
        meas = dataclasses.replace(
            campaign.measurement,
            position_std=(float(weight_std[0]), float(weight_std[1]), float(weight_std[2])),
            rotation_std=(float(weight_std[3]), float(weight_std[4]), float(weight_std[5])),
            weight_std=None,
        )  # fmt: skip
        campaign = dataclasses.replace(campaign, measurement=meas)
        weighting = "stated"
    rng = np.random.default_rng(seed)
    levels, kepts, zs = [], [], []
    for _ in range(repeats):
        order = rng.permutation(n)
        for part in np.array_split(order, folds):
            train = campaign.subset(np.sort(np.setdiff1d(order, part)))
            cal = identify(model, train, lambda_=lambda_, accept_unconverged=True, weighting=weighting)
            level, kept, _, z = orientation_level(cal.model, campaign.subset(np.sort(part)), retool=retool)
            levels.append(level)
            kepts.append(kept)
            zs.append(z)
    lv, kp = np.array(levels), np.array(kepts)
    pooled = float(np.sum(lv * kp) / np.sum(kp))
    z_all = np.concatenate(zs)
    dispersion = None
    if lv.size > 1 and pooled > 0.0:
        observed = float(np.sum((lv / pooled - 1.0) ** 2)) / (lv.size - 1)
        dispersion = observed / float(np.mean(2.0 / kp))
    return ValidatedLevel(
        level=pooled,
        dof=float(np.sum(kp)) / repeats,
        kurtosis=float(np.mean(z_all**4) / np.mean(z_all**2) ** 2),
        folds=folds,
        poses=n,
        seed=seed,
        repeats=repeats,
        dispersion=dispersion,
    )


def orientation_check(
    model: RobotModel, reference: ValidatedLevel, campaign: Campaign, *, retool: bool, significance: float
) -> OrientationCheck:
    """Test a 6-DOF check's orientations against the calibration's validated orientation level.

    Parameters
    ----------
    model : RobotModel
        The calibrated model with its tool rotation (the calibration file applied).
    reference : ValidatedLevel
        The calibration's orientation level (:func:`orientation_validated_level`) [rad^2].
    campaign : Campaign
        The 6-DOF check (positions and orientations).
    retool : bool
        The probe was remounted: re-register the tool point and the tool rotation.
    significance : float
        Level of this half's test.
    """
    level, kept, rms, _ = orientation_level(model, campaign, retool=retool)
    outcome = level_test(level, kept, reference)
    names = (*BASE_NAMES, *((*TOOL_NAMES, *ROTATION_NAMES) if retool else ()))
    # The tolerance's pose count: a 6-DOF pose gives 3 rotation equations, the re-registration
    # takes about its share of them (half of the parameters: positions and rotations share it).
    tolerance = tolerance_check(level, kept, reference, reregistered=len(names) // 2)
    return OrientationCheck(
        consistent=outcome.p_value >= significance,
        significance=significance,
        level=level,
        level_dof=kept,
        rms=rms,
        level_test=outcome,
        tolerance=tolerance,
        reregistered=names,
    )
