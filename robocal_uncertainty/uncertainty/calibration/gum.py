"""First-order (GUM, JCGM 100) propagation of the smooth sources, and its JCGM 101 §8 check.

The identification is linearised at the calibration (x = H b, the weighted Tikhonov
solution), so each smooth source's additive batch fields have a sensitivity matrix; the
sources' distributions are the same objects the Monte Carlo draws from, so the GUM variance
and the trials come from one definition. Also the first-order Tikhonov shrinkage, a bias
the Monte Carlo cannot see because every trial is centred on the calibration.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian, forward_poses_and_jacobian
from robocal_uncertainty.core.measurement import joint_columns, row_weights, stack_jacobian
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.montecarlo.distributions import Distribution, IndependentNormal
from robocal_uncertainty.montecarlo.gum import GumResult, propagate_gum
from robocal_uncertainty.montecarlo.summary import Summary
from robocal_uncertainty.montecarlo.validation import validate_gum
from robocal_uncertainty.uncertainty.calibration.preparation import Prepared, prepare
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, GumPose
from robocal_uncertainty.uncertainty.model_error_draws import FieldNormal
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = [
    "field_sensitivities",
    "first_order_standard_uncertainty",
    "gum_poses",
    "regularisation_bias",
    "smooth_gum",
]

Array = NDArray[np.float64]


def field_sensitivities(prep: Prepared, *, angular: bool = False) -> tuple[dict[str, Array], Array]:
    """First-order sensitivity of the outputs to each additive batch field, and y = f(E[X]).

    Outputs are the tool position (x, y, z) at every test configuration or, with `angular`,
    the rotation deviation (rx, ry, rz) about the calibrated tool rotation (then y = 0),
    through the angular Jacobian of the tool; the identification is linearised at the
    calibration (x = H b). Model errors (the predictions field) move positions only.
    """
    problem = prep.problem
    layout = problem.layout
    est = problem.estimated
    calibration = prep.calibration
    trials = prep.trials
    q = prep.campaign.joint_positions
    measurement = problem.measurement
    n_poses = trials.points.shape[0]
    dim = N_AXES
    n_test, n_joints = prep.test_joints.shape
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, q)
    weights = row_weights(measurement, n_poses)
    # stack_jacobian already whitens the rows (W A): the weights must not enter twice.
    a_mat = stack_jacobian(measurement, jac, est) / problem.scale
    lam = calibration.lambda_
    # x = H b: the linearised (weighted) Tikhonov solution for the stacked residual b,
    # H = (A^T W^2 A + lam^2 P)^-1 A^T W^2.
    h = np.linalg.solve(a_mat.T @ a_mat + lam**2 * np.diag(problem.penalty_mask), a_mat.T)
    if weights is not None:
        h = h * weights[None, :]
    p_out = calibration.estimate.copy()
    b0 = layout.base_index
    if trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
    if angular:
        _, _, g6 = forward_poses_and_jacobian(layout, p_out, prep.test_joints)
        gy = np.ascontiguousarray(g6[:, 3:, :])
        y = np.zeros((n_test, dim))
    else:
        y, gy = forward_points_and_jacobian(layout, p_out, prep.test_joints)
    if trials.drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    n_out = dim * n_test
    s_points = gy[:, :, est].reshape(n_out, est.size) @ (h / problem.scale[:, None])
    theta_cols = joint_columns(layout)
    # A reading error dq shifts the prediction by J_q dq: for the fit, the measurement moved by -J_q dq.
    m_dim = measurement.dimension
    s_joints = -np.einsum("opc,pcj->opj", s_points.reshape(n_out, n_poses, m_dim), jac[..., theta_cols])
    s_test = np.zeros((n_test, dim, n_test, n_joints))
    # Model errors (the residual source) have the measurement's components: positions move
    # positions and, for 6-DOF measurements, rotations move rotations.
    s_pred = np.zeros((n_test, dim, n_test, m_dim))
    for i in range(n_test):
        s_test[i, :, i, :] = gy[i][:, theta_cols]
        if not angular:
            s_pred[i, :, i, :dim] = trials.output_rotation
        elif m_dim == 2 * dim:
            s_pred[i, :, i, dim:] = trials.output_rotation
    fields = {
        "points": s_points,
        "joints": s_joints.reshape(n_out, n_poses * n_joints),
        "test_joints": s_test.reshape(n_out, n_test * n_joints),
        "predictions": s_pred.reshape(n_out, n_test * m_dim),
    }
    return fields, y.reshape(n_out)


def smooth_gum(prep: Prepared, coverage: float, *, angular: bool = False, per_pose: bool = False) -> GumResult | None:
    """GUM (JCGM 100) propagation of the smooth sources' distributions; None if there is none.

    With `per_pose`, the covariance is propagated within each test configuration only (zero
    between them; every standard uncertainty the same to rounding): what a statement of
    thousands of configurations that reads each one's 3 x 3 block needs."""
    smooth = [src for src in prep.trials.sources if src.smooth and src.distribution is not None]
    if not smooth:
        return None
    fields, y0 = field_sensitivities(prep, angular=angular)
    inputs: dict[str, Distribution] = {}
    columns = []
    for src in smooth:
        block = np.hstack([fields[name] for name, _ in src.segments])
        if isinstance(src.distribution, FieldNormal):
            # The field's draws are F z with z standard normal: propagate z through S F, the
            # same factor the Monte Carlo draws with, never the dense covariance of the draws.
            inputs[src.name] = IndependentNormal(np.ones(src.distribution.whitened_size))
            block = src.distribution.whitened_sensitivities(block)
        elif src.distribution is not None:
            inputs[src.name] = src.distribution
        columns.append(block)
    sensitivities = np.hstack(columns)

    def estimate(x: Array) -> Array:
        # Zero-mean deviations: the GUM estimate is the calibrated model's prediction.
        return np.broadcast_to(y0, (x.shape[0], y0.size))

    return propagate_gum(
        estimate, inputs, coverage=coverage, sensitivities=sensitivities, output_blocks=N_AXES if per_pose else None
    )


