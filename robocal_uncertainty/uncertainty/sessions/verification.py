"""Verification of a calibration in a new session: re-register, test, state the size of any change.

With ``y`` the check points (n x 3, new tracker frame), ``f(theta)`` the calibrated
model's prediction with the re-registered nuisance ``theta`` (6 tracker-pose parameters, plus
3 tool-point coordinates when the probe was remounted) and ``C`` the covariance of ``y - f``
under "nothing changed":

``C = J_k Sigma_k J_k^T + blockdiag_i(Sigma_tracker,i + J_q,i Sigma_q J_q,i^T + R Sigma_m R^T)``

(calibration parameter uncertainty, correlated across poses; tracker and encoder noise;
the calibration's model error ``Sigma_m``, stated in the robot base frame and turned into the
new tracker frame by the re-registered rotation ``R``). When the calibration states its model
error as a field correlated over the configurations
(:class:`~robocal_uncertainty.core.model_error_field.ModelErrorField`), the block-diagonal
``R Sigma_m R^T`` is replaced by the field over the check poses less what the calibration's
parameters absorbed of it (``K_cc - J_k G K_tc - (J_k G K_tc)^T``; ``Sigma_k`` then holds
``G K_tt G^T``), and the null draws it as one normal over the poses whose scale is widened by
the estimate's degrees of freedom. The GLS estimate ``theta_hat`` minimises ``r^T C^-1 r`` and
the statistic ``chi2 = r^T C^-1 r`` at the minimum is compared with its Monte Carlo null
distribution (:mod:`.null_distribution`) on ``3 n - k`` degrees of freedom (``k`` = rank of
the re-registration Jacobian). The check is *consistent* when its p-value is at least the
significance level (the false-alarm rate).

When the calibration records a
:class:`~robocal_uncertainty.core.session.ValidatedLevel` (its own held-out error level), the
verdict is the *level test* instead (:func:`~.level.level_test`): the check's mean square
error per component after an ordinary least-squares re-registration against that level, with
the ratio ("errors 1.6x the calibration session's") and its interval. Why: on real sessions
the statement's model-error field has a scale fixed by one to a few degrees of freedom, so the
chi-square's null distribution is so wide that a session with twice the errors reads
consistent at every check size; the level is measured, not stated. The chi-square p-value is
still reported.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, stats

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import fit_rigid_base
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import joint_columns
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix
from robocal_uncertainty.core.session import (
    BASE_NAMES,
    DEFAULT_NULL_TRIALS,
    DEFAULT_SIGNIFICANCE,
    TOOL_NAMES,
    LevelTest,
    SessionState,
    TrackerMove,
    Verification,
    effect_jacobian,
)
from robocal_uncertainty.errors import ConfigError, IdentifiabilityError, InputError
from robocal_uncertainty.uncertainty.sessions.check_campaign import (
    block_diagonal,
    check_campaign,
    effective_dof,
    pose_noise,
    unique_poses,
)
from robocal_uncertainty.uncertainty.sessions.level import FoldLevel, error_level, level_test, tolerance_check
from robocal_uncertainty.uncertainty.sessions.null_distribution import (
    NullNoise,
    chol_factor,
    gls_chi2,
    null_statistics,
    sqrt_psd,
)
from robocal_uncertainty.uncertainty.sessions.tracker_move import tracker_move

__all__ = ["fold_level", "verify_session"]

Array = NDArray[np.float64]
_DEGENERATE_RCOND = 1e-7
_MAX_ITERATIONS = 30


@dataclass(frozen=True, eq=False)
class _Setup:
    """A check made ready: its unique poses, the nuisance it re-registers, the stated parts."""

    model: RobotModel
    state: SessionState
    campaign: Campaign
    y: Array
    duplicates: int
    tracker: TrackerNoise
    encoder: EncoderNoise
    free_names: tuple[str, ...]
    free: NDArray[np.intp]
    kin_names: tuple[str, ...]
    kin: NDArray[np.intp]
    sigma_k: Array
    theta_cols: list[int]
    distances: Array
    between: Array | None
    field_cross: Array | None = None
    field_cols: tuple[int, ...] = ()
    rotated_field: bool = False

    @property
    def layout(self) -> ParameterLayout:
        return self.model.layout

    @property
    def q(self) -> Array:
        return self.campaign.joint_positions

    @property
    def n(self) -> int:
        return self.campaign.n_poses

    @property
    def b0(self) -> int:
        return self.model.layout.base_index

    @property
    def me_field(self) -> ModelErrorField | None:
        return self.state.model_error_field


@dataclass(frozen=True, eq=False)
class _Fit:
    """The re-registered check: parameters, prediction, GLS factor and the chi-square test."""

    p: Array
    jac: Array
    a_mat: Array
    chol: Array
    r: Array
    c_mat: Array
    reg_cov: Array
    dof: int
    chi2: float
    p_chi2: float
    r_new: Array


def verify_session(
    model: RobotModel,
    state: SessionState,
    campaign: Campaign,
    *,
    retool: bool = False,
    significance: float = DEFAULT_SIGNIFICANCE,
    tracker_noise: TrackerNoise | None = None,
    encoder_noise: EncoderNoise | None = None,
    null_trials: int = DEFAULT_NULL_TRIALS,
    seed: int = 0,
    effects: tuple[str, ...] = (),
) -> Verification:
    """Re-register a new session on a check campaign and test the calibration against it.

    Parameters
    ----------
    model : RobotModel
        The calibrated model (the calibration file applied; its layout without a tool rotation).
    state : SessionState
        What the calibration session left (covariances, model error, registration).
    campaign : Campaign
        Check measurements of the new session: points in its tracker frame (the tracker pose
        is re-registered) or in the robot base frame (nothing is, but the tool when `retool`).
    retool : bool
        Re-register the tool point too (the probe was remounted).
    significance : float
        Test level (false-alarm rate), default 5 %.
    tracker_noise, encoder_noise : optional
        The new session's instruments; the calibration session's by default.
    null_trials : int
        Monte Carlo draws of the statistic under "nothing changed" from the stated
        distributions (uniform tracker and encoder errors, the model error resampled from its
        draws or normal, normal parameter and between-session errors; the estimated parts
        scaled by ``sqrt(nu / chi2_nu)`` per draw); they give the p-value. With uniform errors
        the statistic has lighter tails than a chi-square, whose p-value would be too large.
    seed : int
        Seed of those draws (``SeedSequence(seed)`` spawned per block of 4096 draws).
    effects : tuple of str
        Session effects to estimate after the re-registration (joint offsets, length scale;
        :func:`~robocal_uncertainty.core.session.effect_jacobian`) in one linear GLS step with
        it: what changed since the calibration, with its covariance (``Verification.effects``);
        they do not enter the test.

    Raises
    ------
    IdentifiabilityError
        Too few poses, or poses that cannot re-register (degenerate).
    InputError
        Wrong joints, no positions.
    ConfigError
        A significance level outside (0, 1).
    """
    if not (0.0 < float(significance) < 1.0):
        msg = f"significance must be in (0, 1), got {significance!r}"
        raise ConfigError(msg)
    setup, p = _prepare(model, state, campaign, retool, tracker_noise, encoder_noise)
    fit = _reregister(setup, p, retool)
    null = _null_draws(setup, fit, null_trials, seed)
    p_value = float((1 + np.count_nonzero(null >= fit.chi2)) / (1 + null.size))
    return _verification(setup, fit, p_value, float(significance), null_trials, seed, retool, effects)


def fold_level(model: RobotModel, state: SessionState, campaign: Campaign, *, retool: bool) -> FoldLevel:
    """A held-out fold's error level: what :func:`verify_session` reports of it, and only that.

    The same re-registration and level (``verify_session(...).level`` and its companions, the
    same numbers), without the null draws, the residual statistics and the drift's size a
    verdict needs: the validated level (:func:`~.validated_level.validated_level`) reads twenty
    folds' levels and nothing else of them.
    """
    setup, p = _prepare(model, state, campaign, retool, None, None, rotated_field=True)
    fit = _reregister(setup, p, retool)
    level, level_dof, level_z, level_trace, _ = _check_level(setup, fit)
    return FoldLevel(level=level, level_dof=level_dof, level_trace=level_trace, level_z=level_z, n_poses=setup.n)


def _prepare(
    model: RobotModel,
    state: SessionState,
    campaign: Campaign,
    retool: bool,
    tracker_noise: TrackerNoise | None,
    encoder_noise: EncoderNoise | None,
    *,
    rotated_field: bool = False,
) -> tuple[_Setup, Array]:
    """The check's unique poses and stated parts, and the parameters with the tracker pose fitted.

    With `rotated_field` the field's prediction covariance is assembled once and rotated per
    iteration (:func:`_field_prediction`): equal to rounding, but rounding that an ill-conditioned
    re-registration (tracker pose and tool point acting almost alike) magnifies in its covariance
    (1e-8 relative on a 10-pose UR10 check), so ``verify`` keeps the field's own assembly and only
    the validated level's folds, which read the level (changed by 4e-13 relative), take this one.
    """
    if model.tool_rotation:
        model = dataclasses.replace(model, tool_rotation=False)
    campaign, y, duplicates = unique_poses(*check_campaign(model, campaign, retool)[:2])
    try:
        check_campaign(model, campaign, retool)
    except IdentifiabilityError as err:
        msg = f"{duplicates} check pose(s) repeat another exactly and count once: {err}"
        raise IdentifiabilityError(msg) from err
    layout = model.layout
    names = layout.names
    q = campaign.joint_positions
    n = campaign.n_poses
    p = model.parameter_vector()
    b0 = layout.base_index
    free_names: list[str] = []
    if campaign.frame == "tracker":
        free_names += list(BASE_NAMES)
        p_kin = p.copy()
        p_kin[b0 : b0 + 6] = 0.0
        xyz, rpy = fit_rigid_base(forward_points(layout, p_kin, q), y)
        p[b0 : b0 + 3] = xyz
        p[b0 + 3 : b0 + 6] = rpy
    else:
        p[b0 : b0 + 6] = 0.0
    if retool:
        free_names += list(TOOL_NAMES)
    kin_names = tuple(nm for nm in state.covariance_names if nm not in free_names and not nm.startswith("base."))
    kin_names = tuple(nm for nm in kin_names if nm in names)
    me_field = state.model_error_field
    if me_field is not None and me_field.joint_positions.shape[1] != q.shape[1]:
        msg = f"the model-error field has {me_field.joint_positions.shape[1]} joints, the check {q.shape[1]}"
        raise InputError(msg)
    field_cross, field_cols = (
        _field_cross(me_field, state.model_error_covariance, q, kin_names) if rotated_field else (None, ())
    )
    setup = _Setup(
        model=model,
        state=state,
        campaign=campaign,
        y=y,
        duplicates=duplicates,
        tracker=tracker_noise or state.tracker_noise,
        encoder=encoder_noise or state.encoder_noise,
        free_names=tuple(free_names),
        free=np.array([names.index(nm) for nm in free_names], dtype=np.intp),
        kin_names=kin_names,
        kin=np.array([names.index(nm) for nm in kin_names], dtype=np.intp),
        sigma_k=state.covariance_of(kin_names),
        theta_cols=joint_columns(layout),
        distances=np.linalg.norm(y, axis=1) if campaign.frame == "tracker" else np.full(n, 2.0),
        between=state.between_session_covariance if state.between_session_names else None,
        field_cross=field_cross,
        field_cols=field_cols,
        rotated_field=rotated_field,
    )
    return setup, p


def _field_cross(
    me_field: ModelErrorField | None, per_pose_base: Array, q: Array, kin_names: tuple[str, ...]
) -> tuple[Array | None, tuple[int, ...]]:
    """``G K_tc`` of the field with both sides in the robot base frame, shape (k, 3 n), and its columns.

    What the calibration's parameters absorbed of the field at the check poses does not depend
    on the re-registration but through the tracker rotation, applied pose by pose
    (:func:`_field_prediction`): computed once per check instead of at every iteration.
    """
    if me_field is None:
        return None, ()
    rows = [me_field.gain_names.index(nm) for nm in kin_names if nm in me_field.gain_names]
    cols = tuple(c for c, nm in enumerate(kin_names) if nm in me_field.gain_names)
    if not rows:
        return None, ()
    return np.asarray(me_field.gain[rows] @ me_field.cross_covariance(q, per_pose_base), dtype=np.float64), cols


def _field_prediction(s: _Setup, r_wb: Array, jk: Array) -> Array:
    """:meth:`ModelErrorField.prediction_covariance` at the tracker rotation `r_wb`, shape (3 n, 3 n) [m^2].

    ``K_cc - J_c G K_tc - (J_c G K_tc)^T`` with ``G K_tc`` from :func:`_field_cross` turned
    into the measurement frame pose by pose: the same matrix (to rounding) without the
    Kronecker product over every calibration pose at each iteration of the re-registration.
    """
    assert s.me_field is not None
    n = s.n
    k_cc = s.me_field.covariance(s.q, r_wb @ s.state.model_error_covariance @ r_wb.T)
    if s.field_cross is None:
        return k_cc
    g_ktc = (s.field_cross.reshape(-1, n, 3) @ r_wb.T).reshape(-1, 3 * n)
    cross = jk[:, list(s.field_cols)] @ g_ktc
    out = k_cc - cross - cross.T
    return np.asarray(0.5 * (out + out.T), dtype=np.float64)


def _covariance(s: _Setup, jac: Array, params: Array) -> Array:
    """Covariance of the check's residuals under "nothing changed", shape (3 n, 3 n) [m^2]."""
    cov = block_diagonal(pose_noise(jac, s.theta_cols, s.distances, s.tracker, s.encoder, s.model.prismatic))
    cov = cov + _correlated(s, jac, params)
    if s.between is not None:
        g = effect_jacobian(s.layout, params, s.q, s.state.between_session_names).reshape(3 * s.n, -1)
        cov = cov + g @ s.between @ g.T
    return np.asarray(cov, dtype=np.float64)


