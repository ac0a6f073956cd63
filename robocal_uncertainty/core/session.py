"""Sessions: what one measurement session adds to a robot's calibration, and what checking a new one yields.

A calibration is made in one *session*: the tracker stands somewhere (the measurement frame,
``world_T_base``), a probe is mounted (the tool point). The robot's kinematic parameters are
meant to outlive the session; the registration and the tool may not. :class:`SessionState`
holds what a later session needs (parameter covariance, model error, noise models, the
session's registration with its uncertainty, the :class:`ValidatedLevel` of its own held-out
poses); :class:`Verification` is the outcome of checking a new session against it, with the
:class:`TrackerMove` and the :class:`LevelTest` it reports. These are data: the calibration
file reads and writes them here, in core. What computes them (the session record of a
calibration, the check's re-registration and test, the between-session model) lives in
:mod:`robocal_uncertainty.uncertainty.sessions`; the first-order parameter covariance and gain
of a point calibration, which that package and the model-error field both use, stay here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, stats

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "BASE_NAMES",
    "DEFAULT_NULL_TRIALS",
    "DEFAULT_SIGNIFICANCE",
    "LENGTH_SCALE",
    "MIN_CHECK_DOF",
    "STATEMENT_TOLERANCE",
    "TOOL_NAMES",
    "LevelTest",
    "SessionState",
    "ToleranceCheck",
    "TrackerMove",
    "ValidatedLevel",
    "Verification",
    "effect_jacobian",
    "parameter_covariance",
    "parameter_gain",
]

Array = NDArray[np.float64]
LENGTH_SCALE = "length_scale"
"""Session effect: every joint length parameter (a, d) scaled by ``1 + s`` (temperature)."""
BASE_NAMES: tuple[str, ...] = ("base.x", "base.y", "base.z", "base.roll", "base.pitch", "base.yaw")
TOOL_NAMES: tuple[str, ...] = ("tool.x", "tool.y", "tool.z")
DEFAULT_SIGNIFICANCE = 0.05
"""Level of the check's chi-square test: its false-alarm rate when nothing changed."""
MIN_CHECK_DOF = 6
"""Fewest equations a check must leave after the re-registration (3 n - k)."""
DEFAULT_NULL_TRIALS = 20000
"""Monte Carlo draws of the check statistic under the null hypothesis."""