def first_order_standard_uncertainty(
    model: RobotModel,
    campaign: Campaign,
    test_q: Array,
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    frame: str = "measurement",
) -> Array | None:
    """GUM (first-order) standard uncertainty of the tool position at `test_q`, as `evaluate` states it.

    The same propagation as the ``gum`` part of :func:`evaluate_uncertainty`'s statement, for
    callers that run their own trials (the workspace map) and check them against it.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration data (joint readings [rad], points [m]).
    test_q : ndarray, shape (n, n_joints) [rad]
        Configurations.
    settings : UncertaintySettings
        Sources and their models.
    calibration : IdentificationResult
        The calibration of `campaign`.
    frame : {"measurement", "base"}
        Output frame.

    Returns
    -------
    ndarray, shape (n, 3) [m], or None
        Per configuration and axis; None when no source is smooth (nothing to propagate).
    """
    prep = prepare(
        model, campaign, np.atleast_2d(np.asarray(test_q, dtype=np.float64)), settings, calibration, "auto", frame
    )
    gum = smooth_gum(prep, 0.95)
    if gum is None:
        return None
    variance = np.clip(np.diag(np.asarray(gum.covariance)), 0.0, None)
    return np.asarray(np.sqrt(variance).reshape(-1, N_AXES), dtype=np.float64)


def regularisation_bias(prep: Prepared) -> Array:
    """First-order Tikhonov shrinkage of the tool position at each test configuration [m].

    For b = A x + e the regularised estimate has E[x_hat] - x = -(A^T A + lam^2 P)^-1 lam^2 P x:
    a bias the Monte Carlo cannot see, because every trial is centred on the calibration.
    Evaluated with x_hat in place of the unknown x, it is a lower estimate (x_hat is itself
    shrunk). Shape (n_test, 3), in the output frame.
    """
    problem = prep.problem
    calibration = prep.calibration
    lam = calibration.lambda_
    n_test = prep.test_joints.shape[0]
    if lam <= 0.0 or not problem.penalty_mask.any():
        return np.zeros((n_test, N_AXES))
    layout = problem.layout
    est = problem.estimated
    measurement = problem.measurement
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, prep.campaign.joint_positions)
    a_mat = stack_jacobian(measurement, jac, est) / problem.scale
    penalty = lam**2 * problem.penalty_mask
    x_hat = prep.trials.x_hat
    shift = -np.linalg.solve(a_mat.T @ a_mat + np.diag(penalty), penalty * x_hat) / problem.scale
    p_out = calibration.estimate.copy()
    b0 = layout.base_index
    if prep.trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
    _, gy = forward_points_and_jacobian(layout, p_out, prep.test_joints)
    if prep.trials.drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    return np.asarray(gy[:, :, est] @ shift, dtype=np.float64)


def gum_poses(
    prep: Prepared, summary: Summary, coverage: float, n_dig: int, *, angular: bool = False, per_pose: bool = False
) -> list[GumPose]:
    """Per test configuration: the GUM statement and its JCGM 101 §8 validation.

    With `angular`, `summary` holds the rotation deviations about the calibrated rotation.
    `per_pose`: the propagation within each configuration only (:func:`smooth_gum`); each
    configuration's statement is the same to rounding.
    """
    dim = N_AXES
    n_test = prep.test_joints.shape[0]
    n_out = dim * n_test
    applicable = all(src.smooth for src in prep.trials.sources)
    gum = smooth_gum(prep, coverage, angular=angular, per_pose=per_pose)
    k_norm = float(stats.norm.ppf(0.5 + coverage / 2.0))
    if gum is None:
        _, y_all = field_sensitivities(prep, angular=angular)
        cov_all = np.zeros((n_out, n_out))
    else:
        y_all = np.array([o.estimate for o in gum.outputs])
        cov_all = np.asarray(gum.covariance)
    positions = Summary(
        outputs=summary.outputs[:n_out],
        covariance=summary.covariance[:n_out, :n_out],
        coverage_probability=summary.coverage_probability,
        n_trials=summary.n_trials,
    )
    out = []
    for i in range(n_test):
        cols = slice(dim * i, dim * (i + 1))
        y = y_all[cols]
        cov_y = cov_all[cols, cols]
        u = np.sqrt(np.clip(np.diag(cov_y), 0.0, None))
        big_u = k_norm * u
        if gum is None:
            mc = [a.probabilistically_symmetric for a in positions.outputs[cols]]
            d_low = np.array([abs(y[j] - mc[j].low) for j in range(dim)])
            d_high = np.array([abs(y[j] - mc[j].high) for j in range(dim)])
            delta = np.zeros(dim)
            validated: tuple[bool, ...] = (False,) * dim
        else:
            checks = [validate_gum(gum, positions, output=dim * i + j, n_dig=n_dig) for j in range(dim)]
            d_low = np.array([c.d_low for c in checks])
            d_high = np.array([c.d_high for c in checks])
            delta = np.array([c.delta for c in checks])
            validated = tuple(bool(applicable and c.validated) for c in checks)
        out.append(
            GumPose(
                applicable=applicable,
                estimate=y,
                covariance=cov_y,
                standard_uncertainty=u,
                coverage_factor=k_norm,
                expanded_uncertainty=big_u,
                validated=validated,
                d_low=d_low,
                d_high=d_high,
                delta=delta,
            )
        )
    return out