def _correlated(s: _Setup, jac: Array, params: Array) -> Array:
    """Model error and calibration parameter errors over the poses, shape (3 n, 3 n) [m^2]."""
    n, kin = s.n, s.kin
    r_wb = rpy_to_matrix(params[s.b0 + 3 : s.b0 + 6])
    jk = jac[:, :, kin].reshape(3 * n, kin.size)
    if s.me_field is None:
        cov = block_diagonal(np.broadcast_to(r_wb @ s.state.model_error_covariance @ r_wb.T, (n, 3, 3)))
    else:
        cov = (
            _field_prediction(s, r_wb, jk)
            if s.rotated_field
            else s.me_field.prediction_covariance(s.q, s.state.model_error_covariance, r_wb, jk, s.kin_names)
        )
    if kin.size:
        cov = cov + jk @ s.sigma_k @ jk.T
    return np.asarray(cov, dtype=np.float64)


def _reregister(s: _Setup, p: Array, retool: bool) -> _Fit:
    """GLS re-registration of the nuisance (tracker pose, tool point) and the chi-square test."""
    layout, free, n, q = s.layout, s.free, s.n, s.q
    scale = np.ones(free.size)
    pred, jac = forward_points_and_jacobian(layout, p, q)
    a_mat = jac[:, :, free].reshape(3 * n, free.size)
    if free.size:
        scale = np.linalg.norm(a_mat, axis=0)
        s_values = np.linalg.svd(a_mat / scale, compute_uv=False)
        if s_values[-1] <= _DEGENERATE_RCOND * s_values[0]:
            tracker = s.campaign.frame == "tracker"
            msg = (
                f"degenerate check campaign: its {n} poses cannot re-register "
                f"{'the tracker pose' if tracker else ''}"
                f"{' and ' if tracker and retool else ''}{'the tool point' if retool else ''} "
                "(the tool points must span the workspace and the wrist must turn between poses)"
            )
            raise IdentifiabilityError(msg)
    chol = chol_factor(_covariance(s, jac, p))
    for _ in range(_MAX_ITERATIONS):
        r = (s.y - pred).reshape(3 * n)
        if not free.size:
            break
        aw = linalg.solve_triangular(chol, a_mat / scale, lower=True)
        rw = linalg.solve_triangular(chol, r, lower=True)
        step = np.linalg.lstsq(aw, rw, rcond=None)[0] / scale
        p[free] += step
        pred, jac = forward_points_and_jacobian(layout, p, q)
        a_mat = jac[:, :, free].reshape(3 * n, free.size)
        chol = np.asarray(np.linalg.cholesky(_covariance(s, jac, p)), dtype=np.float64)
        if np.max(np.abs(step * scale)) < 1e-12 + 1e-10 * np.max(np.abs(p[free] * scale)):
            break
    r = (s.y - pred).reshape(3 * n)
    if free.size:
        aw = linalg.solve_triangular(chol, a_mat / scale, lower=True)
        rank = int(np.linalg.matrix_rank(aw))
        reg_cov = np.linalg.pinv(aw.T @ aw) / np.outer(scale, scale)
    else:
        rank = 0
        reg_cov = np.zeros((0, 0))
    dof = 3 * n - rank
    chi2 = gls_chi2(r, chol, a_mat)
    return _Fit(
        p=p,
        jac=jac,
        a_mat=a_mat,
        chol=chol,
        r=r,
        c_mat=chol @ chol.T,
        reg_cov=reg_cov,
        dof=dof,
        chi2=chi2,
        p_chi2=float(stats.chi2.sf(chi2, dof)),
        r_new=rpy_to_matrix(p[s.b0 + 3 : s.b0 + 6]),
    )