@dataclass(frozen=True)
class ValidatedLevel:
    """The calibration session's own error level on held-out poses: the reference of ``verify``.

    The campaign is cut into folds, several times over (repeated random splits); each fold is
    predicted by a calibration of the other poses and re-registered as a check would be. Its
    *level* is the mean square error per component left after the re-registration,
    ``r^T P r / m_kept`` with ``P`` the projection off the re-registration (ordinary least
    squares) and ``m_kept = 3 n tr(P C P) / tr(C)`` the equations it keeps (``C`` the stated
    covariance: only its shape enters, through the share a smooth error loses to the
    re-registration), pooled over every fold of every split. A check of a later session is
    compared with this measured level, not with the statement's scale, which a model-error
    field estimated from one campaign hardly fixes.

    Why repeated splits: one split's level depends on which poses happened to share a fold
    (on the UR10 series one 5-fold split scatters 0.21-0.27 in log against the calibration's
    level on all its other poses, three splits 0.17). Why the scatter of the fold levels: a
    level of ``nu`` equations would have relative variance ``2 / nu`` with independent normal
    components; real held-out errors are heavier-tailed, unequal between the axes and
    correlated within a pose, so a level of ten real poses scatters more (about 1.5x on the
    UR10 series). The folds measure it: their levels' relative variance over what ``2 / nu``
    says is the *dispersion*, and every degree of freedom of the test (the check's and this
    level's) is divided by it.

    Attributes
    ----------
    level : float [m^2]
        Pooled mean square error per component after re-registration.
    dof : float
        Degrees of freedom of `level` before the dispersion correction: one split's kept
        equations (every split holds out each pose once: repeating splits steadies the level
        but measures no new pose).
    kurtosis : float
        ``mean(z^4) / mean(z^2)^2`` of the folds' standardised residual components (3 for
        normal errors); kept for the record, and the correction of files written without a
        `dispersion` (``2 / (kurtosis - 1)``).
    folds, poses : int
        Folds per split and held-out poses of one split.
    seed : int
        Seed of the fold splits.
    repeats : int
        Random splits into `folds` folds.
    dispersion : float or None
        Relative variance of the fold levels about `level` over the mean of their ``2 / nu``
        (1 for independent normal components); None in files written before it.
    """

    level: float
    dof: float
    kurtosis: float
    folds: int
    poses: int
    seed: int = 0
    repeats: int = 1
    dispersion: float | None = None

    @property
    def dof_factor(self) -> float:
        """What the degrees of freedom of a level are multiplied by (at most 1).

        ``1 / dispersion`` (the fold levels' scatter against their normal-theory variance);
        for files without a dispersion, ``2 / (kurtosis - 1)``.
        """
        if self.dispersion is not None and self.dispersion > 0.0:
            return float(min(1.0, 1.0 / self.dispersion))
        return float(min(1.0, 2.0 / max(self.kurtosis - 1.0, 1e-9)))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (the calibration file's ``session.validated_level``)."""
        out: dict[str, object] = {
            "level": self.level,
            "dof": self.dof,
            "kurtosis": self.kurtosis,
            "folds": self.folds,
            "poses": self.poses,
            "seed": self.seed,
            "repeats": self.repeats,
        }
        if self.dispersion is not None:
            out["dispersion"] = self.dispersion
        return out

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> ValidatedLevel:
        """Inverse of :meth:`to_dict`."""
        dispersion = data.get("dispersion")
        return cls(
            level=float(data["level"]),  # type: ignore[arg-type]
            dof=float(data["dof"]),  # type: ignore[arg-type]
            kurtosis=float(data["kurtosis"]),  # type: ignore[arg-type]
            folds=int(data["folds"]),  # type: ignore[call-overload]
            poses=int(data["poses"]),  # type: ignore[call-overload]
            seed=int(data.get("seed", 0)),  # type: ignore[call-overload]
            repeats=int(data.get("repeats", 1)),  # type: ignore[call-overload]
            dispersion=None if dispersion is None else float(dispersion),  # type: ignore[arg-type]
        )


@dataclass(frozen=True, eq=False)
class SessionState:
    """What a calibration session leaves for verification and for the next session (SI units).

    Attributes
    ----------
    frame : {"base", "tracker"}
        Frame of the session's measurements.
    frame_id : str
        Name of that frame.
    n_poses : int
        Poses of the calibration campaign.
    covariance_names : tuple of str, length k
        The estimated parameters (those the data determine), order of `parameter_covariance`.
    parameter_covariance : ndarray, shape (k, k) [m^2, m rad, rad^2]
        Covariance of the estimates (linearised, from the stated noise and the model error).
    model_error_covariance : ndarray, shape (3, 3) [m^2]
        Covariance per pose of the error the kinematic model cannot represent, in the robot
        base frame (zeros when the residuals are consistent with the stated noise).
    tracker_noise, encoder_noise
        Noise models stated for the session.
    registration : ndarray, shape (6,) [m, rad]
        ``world_T_base`` of the session (``base.x .. base.yaw``: the robot base in the tracker
        frame); zeros for a base-frame campaign.
    registration_covariance : ndarray, shape (6, 6)
        Its covariance (zeros where not estimated).
    sources : tuple of str
        Uncertainty sources the statement was made with.
    between_session_covariance : ndarray, shape (k_b, k_b) or None
        Between-session covariance of the session effects named by `between_session_names`
        (joint offsets [rad^2], ``length_scale`` [1]) when several sessions were pooled.
    scope : str
        ``"session"`` (statement for the calibration session only) or ``"future sessions"``.
    extra : dict
        Provenance written to and read from the calibration file (campaign, settings, tool
        point, model-adequacy test).
    model_error_draws : ndarray, shape (n, 3) [m] or None
        The calibration's residuals whitened to `model_error_covariance`, robot base frame:
        the model error is resampled from them (its real, heavy-tailed shape), as the
        Monte Carlo's ``residual`` source does. None: normal with that covariance.
    model_error_dof : float or None
        Effective degrees of freedom of the model-error estimate (``2 n / var(m_i)`` with
        ``m_i`` the per-pose Mahalanobis size of the draws over 3): the null distribution of a
        check scales the model error by ``sqrt(nu / chi2_nu)`` per trial, so an estimate from
        few poses widens it as a Student-t does. None: the estimate is taken as exact.
    between_session_names : tuple of str
        Session effects of `between_session_covariance` (see :data:`SESSION_EFFECTS`).
    between_session_dof : float or None
        Degrees of freedom of that estimate (the null scales it as the model error's).
    model_error_field : ModelErrorField or None
        The model error correlated over the configurations (``model_error_covariance`` is then
        its per-pose covariance): a check adds it as one correlated normal over its poses,
        less what the calibration's parameters absorbed of it. None: independent per pose.
    validated_level : ValidatedLevel or None
        The calibration session's own error level on held-out poses: ``verify`` tests a check's
        level against it (an F test) and states the ratio. None (files without it): the
        chi-square test against the statement alone.
    """

    frame: Literal["base", "tracker"]
    frame_id: str
    n_poses: int
    covariance_names: tuple[str, ...]
    parameter_covariance: Array
    model_error_covariance: Array
    tracker_noise: TrackerNoise
    encoder_noise: EncoderNoise
    registration: Array
    registration_covariance: Array
    sources: tuple[str, ...] = ("tracker", "encoder", "residual")
    between_session_covariance: Array | None = None
    scope: str = "session"
    extra: dict[str, object] = field(default_factory=dict)
    model_error_draws: Array | None = None
    model_error_dof: float | None = None
    between_session_names: tuple[str, ...] = ()
    between_session_dof: float | None = None
    model_error_field: ModelErrorField | None = None
    validated_level: ValidatedLevel | None = None

    @property
    def orientation_level(self) -> ValidatedLevel | None:
        """A 6-DOF calibration's own tool-orientation error level on held-out poses [rad^2].

        Recorded in ``extra`` (the file's ``session.orientation_level``); ``verify`` tests a 6-DOF
        check's orientations against it. None for point calibrations and older files.
        """
        data = self.extra.get("orientation_level")
        return ValidatedLevel.from_dict(data) if isinstance(data, dict) else None

    def covariance_of(self, names: tuple[str, ...] | list[str]) -> Array:
        """Sub-block of the parameter covariance for `names` (zero rows for names not estimated)."""
        index = {n: i for i, n in enumerate(self.covariance_names)}
        out = np.zeros((len(names), len(names)))
        have = [(a, index[n]) for a, n in enumerate(names) if n in index]
        for a, i in have:
            for b, j in have:
                out[a, b] = self.parameter_covariance[i, j]
        return out


@dataclass(frozen=True)
class TrackerMove:
    """How far the tracker moved between two registrations, in the robot base frame.

    Attributes
    ----------
    translation : ndarray, shape (3,) [m]
        New tracker position minus old, robot base frame.
    translation_std : ndarray, shape (3,) [m]
    distance, distance_std : float [m]
        Norm of `translation` and its first-order standard uncertainty.
    rotation : ndarray, shape (3,) [rad]
        Rotation vector of ``R_new R_old^T`` (tracker orientation in the base frame).
    rotation_std : ndarray, shape (3,) [rad]
    angle, angle_std : float [rad]
    covariance : ndarray, shape (6, 6)
        Of (translation, rotation).
    """

    translation: Array
    translation_std: Array
    distance: float
    distance_std: float
    rotation: Array
    rotation_std: Array
    angle: float
    angle_std: float
    covariance: Array


@dataclass(frozen=True)
class Verification:
    """Outcome of :func:`~robocal_uncertainty.uncertainty.sessions.verification.verify_session`.

    Attributes
    ----------
    consistent : bool
        True when ``p_value >= significance``.
    verdict : str
        One line: consistent, or drifted with its magnitude.
    chi2, dof, p_value, significance : float
        The test (``dof = 3 n - k``); `p_value` from the Monte Carlo null distribution.
    p_value_chi2 : float
        The chi-square approximation's p-value (normal errors), for comparison.
    null_trials, seed : int
        Draws and seed of the null distribution.
    n_poses : int
    reregistered : tuple of str
        Parameters re-registered on the check (tracker pose, tool point).
    registration : ndarray, shape (k,) [m, rad]
        Their estimates.
    registration_covariance : ndarray, shape (k, k)
    move : TrackerMove or None
        Tracker move from the calibration session (None for a base-frame check).
    tool_change : ndarray, shape (3,) [m] or None
        Re-registered tool point minus the calibrated one.
    tool_change_std : ndarray, shape (3,) [m] or None
    residuals : ndarray, shape (n, 3) [m]
        Measured minus predicted after the re-registration.
    normalised : ndarray, shape (n, 3)
        Residuals over their standard deviation under "nothing changed".
    pose_chi2 : ndarray, shape (n,)
        ``z_i^T z_i`` per pose with the pose's whitened residual block (about chi2 with
        3 (n - k/3)/n degrees of freedom each).
    stated_std : ndarray, shape (n, 3) [m]
        Standard deviation of each residual component under "nothing changed".
    excess_std : float [m]
        Size of the drift: with a validated level, ``sqrt(max(level - validated level, 0))``
        (extra standard deviation per component beyond the calibration's own held-out errors);
        without, the smallest extra per-axis standard deviation that makes the chi-square
        statistic equal its degrees of freedom (0 when chi2 <= dof).
    rms_error : float [m]
        RMS over the poses of the residual norm.
    model_error_std : ndarray, shape (3,) [m]
        Model-error standard uncertainty per axis the check assumed (base frame).
    warnings : tuple of str
    effect_names : tuple of str
    effects : ndarray, shape (k,) or None
        Session effects estimated on the check (what changed since the calibration).
    effects_covariance : ndarray, shape (k, k) or None
    effective_dof : ndarray, shape (n, 3) or None
        Welch-Satterthwaite degrees of freedom of each residual component's standard
        deviation (inf where every part is taken as exact); see :meth:`coverage_factors`.
    model_error_length_scale : float [rad] or None
        Correlation length of the model-error field the check assumed (None: independent
        from pose to pose).
    test : str
        ``"error level"`` (the check's level against the calibration's validated level, an F
        test; `p_value` is its), ``"error level, future session"`` (a t test on the log level
        with the between-session spread of the level) or ``"chi-square"`` (against the
        statement alone, the Monte Carlo null; calibration files without a validated level).
    p_value_statement : float
        The chi-square statistic's Monte Carlo p-value against the statement alone (equal to
        `p_value` for the ``"chi-square"`` test), reported beside the level test.
    level : float [m^2]
        The check's mean square error per kept equation (see :class:`ValidatedLevel`).
    level_dof : float
        Its degrees of freedom before the dispersion correction (``3 n - k``).
    error_ratio : float or None
        ``sqrt(level / validated level)``: the check's errors relative to the calibration
        session's own held-out errors (1: as validated).
    error_ratio_interval : tuple of float or None
        Its 95 % interval (from the F distribution of the two levels).
    duplicates : int
        Check poses dropped as exact repeats of another (same joints and measurement).
    level_z : ndarray, shape (3 n,) or None
        The re-registered residual components over their expected size at `level` (for the
        kurtosis of a :class:`ValidatedLevel`).
    level_trace : float
        The equations `level` is taken over (``m_kept``; pooling weight of fold levels).
    tolerance : ToleranceCheck or None
        The check's level against what the statement tolerates (consistent, drifted or
        inconclusive, with the size a check would need); None without a validated level or
        with a between-session spread of the level (the future-session test).
    orientation : OrientationCheck or None
        A 6-DOF calibration checked on a 6-DOF check: the tool orientations' error level
        against the calibration's (:mod:`~robocal_uncertainty.uncertainty.sessions.orientation`);
        `consistent` then needs both halves, each tested at half the significance. None: the
        positions alone.
    """

    consistent: bool
    verdict: str
    chi2: float
    dof: int
    p_value: float
    p_value_chi2: float
    null_trials: int
    seed: int
    significance: float
    n_poses: int
    reregistered: tuple[str, ...]
    registration: Array
    registration_covariance: Array
    move: TrackerMove | None
    tool_change: Array | None
    tool_change_std: Array | None
    residuals: Array
    normalised: Array
    pose_chi2: Array
    stated_std: Array
    excess_std: float
    rms_error: float
    model_error_std: Array
    warnings: tuple[str, ...] = ()
    effect_names: tuple[str, ...] = ()
    effects: Array | None = None
    effects_covariance: Array | None = None
    effective_dof: Array | None = None
    model_error_length_scale: float | None = None
    test: str = "chi-square"
    p_value_statement: float = float("nan")
    level: float = float("nan")
    level_dof: float = float("nan")
    error_ratio: float | None = None
    error_ratio_interval: tuple[float, float] | None = None
    duplicates: int = 0
    level_z: Array | None = None
    level_trace: float = float("nan")
    tolerance: ToleranceCheck | None = None
    orientation: Any = None  # OrientationCheck (uncertainty.sessions.orientation; core imports no uncertainty)

    def coverage_factors(self, coverage: float = 0.95) -> Array:
        """Per component: the t-quantile for `coverage` with its Welch-Satterthwaite dof, shape (n, 3).

        The components estimated from few observations (the between-session effects, the
        model error) carry their degrees of freedom; the others are taken as exact.
        """
        dof = np.full(self.normalised.shape, np.inf) if self.effective_dof is None else self.effective_dof
        return np.asarray(stats.t.ppf(0.5 + coverage / 2.0, dof), dtype=np.float64)

    def inside(self, coverage: float = 0.95) -> NDArray[np.bool_]:
        """Which residual components lie inside their `coverage` interval, shape (n, 3)."""
        return np.asarray(np.abs(self.normalised) <= self.coverage_factors(coverage))


def effect_jacobian(layout: ParameterLayout, params: Array, joint_positions: Array, names: tuple[str, ...]) -> Array:
    """Derivative of the tool points with respect to session effects, shape (n, 3, k).

    Parameters
    ----------
    layout : ParameterLayout
    params : ndarray, shape (n_params,) [m, rad]
    joint_positions : ndarray, shape (n, n_joints) [rad]
    names : tuple of str
        Joint offsets (``jointN.theta``: a change of the offset) and :data:`LENGTH_SCALE`
        (every joint ``a`` and ``d`` scaled by ``1 + s``).
    """
    _, jac = forward_points_and_jacobian(layout, params, joint_positions)
    out = np.zeros((*jac.shape[:2], len(names)))
    lengths = [idx[k] for idx in layout.joint_slices() for k in ("a", "d")]
    for c, name in enumerate(names):
        if name == LENGTH_SCALE:
            out[:, :, c] = jac[:, :, lengths] @ params[lengths]
        elif name in layout.names:
            out[:, :, c] = jac[:, :, layout.names.index(name)]
        else:
            msg = f"unknown session effect {name!r} (joint offsets jointN.theta or {LENGTH_SCALE})"
            raise ConfigError(msg)
    return out


STATEMENT_TOLERANCE = 0.04
"""How far below 95 % the share of a session's points inside the statement's 95 % region may fall
before the session is *clearly* outside the statement: 95 +- 4 %, the band a statement for a
future session is held to."""


@dataclass(frozen=True)
class ToleranceCheck:
    """A check's error level against what the statement tolerates, three ways.

    The statement (the validated level, Student t on its degrees of freedom) holds for a session
    while about 95 % of its points fall inside its 95 % region; with normal errors that lasts up
    to an error ratio ``r* = t_nu(0.975) / z(0.955)`` (91 % inside, :data:`STATEMENT_TOLERANCE`).
    *drifted*: the check's ratio is beyond ``r*`` (one-sided F test at 5 %); *consistent*: its
    one-sided 95 % upper bound is within ``r*``; *inconclusive*: the check is too small to tell.

    Attributes
    ----------
    verdict : str
        ``"consistent"``, ``"drifted"`` or ``"inconclusive"``.
    tolerated_ratio : float
        ``r*``.
    upper_ratio : float
        One-sided 95 % upper bound of the check's error ratio.
    p_beyond : float
        One-sided p-value of "the ratio is at most ``r*``".
    poses_needed : int or None
        Fewest check poses (same re-registration) whose upper bound stays within ``r*`` when the
        check's errors are the calibration's; None when no size reaches it (the reference level's
        own degrees of freedom are the limit).
    """

    verdict: str
    tolerated_ratio: float
    upper_ratio: float
    p_beyond: float
    poses_needed: int | None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {
            "verdict": self.verdict,
            "rule": "statement's 95 % region holds at least 91 % of the points (95 +- 4 %)",
            "tolerated_error_ratio": self.tolerated_ratio,
            "error_ratio_upper_95": self.upper_ratio,
            "p_beyond_tolerance": self.p_beyond,
            "poses_needed": self.poses_needed,
        }


@dataclass(frozen=True)
class LevelTest:
    """A check's error level tested against a :class:`ValidatedLevel`.

    Computed by :func:`~robocal_uncertainty.uncertainty.sessions.level.level_test`.

    Attributes
    ----------
    test : str
        ``"error level"`` (F test) or ``"error level, future session"`` (t test on the log level).
    p_value : float
        One-sided: the check's errors larger than the reference's.
    check_dof, reference_dof : float
        The F test's degrees of freedom after the reference's dof factor.
    ratio : float
        ``sqrt(level / reference level)``.
    ratio_interval : tuple of float
        Its 95 % interval from the F distribution.
    """

    test: str
    p_value: float
    check_dof: float
    reference_dof: float
    ratio: float
    ratio_interval: tuple[float, float]


def parameter_covariance(
    calibration: IdentificationResult, joint_positions: Array, pose_covariances: Array, *, include_bias: bool = True
) -> Array:
    """Linearised covariance of the estimated parameters of a point calibration.

    The regularised Gauss-Newton solution is, to first order, ``x = G b`` with
    ``G = (A^T A + lambda^2 P)^-1 A^T`` (column-scaled Jacobian ``A`` at the estimate), so
    ``Cov(x) = G C G^T`` with ``C`` the block-diagonal covariance of the measured points
    (stated noise plus model error): the sandwich, valid whatever the weighting.

    Parameters
    ----------
    calibration : IdentificationResult
        A point calibration (unweighted, 3 equations per pose).
    joint_positions : ndarray, shape (n_poses, n_joints) [rad]
    pose_covariances : ndarray, shape (n_poses, 3, 3) or (3 n_poses, 3 n_poses) [m^2]
        Covariance of each measured point in the measurement frame, or of all of them
        (pose-major) when their errors are correlated (a model-error field).

    Returns
    -------
    ndarray, shape (k, k): over the estimated parameters, in ``parameter_names`` order.
    """
    measurement = calibration.measurement
    if measurement.dimension != 3 or measurement.weights is not None:
        msg = "a parameter covariance for a later session needs a point calibration (3 unweighted equations per pose)"
        raise ConfigError(msg)
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    n = joint_positions.shape[0]
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, joint_positions)
    scale = calibration.column_scale[est]
    a_mat = jac.reshape(3 * n, layout.size)[:, est] / scale
    penalty = calibration.lambda_**2 * np.diag(calibration.penalized[est].astype(np.float64))
    gain = np.linalg.solve(a_mat.T @ a_mat + penalty, a_mat.T)
    c_mat = pose_covariances if pose_covariances.ndim == 2 else linalg.block_diag(*pose_covariances)
    cov_x = gain @ c_mat @ gain.T
    if include_bias and calibration.lambda_ > 0.0:
        # First-order Tikhonov shrinkage -(A^T A + P)^-1 P x, evaluated at x_hat: a systematic
        # error of the estimate the sandwich does not hold (see uncertainty.calibration.gum.regularisation_bias).
        x_hat = (calibration.estimate - calibration.nominal)[est] * scale
        bias = -np.linalg.solve(a_mat.T @ a_mat + penalty, penalty @ x_hat)
        cov_x = cov_x + np.outer(bias, bias)
    cov = cov_x / np.outer(scale, scale)
    return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)


def parameter_gain(calibration: IdentificationResult, joint_positions: Array) -> Array:
    """First-order change of the estimated parameters per measured point error, shape (k, 3 n).

    ``G = D^-1 (A^T A + lambda^2 P)^-1 A^T`` (column scale ``D``), pose-major columns in the
    measurement frame, rows over the estimated parameters (``parameter_names`` order) [m/m, rad/m].
    """
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    n = joint_positions.shape[0]
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, joint_positions)
    scale = calibration.column_scale[est]
    a_mat = jac.reshape(3 * n, layout.size)[:, est] / scale
    penalty = calibration.lambda_**2 * np.diag(calibration.penalized[est].astype(np.float64))
    gain = np.linalg.solve(a_mat.T @ a_mat + penalty, a_mat.T)
    return np.asarray(gain / scale[:, None], dtype=np.float64)
