"""Session records of a calibration, and the between-session reproducibility of a robot.

:func:`session_state` turns a calibration into the
:class:`~robocal_uncertainty.core.session.SessionState` a later session needs: the linearised
covariance of the estimated parameters (stated tracker and encoder noise plus the model error
of :func:`~robocal_uncertainty.uncertainty.model_adequacy.assess_model_adequacy`), the model
error in the robot base frame, and the session's registration with its uncertainty.

When the model is inadequate the model error is, by default, a field correlated over the joint
configurations (:func:`estimate_model_error_field`: restricted maximum likelihood on the
calibration's residuals; :mod:`~robocal_uncertainty.core.model_error_field`): a real robot's
error is smooth, and one independent from pose to pose makes a check of a few poses too narrow
(UR10 series, 10-pose checks against 53-pose calibrations: 91.3 % consistent at the 5 % level
with the independent model error, 96.1 % of 1 600 with the field).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.core.session import (
    BASE_NAMES,
    SessionState,
    ValidatedLevel,
    check_level,
    parameter_covariance,
    parameter_gain,
    verify_session,
)
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy, assess_model_adequacy, pose_noise_covariances
from robocal_uncertainty.uncertainty.model_error_draws import estimate_field

__all__ = [
    "FIELD_MAX_POSES",
    "CrossValidatedModelError",
    "campaign_distances",
    "cross_validated_model_error",
    "estimate_model_error_field",
    "session_state",
    "validated_level",
]

Array = NDArray[np.float64]


def campaign_distances(campaign: Campaign, calibration: IdentificationResult) -> Array:
    """Tracker-to-target distance of every pose [m] (the tracker at the origin of its frame)."""
    positions = campaign.measurement.positions(campaign.points)
    if campaign.frame == "tracker" and positions is not None:
        return np.asarray(np.linalg.norm(positions, axis=1), dtype=np.float64)
    # Base-frame points: the tracker position is unknown; 2 m is the simulation's default reach.
    return np.full(campaign.n_poses, 2.0)


def model_error_dof(draws: Array, covariance: Array) -> float:
    """Effective degrees of freedom of a model-error covariance estimated from `draws`.

    With ``m_i = d_i^T Sigma^-1 d_i / 3`` (mean 1), the estimate's relative variance is
    ``var(m_i) / n``; a chi-square variance estimate with ``nu`` degrees of freedom has
    relative variance ``2 / nu``, so ``nu = 2 n / var(m_i)`` (``3 n`` for normal draws, fewer
    for heavy-tailed ones).
    """
    inv = np.linalg.pinv(covariance)
    m = np.einsum("pi,ij,pj->p", draws, inv, draws) / float(np.linalg.matrix_rank(covariance) or 1)
    var = float(np.var(m, ddof=1)) if m.size > 1 else float("inf")
    return float(2.0 * m.size / var) if var > 0 else float("inf")


def _parameter_factor(folds: list[tuple[Array, Array, Array, Array, Array]], model_error_base: Array) -> float:
    """The factor of :attr:`CrossValidatedModelError.parameter_factor` (bisection in log space)."""
    from scipy import linalg

    dof = sum(r.size - a.shape[1] for r, _, _, _, a in folds)

    def pooled(kappa: float) -> float:
        total = 0.0
        for r, noise, r_wb, param, a_mat in folds:
            me = r_wb @ model_error_base @ r_wb.T
            c_mat = linalg.block_diag(*(noise + me)) + kappa * param
            chol = np.linalg.cholesky(c_mat)
            rw = linalg.solve_triangular(chol, r, lower=True)
            qm, _ = np.linalg.qr(linalg.solve_triangular(chol, a_mat, lower=True))
            rw = rw - qm @ (qm.T @ rw)
            total += float(rw @ rw)
        return total

    if pooled(1.0) <= dof:
        return 1.0
    lo, hi = 0.0, np.log(1e3)
    if pooled(float(np.exp(hi))) > dof:
        return float(np.exp(hi))
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if pooled(float(np.exp(mid))) > dof:
            lo = mid
        else:
            hi = mid
    return float(np.exp(hi))


def session_state(
    calibration: IdentificationResult,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    sources: tuple[str, ...] = ("tracker", "encoder", "residual"),
    adequacy: ModelAdequacy | None = None,
    campaign_name: str | None = None,
    settings: dict[str, object] | None = None,
    cross_validated: CrossValidatedModelError | None = None,
    correlated: bool = True,
    model_error_from: SessionState | None = None,
) -> tuple[SessionState, ModelAdequacy]:
    """What a point calibration leaves for verification and for the next session.

    Parameters
    ----------
    calibration : IdentificationResult
        A point calibration of `campaign`.
    campaign : Campaign
        Its campaign (joints reordered to the model's).
    tracker_noise, encoder_noise
        The stated noise models of the session.
    sources : tuple of str
        Sources the statement uses; without ``residual`` no model error is carried.
    adequacy : ModelAdequacy, optional
        Already computed model adequacy (computed here otherwise).
    campaign_name : str, optional
        The campaign file, recorded.
    settings : dict, optional
        Settings to record (lambda method, weighting, ...).
    cross_validated : CrossValidatedModelError, optional
        The model error from held-out poses (:func:`cross_validated_model_error`): used in
        place of the one from the calibration's own residuals when the model is inadequate.
    correlated : bool
        When the model is inadequate (and no `cross_validated` is given), estimate the model
        error as a field correlated over the configurations (:func:`estimate_model_error_field`,
        shape from the residuals' moments): the per-pose covariance, the parameter covariance
        (``G (N + V) G^T`` with the correlated ``V``) and what a check needs to use it.
    """
    campaign = campaign.reorder_joints(calibration.model.joint_names)
    q = campaign.joint_positions
    distances = campaign_distances(campaign, calibration)
    if adequacy is None:
        adequacy = assess_model_adequacy(calibration, q, tracker_noise, encoder_noise, distances)
    noise = pose_noise_covariances(calibration, q, tracker_noise, encoder_noise, distances)
    layout = calibration.model.layout
    b0 = layout.base_index
    r_wb = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6])
    use_residual = "residual" in sources and not adequacy.adequate
    if model_error_from is not None:
        use_residual = "residual" in sources and bool(np.any(model_error_from.model_error_covariance))
    model_error = adequacy.inadequacy_covariance if use_residual else np.zeros((3, 3))
    draws = adequacy.draws @ r_wb if use_residual else None
    if use_residual and cross_validated is not None:
        model_error = r_wb @ cross_validated.covariance @ r_wb.T
        draws = cross_validated.draws
    if use_residual and model_error_from is not None and model_error_from.model_error_field is None:
        model_error = r_wb @ model_error_from.model_error_covariance @ r_wb.T
        draws = model_error_from.model_error_draws
    me_field = None
    field_dof = None
    if use_residual and cross_validated is None and correlated:
        if model_error_from is not None and model_error_from.model_error_field is not None:
            # Another calibration's model error (same session, other poses): its field as stated.
            me_field = dataclasses.replace(model_error_from.model_error_field, joint_positions=q)
            model_error = r_wb @ model_error_from.model_error_covariance @ r_wb.T
        else:
            shape = r_wb.T @ adequacy.inadequacy_covariance @ r_wb
            me_field, scale = estimate_model_error_field(calibration, q, noise, shape)
            shape = 3.0 * shape / np.trace(shape) if np.trace(shape) > 0 else np.eye(3)
            model_error = r_wb @ (scale * shape) @ r_wb.T
        from scipy import linalg

        total = linalg.block_diag(*noise) + me_field.covariance(q, model_error)
        cov = parameter_covariance(calibration, q, total)
        rotate = np.kron(np.eye(q.shape[0]), r_wb)
        me_field = dataclasses.replace(
            me_field,
            gain_names=tuple(n for n, e in zip(calibration.parameter_names, calibration.estimated) if e),
            gain=parameter_gain(calibration, q) @ rotate,
        )
        field_dof = me_field.dof
    else:
        cov = parameter_covariance(calibration, q, noise + model_error)
    if use_residual and cross_validated is not None:
        cov = cov * cross_validated.parameter_factor
    names = tuple(n for n, e in zip(calibration.parameter_names, calibration.estimated) if e)
    model_error_cov_base = r_wb.T @ model_error @ r_wb
    state = SessionState(
        frame=campaign.frame,
        frame_id=campaign.frame_id,
        n_poses=campaign.n_poses,
        covariance_names=names,
        parameter_covariance=cov,
        model_error_covariance=r_wb.T @ model_error @ r_wb,
        model_error_draws=draws,
        model_error_dof=field_dof
        if me_field is not None
        else (None if draws is None else model_error_dof(draws, model_error_cov_base)),
        model_error_field=me_field,
        tracker_noise=tracker_noise,
        encoder_noise=encoder_noise,
        registration=calibration.estimate[b0 : b0 + 6].copy() if campaign.frame == "tracker" else np.zeros(6),
        registration_covariance=np.zeros((6, 6)),
        sources=tuple(sources),
        extra={
            "campaign": campaign_name,
            "settings": dict(settings or {}),
            "tool_point_m": [float(v) for v in calibration.model.tool_point],
            "model_adequacy": {
                "adequate": bool(adequacy.adequate),
                "chi2": float(adequacy.chi2),
                "dof": float(adequacy.dof),
                "p_value": float(adequacy.p_value),
                "significance": float(adequacy.significance),
                "included": "residual" in sources,
                "cross_validated": None if cross_validated is None else cross_validated.to_dict(),
            },
        },
    )
    return dataclasses.replace(state, registration_covariance=state.covariance_of(BASE_NAMES)), adequacy


@dataclass(frozen=True, eq=False)
class CrossValidatedModelError:
    """The model error as held-out poses of the calibration campaign show it (k-fold).

    Attributes
    ----------
    covariance : ndarray, shape (3, 3) [m^2]
        Per-pose model-error covariance, robot base frame: the held-out residual covariance
        less the stated noise and the folds' own parameter uncertainty (clipped to be PSD).
    draws : ndarray, shape (n_poses, 3) [m]
        The held-out residuals (centred) whitened to `covariance`, robot base frame.
    fitted_covariance : ndarray, shape (3, 3) [m^2]
        The first-order estimate from the calibration's own residuals, for comparison.
    folds : int
    parameter_factor : float
        Factor (>= 1) on the calibration's parameter covariance with which the held-out folds,
        tested as a check is (tracker pose re-registered), give a statistic equal to its degrees
        of freedom: the first-order covariance treats the model error as independent from pose
        to pose, a smooth real one moves the parameters more.
    """

    covariance: Array
    draws: Array
    fitted_covariance: Array
    folds: int
    parameter_factor: float = 1.0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (the draws are written with the session's model error)."""
        return {
            "folds": self.folds,
            "parameter_factor": self.parameter_factor,
            "covariance_base_m2": self.covariance.tolist(),
            "fitted_covariance_base_m2": self.fitted_covariance.tolist(),
        }


def cross_validated_model_error(
    model: RobotModel,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    folds: int = 5,
    lambda_: str | float = "auto",
    seed: int = 0,
) -> CrossValidatedModelError:
    """The model error from k-fold held-out residuals instead of the calibration's own residuals.

    The calibration's residuals are shrunk by the fit and the poses the model fits worst pull
    the fit towards them, so a model error estimated from them is too small and too
    light-tailed for new poses: on the UR10 series a check of 10 unchanged poses against it is
    rejected 9-22 % of the time at the 5 % level. Here every pose is predicted by a calibration
    of the other folds (same tracker set-up, no re-registration); the per-pose model error is
    the covariance of these held-out residuals less the stated noise and the folds' own
    parameter uncertainty, and the held-out residuals are what the check resamples.

    Raises
    ------
    IdentifiabilityError
        Too few poses for the folds.
    """
    campaign = campaign.reorder_joints(model.joint_names)
    n = campaign.n_poses
    order = np.random.default_rng(seed).permutation(n)
    held: list[Array] = []
    known: list[Array] = []
    fitted: list[Array] = []
    folds_data: list[tuple[Array, Array, Array, Array, Array]] = []
    for part in np.array_split(order, folds):
        train = np.setdiff1d(order, part)
        cal = identify(model, campaign.subset(train), lambda_=lambda_, accept_unconverged=True)
        state, adequacy = session_state(cal, campaign.subset(train), tracker_noise, encoder_noise, correlated=False)
        test = campaign.subset(np.sort(part))
        q = test.joint_positions
        layout = cal.model.layout
        pred, jac = forward_points_and_jacobian(layout, cal.estimate, q)
        y = test.measurement.positions(test.points)
        assert y is not None
        noise = pose_noise_covariances(cal, q, tracker_noise, encoder_noise, campaign_distances(test, cal))
        idx = [layout.names.index(nm) for nm in state.covariance_names]
        jk = jac[:, :, idx]
        param = np.einsum("pik,kl,pjl->pij", jk, state.parameter_covariance, jk)
        b0 = layout.base_index
        r_wb = rpy_to_matrix(cal.estimate[b0 + 3 : b0 + 6])
        held.append((y - pred) @ r_wb)
        kin = [i for i, nm in enumerate(state.covariance_names) if not nm.startswith("base.")]
        jk_flat = jk[:, :, kin].reshape(-1, len(kin))
        base = jac[:, :, b0 : b0 + 6].reshape(-1, 6)
        folds_data.append(
            (
                (y - pred).reshape(-1),
                noise,
                r_wb,
                jk_flat @ state.parameter_covariance[np.ix_(kin, kin)] @ jk_flat.T,
                base / np.linalg.norm(base, axis=0),
            )
        )
        known.append(np.einsum("ki,pkl,lj->pij", r_wb, noise + param, r_wb))
        fitted.append(r_wb.T @ adequacy.inadequacy_covariance @ r_wb)
    residuals = np.concatenate(held)
    centred = residuals - residuals.mean(axis=0)
    observed = residuals.T @ residuals / n
    evals, evecs = np.linalg.eigh(observed - np.concatenate(known).mean(axis=0))
    cov = (evecs * np.clip(evals, 0.0, None)) @ evecs.T
    s_evals, s_evecs = np.linalg.eigh(centred.T @ centred / n)
    s_inv_sqrt = (s_evecs / np.sqrt(np.maximum(s_evals, np.finfo(float).tiny))) @ s_evecs.T
    m_evals, m_evecs = np.linalg.eigh(cov)
    m_sqrt = (m_evecs * np.sqrt(np.clip(m_evals, 0.0, None))) @ m_evecs.T
    factor = _parameter_factor(folds_data, cov)
    return CrossValidatedModelError(
        parameter_factor=factor,
        covariance=cov,
        draws=centred @ (m_sqrt @ s_inv_sqrt).T,
        fitted_covariance=np.mean(fitted, axis=0),
        folds=folds,
    )


FIELD_MAX_POSES = 200
"""Most poses the field's hyperparameters are estimated from (a seeded subset of larger campaigns)."""


def estimate_model_error_field(
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape_base: Array,
    *,
    max_poses: int = FIELD_MAX_POSES,
    seed: int = 0,
) -> tuple[ModelErrorField, float]:
    """The correlated model error of a point calibration by restricted maximum likelihood.

    The estimator every statement uses (:func:`~robocal_uncertainty.uncertainty.model_error_draws.estimate_field`:
    the likelihood of the residuals' contrasts orthogonal to the fit, ``V = [c rho(d / l) +
    (1 - c) I] (x) s S``, see :mod:`~robocal_uncertainty.core.model_error_field`), here with the
    likelihood's scale ``s``: a check re-registers and is tested against the validated level,
    and the session records the field with what a check needs to use it.

    Parameters
    ----------
    calibration : IdentificationResult
        A point calibration (unweighted).
    joint_positions : ndarray, shape (n, n_joints) [rad]
    noise : ndarray, shape (n, 3, 3) [m^2]
        Stated noise covariance per pose, measurement frame.
    shape_base : ndarray, shape (3, 3)
        Shape ``S`` of the per-pose model-error covariance, robot base frame (its trace is
        normalised to 3; the identity when the residuals gave none).
    max_poses : int
        Campaigns with more poses estimate the hyperparameters on a seeded subset of this many.
    seed : int
        Seed of that subset.

    Returns
    -------
    (ModelErrorField, float)
        The field (without its gain: :func:`session_state` adds it) and ``s`` [m^2]: the
        per-pose model-error covariance is ``s S``.
    """
    q_all = np.asarray(joint_positions, dtype=np.float64)
    b0 = calibration.model.layout.base_index
    r_wb = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6])
    shape = np.asarray(shape_base, dtype=np.float64)
    shape = 3.0 * shape / np.trace(shape) if np.trace(shape) > 0 else np.eye(3)
    estimate = estimate_field(
        calibration, q_all, noise, r_wb @ shape @ r_wb.T, max_equations=3 * max_poses, seed=seed, leave_one_out=False
    )
    field = ModelErrorField(
        correlated_fraction=estimate.correlated_fraction,
        length_scale=estimate.length_scale,
        joint_positions=q_all.copy(),
        gain_names=(),
        gain=np.zeros((0, 3 * q_all.shape[0])),
        dof=estimate.dof,
        log_likelihood=estimate.log_likelihood,
        independent_log_likelihood=estimate.independent_log_likelihood,
        hyper_covariance=estimate.hyper_covariance,
        extra={"poses_used": estimate.poses_used, "contrasts": estimate.contrasts},
    )
    return field, float(np.trace(estimate.per_pose_covariance)) / 3.0


