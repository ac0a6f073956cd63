"""Sessions: what one measurement session adds to a robot's calibration, and the check of a new one.

A calibration is made in one *session*: the tracker stands somewhere (the measurement frame,
``world_T_base``), a probe is mounted (the tool point). The robot's kinematic parameters are
meant to outlive the session; the registration and the tool may not. :class:`SessionState`
holds what a later session needs (parameter covariance, model error, noise models, the
session's registration with its uncertainty); :func:`verify_session` takes a short check
campaign from a new session, re-registers the new measurement frame (and optionally the tool
point) by generalised least squares, and tests whether the robot still agrees with its
calibration within the stated uncertainty.

The test. With ``y`` the check points (n x 3, new tracker frame), ``f(theta)`` the calibrated
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
the estimate's degrees of freedom. The GLS estimate ``theta_hat``
minimises ``r^T C^-1 r`` and the statistic ``chi2 = r^T C^-1 r`` at the minimum follows a
chi-square with ``3 n - k`` degrees of freedom (``k`` = rank of the re-registration
Jacobian: the degrees of freedom the re-registration used are taken off). The check is
*consistent* when its p-value is at least the significance level (the false-alarm rate).

When the calibration records a :class:`ValidatedLevel` (its own held-out error level, measured
on folds of its campaign re-registered as a check), the verdict is the *level test* instead:
the check's mean square error per component after an ordinary least-squares re-registration
against that level, an F test, with the ratio ("errors 1.6x the calibration session's") and its
interval. Why: on real sessions the statement's model-error field has a scale fixed by one to a
few degrees of freedom (its correlation length runs to its bound), so the chi-square's null
distribution above is so wide that a session with twice the errors reads consistent at every
check size; the level is measured, not stated. The chi-square p-value is still reported.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, stats

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, fit_rigid_base
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import joint_columns
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.errors import ConfigError, IdentifiabilityError, InputError

__all__ = [
    "BASE_NAMES",
    "DEFAULT_SIGNIFICANCE",
    "LENGTH_SCALE",
    "MIN_CHECK_DOF",
    "TOOL_NAMES",
    "LevelTest",
    "SessionState",
    "TrackerMove",
    "ValidatedLevel",
    "Verification",
    "check_level",
    "effect_jacobian",
    "level_test",
    "parameter_covariance",
    "parameter_gain",
    "tracker_move",
    "verify_session",
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
_DEGENERATE_RCOND = 1e-7
DEFAULT_NULL_TRIALS = 20000
"""Monte Carlo draws of the check statistic under the null hypothesis."""
_NULL_BLOCK = 4096
_MAX_ITERATIONS = 30


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
    """Outcome of :func:`verify_session`.

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


def _check_campaign(model: RobotModel, campaign: Campaign, retool: bool) -> tuple[Campaign, Array, int]:
    if not isinstance(campaign, Campaign):
        msg = f"check campaign must be a Campaign, got {type(campaign).__name__}"
        raise InputError(msg)
    campaign = campaign.reorder_joints(model.joint_names)
    positions = campaign.measurement.positions(campaign.points)
    if positions is None:
        msg = f"check campaign holds no 3-D positions ({campaign.measurement.quantity}): cannot verify"
        raise InputError(msg)
    k = (6 if campaign.frame == "tracker" else 0) + (3 if retool else 0)
    need = int(np.ceil((k + MIN_CHECK_DOF) / 3))
    if campaign.n_poses < need:
        what = "the tracker pose" + (" and the tool point" if retool else "") if k else "nothing"
        msg = (
            f"check campaign too small: {campaign.n_poses} poses give {3 * campaign.n_poses} equations; "
            f"re-registering {what} takes {k}, and the test needs at least {MIN_CHECK_DOF} more "
            f"(measure at least {need} poses, 5-20 spread over the workspace)"
        )
        raise IdentifiabilityError(msg)
    return campaign, np.asarray(positions, dtype=np.float64), k