def _null_draws(s: _Setup, fit: _Fit, null_trials: int, seed: int) -> Array:
    """The statistic under "nothing changed" (:func:`~.null_distribution.null_statistics`)."""
    n, kin, jac, state, r_new = s.n, s.kin, fit.jac, s.state, fit.r_new
    between_factor = (
        None
        if s.between is None
        else effect_jacobian(s.layout, fit.p, s.q, state.between_session_names).reshape(3 * n, -1) @ sqrt_psd(s.between)
    )
    noise = NullNoise(s.distances, s.tracker, s.encoder, jac[:, :, s.theta_cols], prismatic=s.model.prismatic)
    common = (null_trials, seed, fit.chol, fit.a_mat, noise)
    if s.me_field is None:
        return null_statistics(
            *common,
            model_error=r_new @ state.model_error_covariance @ r_new.T,
            kin_jacobian=jac[:, :, kin].reshape(3 * n, kin.size) if kin.size else np.zeros((3 * n, 0)),
            kin_covariance=s.sigma_k,
            model_error_draws=None if state.model_error_draws is None else state.model_error_draws @ r_new.T,
            model_error_dof=state.model_error_dof,
            between_factor=between_factor,
            between_dof=state.between_session_dof,
        )
    # The correlated model error and the parameter errors it drives: one normal over all
    # the poses, its estimated scale widened by the estimate's degrees of freedom.
    return null_statistics(
        *common,
        model_error=np.zeros((3, 3)),
        kin_jacobian=np.zeros((3 * n, 0)),
        kin_covariance=np.zeros((0, 0)),
        model_error_draws=None,
        model_error_dof=None,
        between_factor=between_factor,
        between_dof=state.between_session_dof,
        correlated_factor=sqrt_psd(_correlated(s, jac, fit.p)),
        correlated_dof=state.model_error_dof,
    )