LEVEL_FOLDS = 5
"""Folds of the calibration campaign that validate its error level (:func:`validated_level`)."""
LEVEL_REPEATS = 4
"""Random splits into :data:`LEVEL_FOLDS` folds the validated level pools: one split's level
depends on which poses shared a fold; on the UR10 series B and D three to six splits steady it
(log scatter against the calibration's level on all its other poses 0.21-0.27 with one split,
0.16-0.18 with three) and give the fold-level dispersion 15-30 folds to be measured on."""


def validated_level(
    model: RobotModel,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    lambda_: str | float = "auto",
    retool: bool = True,
    folds: int = LEVEL_FOLDS,
    seed: int = 0,
    repeats: int = LEVEL_REPEATS,
    sources: tuple[str, ...] = ("tracker", "encoder", "residual"),
    correlated: bool = True,
    reference: SessionState | None = None,
) -> ValidatedLevel:
    """The calibration session's error level on its own held-out poses, re-registered as a check.

    The campaign's poses are split at random (``seed``; `repeats` independent splits) into
    `folds` folds; each is predicted
    by a calibration of the others with the statement of `reference` (the full calibration's
    model error, so every fold is measured against the same statement; :func:`session_state`), re-registered
    (tracker pose, and the tool point with `retool`) as ``verify`` re-registers a check, and its
    observed squared error is set against the stated one
    (:func:`~robocal_uncertainty.core.session.check_level`). A later check is tested against
    this level: same-session checks then agree with it by construction of the split, whatever
    scale the statement's model error has (a field whose scale the data hardly fix).

    Raises
    ------
    IdentifiabilityError
        Folds too small to re-register (fewer than about 4 poses each) or to calibrate without.
    """
    n = campaign.n_poses
    rng = np.random.default_rng(seed)
    checks = []
    for _ in range(repeats):
        order = rng.permutation(n)
        for part in np.array_split(order, folds):
            train = campaign.subset(np.sort(np.setdiff1d(order, part)))
            cal = identify(model, train, lambda_=lambda_, accept_unconverged=True)
            state, _ = session_state(
                cal,
                train,
                tracker_noise,
                encoder_noise,
                sources=sources,
                correlated=correlated,
                model_error_from=reference,
            )
            check = campaign.subset(np.sort(part))
            checks.append(verify_session(cal.model, state, check, retool=retool, null_trials=100))
    return check_level(checks, seed=seed, repeats=repeats)