def _pose_noise(
    jac: Array,
    theta_cols: list[int],
    distances: Array,
    tracker: TrackerNoise,
    encoder: EncoderNoise,
    prismatic: tuple[bool, ...] = (),
) -> Array:
    """Per-pose covariance of tracker and encoder noise, shape (n, 3, 3) [m^2]."""
    cov = encoder.covariance(jac[:, :, theta_cols], prismatic)
    cov += np.eye(3) * (tracker.std(distances) ** 2)[:, None, None]
    return cov


def _effective_dof(
    res_std: Array,
    jac: Array,
    params: Array,
    q: Array,
    layout: ParameterLayout,
    state: SessionState,
    rotation: Array,
    between_names: tuple[str, ...] | None,
) -> Array:
    """Welch-Satterthwaite dof of each residual component's variance, shape (n, 3).

    Parts with finite dof: the model error (``state.model_error_dof``) and each group of
    between-session effects (joint offsets, length scale; ``state.between_session_dof`` for the
    smaller group, the group sizes' ratio for the other). The rest of the variance is exact.
    """
    n = res_std.shape[0]
    total = res_std**2
    parts: list[tuple[Array, float]] = []
    if state.model_error_dof is not None and np.isfinite(state.model_error_dof):
        me = np.diag(rotation @ state.model_error_covariance @ rotation.T)
        parts.append((np.broadcast_to(me, (n, 3)), float(state.model_error_dof)))
    if between_names and state.between_session_covariance is not None and state.between_session_dof is not None:
        g = effect_jacobian(layout, params, q, between_names)
        groups = {nm == LENGTH_SCALE for nm in between_names}
        sizes = {key: sum(1 for nm in between_names if (nm == LENGTH_SCALE) == key) for key in groups}
        per_effect = float(state.between_session_dof) / min(sizes.values())
        for key in groups:
            cols = [c for c, nm in enumerate(between_names) if (nm == LENGTH_SCALE) == key]
            sub = state.between_session_covariance[np.ix_(cols, cols)]
            var = np.einsum("pik,kl,pil->pi", g[:, :, cols], sub, g[:, :, cols])
            parts.append((var, per_effect * sizes[key]))
    if not parts:
        return np.full((n, 3), np.inf)
    denominator = sum(np.minimum(var, total) ** 2 / dof for var, dof in parts)
    with np.errstate(divide="ignore"):
        return np.asarray(np.where(denominator > 0, total**2 / denominator, np.inf), dtype=np.float64)


def _sqrt_psd(matrix: Array) -> Array:
    evals, evecs = np.linalg.eigh(matrix)
    return np.asarray(evecs * np.sqrt(np.clip(evals, 0.0, None)), dtype=np.float64)


def _chol(matrix: Array) -> Array:
    return np.asarray(np.linalg.cholesky(matrix), dtype=np.float64)


def _gls_chi2(r: Array, chol: Array, a_mat: Array) -> float:
    """``r^T C^-1 r`` minus the part the re-registration columns explain (C = chol chol^T)."""
    rw = linalg.solve_triangular(chol, r, lower=True)
    if a_mat.shape[1] == 0:
        return float(rw @ rw)
    aw = linalg.solve_triangular(chol, a_mat, lower=True)
    q, _ = np.linalg.qr(aw)
    rw = rw - q @ (q.T @ rw)
    return float(rw @ rw)