def _check_level(s: _Setup, fit: _Fit) -> tuple[float, float, Array, float, LevelTest | None]:
    """The check's error level (:func:`~.level.error_level`) and its test against the validated level."""
    # The level's shape: stated noise, plus the calibration parameter errors when they come from
    # that noise alone. A parameter covariance driven by a model error carries its field's
    # correlation length, which one campaign hardly fixes (on the UR10 series B and D it made a
    # 2x session read 1x); there the shape is the noise's.
    jac, kin, n = fit.jac, s.kin, s.n
    shape = block_diagonal(pose_noise(jac, s.theta_cols, s.distances, s.tracker, s.encoder, s.model.prismatic))
    if kin.size and not np.any(s.state.model_error_covariance):
        jk_flat = jac[:, :, kin].reshape(3 * n, kin.size)
        shape = shape + jk_flat @ s.sigma_k @ jk_flat.T
    level, level_dof, level_z, level_trace = error_level(fit.r, fit.a_mat, np.asarray(shape, dtype=np.float64))
    reference = s.state.validated_level
    outcome = None
    if reference is not None and reference.level > 0.0:
        between_level = s.state.extra.get("between_session")
        outcome = level_test(
            level, level_dof, reference, dict(between_level) if isinstance(between_level, dict) else None
        )
    return level, level_dof, level_z, level_trace, outcome