def _null_statistics(
    trials: int,
    seed: int,
    chol: Array,
    a_mat: Array,
    distances: Array,
    tracker: TrackerNoise,
    encoder: EncoderNoise,
    joint_jacobian: Array,
    model_error: Array,
    kin_jacobian: Array,
    kin_covariance: Array,
    model_error_draws: Array | None = None,
    model_error_dof: float | None = None,
    between_factor: Array | None = None,
    between_dof: float | None = None,
    prismatic: tuple[bool, ...] = (),
    correlated_factor: Array | None = None,
    correlated_dof: float | None = None,
) -> Array:
    """The check statistic for `trials` draws of the errors "nothing changed" allows, shape (trials,).

    Blocks of :data:`_NULL_BLOCK` draws, each from its own ``SeedSequence(seed).spawn`` child:
    the draws do not depend on anything but the seed and the count. `correlated_factor`
    (``F F^T`` = covariance over all the poses of a correlated model error and the parameter
    errors, shape (3 n, r)) is drawn normal and scaled by ``sqrt(nu / chi2_nu)`` per draw with
    ``nu`` = `correlated_dof`.
    """
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 100:
        msg = f"null_trials must be an integer >= 100, got {trials!r}"
        raise ConfigError(msg)
    n = distances.size
    n_joints = joint_jacobian.shape[-1]
    if a_mat.shape[1]:
        aw = linalg.solve_triangular(chol, a_mat, lower=True)
        q_mat, _ = np.linalg.qr(aw)
    else:
        q_mat = np.zeros((3 * n, 0))
    me_sqrt = np.linalg.cholesky(model_error + 1e-30 * np.eye(3)) if np.any(model_error) else None
    k_sqrt = None
    if kin_jacobian.shape[1]:
        evals, evecs = np.linalg.eigh(kin_covariance)
        k_sqrt = kin_jacobian @ (evecs * np.sqrt(np.clip(evals, 0.0, None)))
    n_blocks = -(-trials // _NULL_BLOCK)
    out = np.empty(trials)
    for b, child in enumerate(np.random.SeedSequence(seed).spawn(n_blocks)):
        rng = np.random.default_rng(child)
        m = min(_NULL_BLOCK, trials - b * _NULL_BLOCK)
        e = tracker.sample(rng, np.broadcast_to(distances, (m, n)))
        dq = encoder.sample_joints(rng, (m, n, n_joints), prismatic)
        e = e + np.einsum("pij,tpj->tpi", joint_jacobian, dq)
        me = None
        if model_error_draws is not None and model_error_draws.shape[0]:
            me = model_error_draws[rng.integers(0, model_error_draws.shape[0], size=(m, n))]
        elif me_sqrt is not None:
            me = rng.standard_normal((m, n, 3)) @ me_sqrt.T
        if me is not None:
            if model_error_dof is not None and np.isfinite(model_error_dof):
                me = me * np.sqrt(model_error_dof / rng.chisquare(model_error_dof, size=m))[:, None, None]
            e = e + me
        flat = e.reshape(m, 3 * n)
        if between_factor is not None:
            shift = rng.standard_normal((m, between_factor.shape[1])) @ between_factor.T
            if between_dof is not None and np.isfinite(between_dof):
                shift = shift * np.sqrt(between_dof / rng.chisquare(between_dof, size=m))[:, None]
            flat = flat + shift
        if k_sqrt is not None:
            flat = flat + rng.standard_normal((m, k_sqrt.shape[1])) @ k_sqrt.T
        if correlated_factor is not None:
            shift = rng.standard_normal((m, correlated_factor.shape[1])) @ correlated_factor.T
            if correlated_dof is not None and np.isfinite(correlated_dof):
                shift = shift * np.sqrt(correlated_dof / rng.chisquare(correlated_dof, size=m))[:, None]
            flat = flat + shift
        w = linalg.solve_triangular(chol, flat.T, lower=True)
        w = w - q_mat @ (q_mat.T @ w)
        out[b * _NULL_BLOCK : b * _NULL_BLOCK + m] = np.sum(w * w, axis=0)
    return out


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
        :func:`effect_jacobian`) in one linear GLS step with it: what changed since the
        calibration, with its covariance (``Verification.effects``); they do not enter the test.

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
    if model.tool_rotation:
        model = dataclasses.replace(model, tool_rotation=False)
    campaign, y, duplicates = _unique_poses(*_check_campaign(model, campaign, retool)[:2])
    try:
        _check_campaign(model, campaign, retool)
    except IdentifiabilityError as err:
        msg = f"{duplicates} check pose(s) repeat another exactly and count once: {err}"
        raise IdentifiabilityError(msg) from err
    tracker = tracker_noise or state.tracker_noise
    encoder = encoder_noise or state.encoder_noise
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
    free = np.array([names.index(nm) for nm in free_names], dtype=np.intp)
    kin_names = tuple(nm for nm in state.covariance_names if nm not in free_names and not nm.startswith("base."))
    kin_names = tuple(nm for nm in kin_names if nm in names)
    kin = np.array([names.index(nm) for nm in kin_names], dtype=np.intp)
    sigma_k = state.covariance_of(kin_names)
    me_field = state.model_error_field
    if me_field is not None and me_field.joint_positions.shape[1] != q.shape[1]:
        msg = f"the model-error field has {me_field.joint_positions.shape[1]} joints, the check {q.shape[1]}"
        raise InputError(msg)
    theta_cols = joint_columns(layout)
    distances = np.linalg.norm(y, axis=1) if campaign.frame == "tracker" else np.full(n, 2.0)
    scale = np.ones(free.size)
    between = state.between_session_covariance if state.between_session_names else None

    def covariance(jac: Array, params: Array) -> Array:
        cov = linalg.block_diag(*_pose_noise(jac, theta_cols, distances, tracker, encoder, model.prismatic))
        cov = cov + correlated(jac, params)
        if between is not None:
            g = effect_jacobian(layout, params, q, state.between_session_names).reshape(3 * n, -1)
            cov = cov + g @ between @ g.T
        return np.asarray(cov, dtype=np.float64)

    def correlated(jac: Array, params: Array) -> Array:
        """Model error and calibration parameter errors over the poses, shape (3 n, 3 n) [m^2]."""
        r_wb = rpy_to_matrix(params[b0 + 3 : b0 + 6])
        jk = jac[:, :, kin].reshape(3 * n, kin.size)
        if me_field is None:
            cov = linalg.block_diag(*([r_wb @ state.model_error_covariance @ r_wb.T] * n))
        else:
            cov = me_field.prediction_covariance(q, state.model_error_covariance, r_wb, jk, kin_names)
        if kin.size:
            cov = cov + jk @ sigma_k @ jk.T
        return np.asarray(cov, dtype=np.float64)

    pred, jac = forward_points_and_jacobian(layout, p, q)
    a_mat = jac[:, :, free].reshape(3 * n, free.size)
    if free.size:
        scale = np.linalg.norm(a_mat, axis=0)
        s = np.linalg.svd(a_mat / scale, compute_uv=False)
        if s[-1] <= _DEGENERATE_RCOND * s[0]:
            msg = (
                f"degenerate check campaign: its {n} poses cannot re-register "
                f"{'the tracker pose' if campaign.frame == 'tracker' else ''}"
                f"{' and ' if campaign.frame == 'tracker' and retool else ''}{'the tool point' if retool else ''} "
                "(the tool points must span the workspace and the wrist must turn between poses)"
            )
            raise IdentifiabilityError(msg)
    chol = _chol(covariance(jac, p))
    for _ in range(_MAX_ITERATIONS):
        r = (y - pred).reshape(3 * n)
        if not free.size:
            break
        aw = linalg.solve_triangular(chol, a_mat / scale, lower=True)
        rw = linalg.solve_triangular(chol, r, lower=True)
        step = np.linalg.lstsq(aw, rw, rcond=None)[0] / scale
        p[free] += step
        pred, jac = forward_points_and_jacobian(layout, p, q)
        a_mat = jac[:, :, free].reshape(3 * n, free.size)
        chol = np.asarray(np.linalg.cholesky(covariance(jac, p)), dtype=np.float64)
        if np.max(np.abs(step * scale)) < 1e-12 + 1e-10 * np.max(np.abs(p[free] * scale)):
            break
    r = (y - pred).reshape(3 * n)
    c_mat = chol @ chol.T
    if free.size:
        aw = linalg.solve_triangular(chol, a_mat / scale, lower=True)
        rank = int(np.linalg.matrix_rank(aw))
        cov_scaled = np.linalg.pinv(aw.T @ aw)
        reg_cov = cov_scaled / np.outer(scale, scale)
    else:
        rank = 0
        reg_cov = np.zeros((0, 0))
    dof = 3 * n - rank
    chi2 = _gls_chi2(r, chol, a_mat)
    p_chi2 = float(stats.chi2.sf(chi2, dof))
    r_new = rpy_to_matrix(p[b0 + 3 : b0 + 6])
    between_factor = (
        None
        if between is None
        else effect_jacobian(layout, p, q, state.between_session_names).reshape(3 * n, -1) @ _sqrt_psd(between)
    )
    if me_field is None:
        null = _null_statistics(
            null_trials,
            seed,
            chol,
            a_mat,
            distances,
            tracker,
            encoder,
            jac[:, :, theta_cols],
            r_new @ state.model_error_covariance @ r_new.T,
            jac[:, :, kin].reshape(3 * n, kin.size) if kin.size else np.zeros((3 * n, 0)),
            sigma_k,
            None if state.model_error_draws is None else state.model_error_draws @ r_new.T,
            state.model_error_dof,
            between_factor,
            state.between_session_dof,
            prismatic=model.prismatic,
        )
    else:
        # The correlated model error and the parameter errors it drives: one normal over all
        # the poses, its estimated scale widened by the estimate's degrees of freedom.
        null = _null_statistics(
            null_trials,
            seed,
            chol,
            a_mat,
            distances,
            tracker,
            encoder,
            jac[:, :, theta_cols],
            np.zeros((3, 3)),
            np.zeros((3 * n, 0)),
            np.zeros((0, 0)),
            None,
            None,
            between_factor,
            state.between_session_dof,
            prismatic=model.prismatic,
            correlated_factor=_sqrt_psd(correlated(jac, p)),
            correlated_dof=state.model_error_dof,
        )
    p_value = float((1 + np.count_nonzero(null >= chi2)) / (1 + null.size))
    p_statement = p_value
    # The level's shape: stated noise, plus the calibration parameter errors when they come from
    # that noise alone. A parameter covariance driven by a model error carries its field's
    # correlation length, which one campaign hardly fixes (on the UR10 series B and D it made a
    # 2x session read 1x); there the shape is the noise's.
    shape = linalg.block_diag(*_pose_noise(jac, theta_cols, distances, tracker, encoder, model.prismatic))
    if kin.size and not np.any(state.model_error_covariance):
        jk_flat = jac[:, :, kin].reshape(3 * n, kin.size)
        shape = shape + jk_flat @ sigma_k @ jk_flat.T
    level, level_dof, level_z, level_trace = _level(r, a_mat, np.asarray(shape, dtype=np.float64))
    reference = state.validated_level
    ratio = ratio_interval = None
    nu_c = nu_r = float("nan")
    test = "chi-square"
    if reference is not None and reference.level > 0.0:
        between_level = state.extra.get("between_session")
        outcome = level_test(
            level, level_dof, reference, dict(between_level) if isinstance(between_level, dict) else None
        )
        test, p_value, nu_c, nu_r = outcome.test, outcome.p_value, outcome.check_dof, outcome.reference_dof
        ratio, ratio_interval = outcome.ratio, outcome.ratio_interval
    res_cov = c_mat - a_mat @ reg_cov @ a_mat.T
    res_std = np.sqrt(np.clip(np.diag(res_cov), 1e-30, None)).reshape(n, 3)
    residuals = r.reshape(n, 3)
    normalised = residuals / res_std
    pose_chi2 = np.empty(n)
    for i in range(n):
        block = res_cov[3 * i : 3 * i + 3, 3 * i : 3 * i + 3]
        pose_chi2[i] = float(residuals[i] @ np.linalg.pinv(block, rcond=1e-10) @ residuals[i])
    rms = float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))
    move = None
    if campaign.frame == "tracker" and state.frame == "tracker":
        move = tracker_move(p[b0 : b0 + 6], reg_cov[:6, :6], state.registration, state.registration_covariance)
    tool_change = tool_std = None
    if retool:
        t0 = layout.tool_index
        k0 = free_names.index("tool.x")
        tool_change = p[t0 : t0 + 3] - model.tool_point
        tool_cov = reg_cov[k0 : k0 + 3, k0 : k0 + 3] + state.covariance_of(TOOL_NAMES)
        tool_std = np.sqrt(np.clip(np.diag(tool_cov), 0.0, None))
    excess = 0.0
    if chi2 > dof:
        lo, hi = 0.0, float(np.sqrt(np.mean(residuals**2))) + 1e-9
        while _gls_chi2(r, _chol(c_mat + hi**2 * np.eye(3 * n)), a_mat) > dof:
            hi *= 2.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if _gls_chi2(r, _chol(c_mat + mid**2 * np.eye(3 * n)), a_mat) > dof:
                lo = mid
            else:
                hi = mid
        excess = hi
    consistent = p_value >= significance
    if ratio is not None and ratio_interval is not None:
        size = (
            f"errors {ratio:.2f}x the calibration session's (95 % interval {ratio_interval[0]:.2f}-"
            f"{ratio_interval[1]:.2f}; "
            + (
                f"F test on {nu_c:.0f} and {nu_r:.0f} degrees of freedom"
                if test == "error level"
                else "t test on the log level with the between-session spread"
            )
            + f", p = {p_value:.3g} {'>=' if consistent else '<'} {significance:g})"
        )
        # The drift's size: the extra standard deviation per component beyond the calibration
        # session's own validated level.
        assert reference is not None
        excess = float(np.sqrt(max(level - reference.level, 0.0)))
        verdict = (
            f"consistent: the robot agrees with its calibration within the stated uncertainty: {size}"
            if consistent
            else f"drifted: the robot deviates from its calibration by about {excess * 1e3:.3g} mm per axis "
            f"beyond its validated error level: {size}; re-calibrate"
        )
    elif consistent:
        verdict = (
            f"consistent: the robot agrees with its calibration within the stated uncertainty "
            f"(chi2 = {chi2:.3g} on {dof} degrees of freedom, p = {p_value:.3g} >= {significance:g})"
        )
    else:
        verdict = (
            f"drifted: the robot deviates from its calibration by about {excess * 1e3:.3g} mm per axis "
            f"beyond the stated uncertainty (chi2 = {chi2:.3g} on {dof} degrees of freedom, "
            f"p = {p_value:.3g} < {significance:g}); re-calibrate"
        )
    warns: list[str] = []
    if duplicates:
        warns.append(f"{duplicates} check pose(s) repeated exactly (same joints and measurement): counted once")
    effective_dof = _effective_dof(
        res_std, jac, p, q, layout, state, r_new, None if between is None else state.between_session_names
    )
    effect_values = effect_cov = None
    if effects:
        g = effect_jacobian(layout, p, q, effects).reshape(3 * n, len(effects))
        full = np.concatenate((a_mat, g), axis=1)
        col = np.linalg.norm(full, axis=0)
        col[col == 0] = 1.0
        fw = linalg.solve_triangular(chol, full / col, lower=True)
        inv = np.linalg.pinv(fw.T @ fw) / np.outer(col, col)
        step = inv @ (full.T @ linalg.cho_solve((chol, True), r))
        effect_values = step[free.size :]
        effect_cov = inv[free.size :, free.size :]
    return Verification(
        consistent=consistent,
        verdict=verdict,
        chi2=chi2,
        dof=dof,
        p_value=p_value,
        p_value_chi2=p_chi2,
        null_trials=null_trials,
        seed=seed,
        significance=float(significance),
        n_poses=n,
        reregistered=tuple(free_names),
        registration=p[free].copy(),
        registration_covariance=reg_cov,
        move=move,
        tool_change=tool_change,
        tool_change_std=tool_std,
        residuals=residuals,
        normalised=normalised,
        pose_chi2=pose_chi2,
        stated_std=res_std,
        excess_std=float(excess),
        rms_error=rms,
        model_error_std=np.sqrt(np.clip(np.diag(state.model_error_covariance), 0.0, None)),
        warnings=tuple(warns),
        effect_names=tuple(effects),
        effects=effect_values,
        effects_covariance=effect_cov,
        effective_dof=effective_dof,
        model_error_length_scale=None if me_field is None else float(me_field.length_scale),
        test=test,
        p_value_statement=p_statement,
        level=level,
        level_dof=level_dof,
        error_ratio=ratio,
        error_ratio_interval=ratio_interval,
        duplicates=duplicates,
        level_z=level_z,
        level_trace=level_trace,
    )


def _unique_poses(campaign: Campaign, y: Array) -> tuple[Campaign, Array, int]:
    """The check without exact repeats (same joints and measured point): a pose counts once."""
    rows = np.concatenate((campaign.joint_positions, y), axis=1)
    _, first = np.unique(rows, axis=0, return_index=True)
    if first.size == campaign.n_poses:
        return campaign, y, 0
    keep = np.sort(first)
    return campaign.subset(keep), y[keep], int(campaign.n_poses - keep.size)


def _level(r: Array, a_mat: Array, shape: Array) -> tuple[float, float, Array, float]:
    """``r^T P r / m_kept`` [m^2], its degrees of freedom, the standardised ``P r`` and ``m_kept``.

    ``P`` projects off the re-registration (ordinary least squares: the level does not lean on
    the stated covariance to weight the poses); ``m_kept = 3 n tr(P S P) / tr(S)`` with ``S``
    the stated noise (and calibration-parameter) covariance: the share of the error a
    re-registration of few poses absorbs (the parameter errors are smooth over the poses) is
    taken off, so a fold of 10 poses and a check of 50 measure the same level.
    """
    m = r.size
    if a_mat.shape[1]:
        q_mat, _ = np.linalg.qr(a_mat / np.linalg.norm(a_mat, axis=0))
        rank = int(np.linalg.matrix_rank(a_mat / np.linalg.norm(a_mat, axis=0)))
        q_mat = q_mat[:, :rank]
        proj = np.eye(m) - q_mat @ q_mat.T
    else:
        proj = np.eye(m)
    rp = proj @ r
    # Degrees of freedom 3 n - k (before the dispersion factor). The stated field's own account
    # (the share of a smooth error the projection takes, Satterthwaite's t1^2 / t2) leans on
    # its correlation length, which one campaign hardly fixes (it ran to its bound on the UR10
    # series): it made the level unstable between calibrations of one series and the power of
    # 200-pose checks lower than of 10-pose ones. What correlation and tails the real errors
    # have shows in the scatter of the calibration's fold levels (ValidatedLevel.dispersion).
    dof = float(m - (np.linalg.matrix_rank(a_mat) if a_mat.shape[1] else 0))
    trace = float(np.trace(shape))
    kept = m * float(np.trace(proj @ shape @ proj)) / trace if trace > 0.0 else dof
    level = float(rp @ rp) / kept
    # Standardised components (for the kurtosis): each over its own expected size.
    z = rp / np.sqrt(np.clip(np.diag(proj), 1e-12, None) * max(level, 1e-300))
    return level, dof, np.asarray(z, dtype=np.float64), kept