def _residual_statistics(fit: _Fit, n: int) -> tuple[Array, Array, Array]:
    """Per component: the residuals' stated std after re-registration; per pose: their chi-square."""
    res_cov = fit.c_mat - fit.a_mat @ fit.reg_cov @ fit.a_mat.T
    res_std = np.sqrt(np.clip(np.diag(res_cov), 1e-30, None)).reshape(n, 3)
    residuals = fit.r.reshape(n, 3)
    pose_chi2 = np.empty(n)
    for i in range(n):
        block = res_cov[3 * i : 3 * i + 3, 3 * i : 3 * i + 3]
        pose_chi2[i] = float(residuals[i] @ np.linalg.pinv(block, rcond=1e-10) @ residuals[i])
    return res_std, residuals, pose_chi2


def _excess_std(fit: _Fit, n: int) -> float:
    """The extra standard deviation per component that brings the chi-square to its dof [m]."""
    if fit.chi2 <= fit.dof:
        return 0.0
    r, c_mat, a_mat, dof = fit.r, fit.c_mat, fit.a_mat, fit.dof
    lo, hi = 0.0, float(np.sqrt(np.mean(fit.r.reshape(n, 3) ** 2))) + 1e-9
    while gls_chi2(r, chol_factor(c_mat + hi**2 * np.eye(3 * n)), a_mat) > dof:
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if gls_chi2(r, chol_factor(c_mat + mid**2 * np.eye(3 * n)), a_mat) > dof:
            lo = mid
        else:
            hi = mid
    return hi