@dataclass(frozen=True)
class LevelTest:
    """A check's error level tested against a :class:`ValidatedLevel` (:func:`level_test`).

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


def level_test(
    level: float, level_dof: float, reference: ValidatedLevel, between: dict[str, object] | None = None
) -> LevelTest:
    """Test a check's error level against the calibration session's validated level.

    ``level / reference.level`` is F distributed with ``(level_dof f, reference.dof f)`` degrees
    of freedom when nothing changed, ``f`` = :attr:`ValidatedLevel.dof_factor` (the dispersion
    the folds showed). With a between-session spread of the level (`between`'s
    ``level_log_std`` over ``level_dof`` degrees of freedom) the statement is for a future
    session: a t test on the log level with Welch-Satterthwaite degrees of freedom.

    Parameters
    ----------
    level : float [m^2]
        The check's mean square error per kept equation.
    level_dof : float
        Its degrees of freedom before the factor (``3 n - k``).
    reference : ValidatedLevel
    between : dict, optional
        The calibration file's ``between_session`` record.
    """
    factor = reference.dof_factor
    nu_c, nu_r = max(level_dof * factor, 1e-3), max(reference.dof * factor, 1e-3)
    t_stat = level / reference.level
    test = "error level"
    p_value = float(stats.f.sf(t_stat, nu_c, nu_r))
    log_std = (between or {}).get("level_log_std")
    if isinstance(log_std, (int, float)) and float(log_std) > 0.0:
        # A future session: its error level varies from session to session (log standard
        # deviation tau over S - 1 degrees of freedom).
        test = "error level, future session"
        parts = np.array([2.0 / nu_c, 2.0 / nu_r, float(log_std) ** 2])
        between_dof_raw = (between or {}).get("level_dof", 1.0)
        between_dof = float(between_dof_raw) if isinstance(between_dof_raw, (int, float)) else 1.0
        dofs = np.array([nu_c, nu_r, max(between_dof, 1.0)])
        welch = float(np.sum(parts) ** 2 / np.sum(parts**2 / dofs))
        p_value = float(stats.t.sf(np.log(t_stat) / np.sqrt(np.sum(parts)), welch))
    interval = (
        float(np.sqrt(t_stat / stats.f.ppf(0.975, nu_c, nu_r))),
        float(np.sqrt(t_stat / stats.f.ppf(0.025, nu_c, nu_r))),
    )
    return LevelTest(test, p_value, float(nu_c), float(nu_r), float(np.sqrt(t_stat)), interval)


def check_level(verifications: list[Verification], *, seed: int = 0, repeats: int = 1) -> ValidatedLevel:
    """Pool held-out fold checks of the calibration session into its :class:`ValidatedLevel`.

    Parameters
    ----------
    verifications : list of Verification
        The fold checks of `repeats` splits (each split holds out every pose once).
    seed : int
        Seed of the splits (recorded).
    repeats : int
        Splits the folds come from.

    The pooled level is the folds' squared residuals over their kept equations (a mean square
    per component [m^2]); its degrees of freedom are one split's summed; the dispersion is the
    fold levels' relative variance about the pooled level over the mean of their normal-theory
    ``2 / nu`` (at least two folds; 1 with one).
    """
    if not verifications:
        raise IdentifiabilityError("no held-out fold to validate the calibration's error level on")
    if repeats < 1 or len(verifications) % repeats:
        msg = f"{len(verifications)} fold checks cannot come from {repeats} splits"
        raise ConfigError(msg)
    num = den = dof = 0.0
    zs = []
    for v in verifications:
        num += v.level * v.level_trace
        den += v.level_trace
        dof += v.level_dof
        if v.level_z is not None:
            zs.append(v.level_z)
    z = np.concatenate(zs) if zs else np.zeros(0)
    kurt = float(np.mean(z**4) / np.mean(z**2) ** 2) if z.size else 3.0
    level = num / den
    levels = np.array([v.level for v in verifications])
    dispersion = None
    if levels.size > 1 and level > 0.0:
        # The fold levels scatter more than their normal-theory 2 / nu when the held-out
        # errors are heavy-tailed, unequal between the axes or correlated within a pose (and
        # by the calibrations of the folds differing): measured, not assumed.
        observed = float(np.sum((levels / level - 1.0) ** 2)) / (levels.size - 1)
        stated = float(np.mean([2.0 / max(v.level_dof, 1e-9) for v in verifications]))
        dispersion = observed / stated
    return ValidatedLevel(
        level=level,
        dof=dof / repeats,
        kurtosis=kurt,
        folds=len(verifications) // repeats,
        poses=int(sum(v.n_poses for v in verifications)) // repeats,
        seed=seed,
        repeats=repeats,
        dispersion=dispersion,
    )


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