def _verdict(
    fit: _Fit, outcome: LevelTest | None, level: float, reference_level: float, p_value: float, significance: float
) -> tuple[bool, str, float]:
    """Consistent or drifted, the verdict line and the drift's size per component [m]."""
    consistent = p_value >= significance
    excess = _excess_std(fit, fit.r.size // 3)
    if outcome is not None:
        ratio, interval = outcome.ratio, outcome.ratio_interval
        size = (
            f"errors {ratio:.2f}x the calibration session's (95 % interval {interval[0]:.2f}-"
            f"{interval[1]:.2f}; "
            + (
                f"F test on {outcome.check_dof:.0f} and {outcome.reference_dof:.0f} degrees of freedom"
                if outcome.test == "error level"
                else "t test on the log level with the between-session spread"
            )
            + f", p = {p_value:.3g} {'>=' if consistent else '<'} {significance:g})"
        )
        # The drift's size: the extra standard deviation per component beyond the calibration
        # session's own validated level.
        excess = float(np.sqrt(max(level - reference_level, 0.0)))
        verdict = (
            f"consistent: the robot agrees with its calibration within the stated uncertainty: {size}"
            if consistent
            else f"drifted: the robot deviates from its calibration by about {excess * 1e3:.3g} mm per axis "
            f"beyond its validated error level: {size}; re-calibrate"
        )
    elif consistent:
        verdict = (
            f"consistent: the robot agrees with its calibration within the stated uncertainty "
            f"(chi2 = {fit.chi2:.3g} on {fit.dof} degrees of freedom, p = {p_value:.3g} >= {significance:g})"
        )
    else:
        verdict = (
            f"drifted: the robot deviates from its calibration by about {excess * 1e3:.3g} mm per axis "
            f"beyond the stated uncertainty (chi2 = {fit.chi2:.3g} on {fit.dof} degrees of freedom, "
            f"p = {p_value:.3g} < {significance:g}); re-calibrate"
        )
    return consistent, verdict, excess


def _session_changes(s: _Setup, fit: _Fit, retool: bool) -> tuple[TrackerMove | None, Array | None, Array | None]:
    """The tracker move against the calibration session's registration, and the tool change."""
    move = None
    p, reg_cov, b0 = fit.p, fit.reg_cov, s.b0
    if s.campaign.frame == "tracker" and s.state.frame == "tracker":
        move = tracker_move(p[b0 : b0 + 6], reg_cov[:6, :6], s.state.registration, s.state.registration_covariance)
    tool_change = tool_std = None
    if retool:
        t0 = s.layout.tool_index
        k0 = s.free_names.index("tool.x")
        tool_change = p[t0 : t0 + 3] - s.model.tool_point
        tool_cov = reg_cov[k0 : k0 + 3, k0 : k0 + 3] + s.state.covariance_of(TOOL_NAMES)
        tool_std = np.sqrt(np.clip(np.diag(tool_cov), 0.0, None))
    return move, tool_change, tool_std


def _effects(s: _Setup, fit: _Fit, effects: tuple[str, ...]) -> tuple[Array | None, Array | None]:
    """Session effects estimated with the re-registration in one linear GLS step, with their covariance."""
    if not effects:
        return None, None
    g = effect_jacobian(s.layout, fit.p, s.q, effects).reshape(3 * s.n, len(effects))
    full = np.concatenate((fit.a_mat, g), axis=1)
    col = np.linalg.norm(full, axis=0)
    col[col == 0] = 1.0
    fw = linalg.solve_triangular(fit.chol, full / col, lower=True)
    inv = np.linalg.pinv(fw.T @ fw) / np.outer(col, col)
    step = inv @ (full.T @ linalg.cho_solve((fit.chol, True), fit.r))
    return step[s.free.size :], inv[s.free.size :, s.free.size :]


def _verification(
    s: _Setup,
    fit: _Fit,
    p_value: float,
    significance: float,
    null_trials: int,
    seed: int,
    retool: bool,
    effects: tuple[str, ...],
) -> Verification:
    """The verdict and everything reported beside it."""
    state, n = s.state, s.n
    level, level_dof, level_z, level_trace, outcome = _check_level(s, fit)
    reference_level = 0.0 if state.validated_level is None else state.validated_level.level
    test_p_value = p_value if outcome is None else outcome.p_value
    consistent, verdict, excess = _verdict(fit, outcome, level, reference_level, test_p_value, significance)
    res_std, residuals, pose_chi2 = _residual_statistics(fit, n)
    move, tool_change, tool_std = _session_changes(s, fit, retool)
    effect_values, effect_cov = _effects(s, fit, effects)
    between_names = None if s.between is None else state.between_session_names
    tolerance = None
    if outcome is not None and outcome.test == "error level" and state.validated_level is not None:
        tolerance = tolerance_check(level, level_dof, state.validated_level, reregistered=s.free.size)
    return Verification(
        consistent=consistent,
        verdict=verdict,
        chi2=fit.chi2,
        dof=fit.dof,
        p_value=test_p_value,
        p_value_chi2=fit.p_chi2,
        null_trials=null_trials,
        seed=seed,
        significance=significance,
        n_poses=n,
        reregistered=s.free_names,
        registration=fit.p[s.free].copy(),
        registration_covariance=fit.reg_cov,
        move=move,
        tool_change=tool_change,
        tool_change_std=tool_std,
        residuals=residuals,
        normalised=residuals / res_std,
        pose_chi2=pose_chi2,
        stated_std=res_std,
        excess_std=float(excess),
        rms_error=float(np.sqrt(np.mean(np.sum(residuals**2, axis=1)))),
        model_error_std=np.sqrt(np.clip(np.diag(state.model_error_covariance), 0.0, None)),
        warnings=(f"{s.duplicates} check pose(s) repeated exactly (same joints and measurement): counted once",)
        if s.duplicates
        else (),
        effect_names=tuple(effects),
        effects=effect_values,
        effects_covariance=effect_cov,
        effective_dof=effective_dof(res_std, fit.jac, fit.p, s.q, s.layout, state, fit.r_new, between_names),
        model_error_length_scale=None if s.me_field is None else float(s.me_field.length_scale),
        test="chi-square" if outcome is None else outcome.test,
        p_value_statement=p_value,
        level=level,
        level_dof=level_dof,
        error_ratio=None if outcome is None else outcome.ratio,
        error_ratio_interval=None if outcome is None else outcome.ratio_interval,
        duplicates=s.duplicates,
        level_z=level_z,
        level_trace=level_trace,
        tolerance=tolerance,
    )
