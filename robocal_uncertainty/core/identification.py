"""Identification of kinematic parameter errors by regularised Gauss-Newton.

Each iteration linearises the measurements (points by default; any
:class:`~robocal_uncertainty.core.measurement.MeasurementType`, whitened by its weights) around
the current estimate and takes the robot paper's (Jiang et al.) Tikhonov step
``E = (U^T U + Gamma^T Gamma)^-1 U^T dS`` with ``Gamma = lambda I`` on a column-scaled Jacobian
(metres and radians do not mix unscaled). The penalty acts on the whole deviation from the
nominal model, so the iteration converges to the minimiser of
``||S - F(p)||^2 + lambda^2 ||D (p - p_nominal)||^2`` rather than drifting.
Lambda is chosen at the L-curve corner (default), by GCV, or fixed.
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Literal, cast

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import POINT, MeasurementType, stack_equations, stack_jacobian, stack_residual
from robocal_uncertainty.core.observability import Observability, structural_observability
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.regularization import LCurve, lcurve
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_from_matrix, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError, ConvergenceError, IdentifiabilityError, InputError

__all__ = [
    "HELD_STD_RATIO",
    "IDENTIFICATION_MESSAGES",
    "WEIGHTINGS",
    "IdentificationResult",
    "LambdaMethod",
    "Weighting",
    "fit_rigid_base",
    "identify",
    "residual_stats",
]

Array = NDArray[np.float64]
LambdaMethod = Literal["lcurve", "gcv", "fixed"]
Weighting = Literal["none", "stated", "variance_components"]
WEIGHTINGS: tuple[str, ...] = ("variance_components", "stated")
"""Choices of :func:`identify`'s ``weighting`` (the first is the default)."""

IDENTIFICATION_MESSAGES: dict[int, str] = {
    0: "converged: parameter step below tolerance",
    1: "stopped: maximum number of iterations reached before the step fell below tolerance",
}
_DEGENERATE_RCOND = 1e-10
HELD_STD_RATIO = 10.0
"""A parameter whose data-only standard uncertainty exceeds this multiple of the stated
(regularised) one is held by the Tikhonov term, not measured by the data."""


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`. Arrays over parameters follow ``parameter_names``.

    Attributes
    ----------
    model : RobotModel
        The calibrated model (nominal model with the estimate applied).
    parameter_names : tuple of str, length n_params
    nominal : ndarray, shape (n_params,) [m, rad]
        Starting values (the base may come from a rigid fit, see ``base_initialised``).
    estimate : ndarray, shape (n_params,) [m, rad]
        Identified values; parameters not estimated keep their nominal value.
    estimated : ndarray of bool, shape (n_params,)
        Parameters that were estimated (identifiable candidates).
    identifiable : ndarray of bool, shape (n_params,)
        Candidates that the campaign's measurements can identify; same as ``estimated``.
    candidates : ndarray of bool, shape (n_params,)
        Parameters that were asked for (the base only when measurements are in a tracker
        frame).
    dependencies : tuple of str
        Why each candidate is not identifiable (the combination it duplicates).
    linearized_std : ndarray, shape (n_params,) [m, rad]
        First-order standard uncertainty of each estimate from the residual scatter
        (NaN where not estimated); the Monte Carlo gives the full statement.
    data_only_std : ndarray, shape (n_params,) [m, rad]
        The same from the data alone, without the Tikhonov term (lambda = 0 at the
        solution's linearisation): ``inf`` where the data carry no information on the
        parameter, NaN where not estimated.
    data_share : ndarray, shape (n_params,)
        Diagonal of the resolution matrix ``(A^T A + lambda^2 P)^-1 A^T A`` of the scaled
        problem: the part of each estimate that the data determine (1: the data alone; 0:
        the regularisation alone holds it at its start). NaN where not estimated.
    lambda_ : float
        Regularisation parameter, in units of the column-scaled problem.
    lambda_method : {"lcurve", "gcv", "fixed"}
    lcurve : LCurve
        L-curve and GCV of the final linearisation.
    column_scale : ndarray, shape (n_params,) [m/m, m/rad]
        Column norms used to scale the Jacobian (0 where not estimated).
    singular_values : ndarray, shape (n_estimated,) [m]
        Of the scaled Jacobian at the solution.
    condition_number : float
    residuals : ndarray, shape (n_poses, measurement.dimension) [m for points]
        Measured minus predicted (``measurement.residual``) after calibration, unweighted.
    rms_before, max_before, rms_after, max_after : float [m for points]
        RMS and maximum over the poses of the norm of the residual (the 3-D point error)
        before (nominal model) and after.
    iterations : int
    penalized : ndarray of bool, shape (n_params,)
        Estimated parameters whose deviation from the start the Tikhonov term penalises
        (every estimated kinematic parameter; never the base transform).
    effective_parameters : float
        Trace of the influence matrix of the regularised fit (the number of parameters
        the data effectively determine; the estimated count when lambda is 0).
    converged : bool
    status : int
        Key of :data:`IDENTIFICATION_MESSAGES`.
    message : str
    warnings : tuple of str
    measurement : MeasurementType
        The campaign's measurement type (what `residuals` are).
    rotation_rms_before, rotation_rms_after : float [rad]
        For measurements holding an orientation: RMS over the poses of the rotation residual
        angle before and after calibration (`rms_before` etc. are then the position part);
        NaN otherwise.
    weighting : {"none", "stated", "variance_components"}
        How the residual components were weighted: ``none`` for measurements of one kind
        (points), ``stated`` by the instrument's stated uncertainties, ``variance_components``
        by standard deviations estimated from the residual scatter (``measurement.weight_std``).
    weighting_iterations : int
        Fits made to estimate the variance components (0 unless ``variance_components``).
    tool_initialised : {"nominal", "fit"}
        Where the tool point started: the model's (``tool_known``), or a linear least-squares
        fit to the measured positions given the nominal kinematics (and the base) when the
        model does not know it (a URDF's tip link is not the probe); it is then not
        regularised.
    """

    model: RobotModel
    parameter_names: tuple[str, ...]
    nominal: Array
    estimate: Array
    estimated: NDArray[np.bool_]
    identifiable: NDArray[np.bool_]
    candidates: NDArray[np.bool_]
    dependencies: tuple[str, ...]
    linearized_std: Array
    lambda_: float
    lambda_method: LambdaMethod
    lcurve: LCurve
    column_scale: Array
    singular_values: Array
    condition_number: float
    residuals: Array
    rms_before: float
    max_before: float
    rms_after: float
    max_after: float
    iterations: int
    converged: bool
    status: int
    message: str
    base_initialised: Literal["nominal", "rigid_fit", "identity"]
    n_poses: int
    penalized: NDArray[np.bool_]
    effective_parameters: float
    warnings: tuple[str, ...] = field(default=())
    measurement: MeasurementType = POINT
    rotation_rms_before: float = float("nan")
    rotation_rms_after: float = float("nan")
    weighting: Weighting = "none"
    weighting_iterations: int = 0
    data_only_std: Array | None = None
    data_share: Array | None = None
    tool_initialised: Literal["nominal", "fit"] = "nominal"

    @property
    def success(self) -> bool:
        """True when the iteration converged."""
        return self.status == 0

    @property
    def held_by_regularisation(self) -> NDArray[np.bool_]:
        """Estimated parameters that the Tikhonov term, not the data, determines, shape (n_params,).

        True where ``data_only_std`` exceeds :data:`HELD_STD_RATIO` times ``linearized_std``
        (infinite when the data carry no information on it): its ``linearized_std`` is the
        regularisation's, not a measurement's. A penalised parameter so held stays near its
        start; an unpenalised one (the base) follows a held one it is tied to.
        """
        if self.data_only_std is None:
            return np.zeros(len(self.parameter_names), dtype=bool)
        with np.errstate(invalid="ignore"):
            held = self.data_only_std > HELD_STD_RATIO * self.linearized_std
        return np.asarray(self.estimated & held, dtype=bool)


def residual_stats(residuals: Array) -> tuple[float, float]:
    """RMS and maximum over the poses of the residual norm (the 3-D error of a point).

    Parameters
    ----------
    residuals : ndarray, shape (n_poses, dimension) [m for points]

    Returns
    -------
    (rms, max) : tuple of float [m for points]
    """
    norms = np.linalg.norm(residuals, axis=-1)
    return float(np.sqrt(np.mean(norms**2))), float(norms.max())


def fit_rigid_base(base_points: Array, measured: Array) -> tuple[Array, Array]:
    """Best rigid transform ``measured ~ R @ base_points + t`` (Kabsch/Umeyama, no scale).

    Parameters
    ----------
    base_points : ndarray, shape (n, 3) [m]
        Points predicted in the robot base frame.
    measured : ndarray, shape (n, 3) [m]
        The same points measured in the tracker frame.

    Returns
    -------
    xyz : ndarray, shape (3,) [m]
    rpy : ndarray, shape (3,) [rad]
    """
    cb = base_points.mean(axis=0)
    cm = measured.mean(axis=0)
    h = (base_points - cb).T @ (measured - cm)
    u, _, vt = np.linalg.svd(h)
    sign = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, sign]) @ u.T
    return cm - rot @ cb, rpy_from_matrix(rot)


MAX_LAMBDA = 1e100
"""Largest fixed lambda accepted: lambda**2 and its products must stay finite floats."""


def _validate(model: RobotModel, campaign: Campaign, lambda_: object) -> tuple[Campaign, LambdaMethod, float]:
    if not isinstance(campaign, Campaign):
        msg = f"campaign must be a Campaign, got {type(campaign).__name__}"
        raise InputError(msg)
    campaign = campaign.reorder_joints(model.joint_names)
    if isinstance(lambda_, str):
        key = lambda_.lower()
        if key in ("auto", "lcurve", "l-curve"):
            return campaign, "lcurve", float("nan")
        if key == "gcv":
            return campaign, "gcv", float("nan")
        try:
            lambda_ = float(key)
        except ValueError as err:
            msg = f"lambda must be 'auto', 'gcv' or a non-negative number, got {lambda_!r}"
            raise ConfigError(msg) from err
    if isinstance(lambda_, (bool, np.bool_)) or not isinstance(lambda_, numbers.Real):
        msg = f"lambda must be 'auto', 'gcv' or a non-negative number, got {lambda_!r}"
        raise ConfigError(msg)
    value = float(lambda_)
    if not np.isfinite(value) or value < 0:
        msg = f"lambda must be a finite non-negative number, got {value}"
        raise ConfigError(msg)
    if value > MAX_LAMBDA:
        msg = (
            f"lambda must be at most {MAX_LAMBDA:g}, got {value:g} (its square overflows; in the column-scaled "
            "units any lambda far above 10 already holds every regularised parameter at its nominal value)"
        )
        raise ConfigError(msg)
    return campaign, "fixed", value


def _projected_tikhonov(
    a_mat: Array, b: Array, penalized: NDArray[np.bool_]
) -> tuple[Array, Array, Array, Array, Array]:
    """Reduce ``min ||b - A x||^2 + lam^2 ||x_pen||^2`` to standard form.

    The unpenalised columns (the base transform: a nuisance pose of the tracker with no prior)
    are eliminated by projecting onto the orthogonal complement of their span, which leaves a
    standard-form Tikhonov problem in the penalised columns alone. Returns the thin SVD
    ``(u, s, vt)`` of the projected penalised block, the projected right-hand side, and the
    ``(q_free, a_free)`` needed to back-substitute the free columns.
    """
    a_pen = a_mat[:, penalized]
    a_free = a_mat[:, ~penalized]
    if a_free.shape[1]:
        q_free, _ = np.linalg.qr(a_free)
        a_pen = a_pen - q_free @ (q_free.T @ a_pen)
        b = b - q_free @ (q_free.T @ b)
    else:
        q_free = a_free
    u, s, vt = np.linalg.svd(a_pen, full_matrices=False)
    return u, s, vt, b, q_free


def _tikhonov_step(
    a_mat: Array, b: Array, penalized: NDArray[np.bool_], lam: float, svd: tuple[Array, Array, Array]
) -> Array:
    """Minimiser of ``||b - A x||^2 + lam^2 ||x_pen||^2`` (free columns solved exactly)."""
    u, s, vt = svd
    x = np.zeros(a_mat.shape[1])
    x[penalized] = vt.T @ (s * (u.T @ b) / (s**2 + lam**2))
    if (~penalized).any():
        rest = b - a_mat[:, penalized] @ x[penalized]
        x[~penalized] = np.linalg.lstsq(a_mat[:, ~penalized], rest, rcond=None)[0]
    return x


@dataclass(frozen=True)
class _Solution:
    params: Array
    x: Array
    lam: float
    curve: LCurve
    iterations: int
    status: int
    predicted: Array
    jacobian: Array


def _objective(residual: Array, x: Array, penalized: NDArray[np.bool_], lam: float) -> float:
    return float(residual @ residual + lam**2 * (x[penalized] @ x[penalized]))


def _gauss_newton(
    x_start: Array,
    *,
    layout: ParameterLayout,
    measurement: MeasurementType,
    p0: Array,
    est: NDArray[np.intp],
    scale: Array,
    penalized: NDArray[np.bool_],
    q: Array,
    measured: Array,
    method: LambdaMethod,
    fixed_lambda: float,
    max_iterations: int,
    step_tolerance: float,
    start: tuple[Array, Array] | None = None,
) -> _Solution:
    """Regularised Gauss-Newton with a backtracking line search on the objective.

    Lambda follows the L-curve (or GCV) of each linearisation while the iterate still moves;
    once the relative step falls below 1e-6 (or after half the iterations) it is frozen, so
    the last iterations minimise one fixed objective and the stopping test is meaningful.
    `start`, when given, is the prediction and Jacobian at `x_start` (already computed by the
    caller), so the first linearisation is not evaluated twice.
    """

    def state(x: Array, known: tuple[Array, Array] | None = None) -> tuple[Array, Array, Array, Array, Array]:
        p = p0.copy()
        p[est] += x / scale
        pred, jac = measurement.predict_and_jacobian(layout, p, q) if known is None else known
        r, a_mat = stack_equations(measurement, measurement.residual(measured, pred), jac, est)
        return p, r, a_mat / scale, pred, jac

    x = x_start.copy()
    p, r, a_mat, pred, jac = state(x, start)
    lam = fixed_lambda
    frozen = method == "fixed"
    curve: LCurve | None = None
    status = 1
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        # Linear model of the total scaled deviation x: r(x') ~ r - A (x' - x).
        b = r + a_mat @ x
        u, s, vt, b_proj, _ = _projected_tikhonov(a_mat, b, penalized)
        curve = lcurve(u, s, b_proj)
        if not frozen:
            lam = curve.corner_lambda if method == "lcurve" else curve.gcv_lambda
        step = _tikhonov_step(a_mat, b, penalized, lam, (u, s, vt)) - x
        current = _objective(r, x, penalized, lam)
        t = 1.0
        while True:
            x_try = x + t * step
            p_try, r_try, a_try, pred_try, jac_try = state(x_try)
            if _objective(r_try, x_try, penalized, lam) <= current or t < 1e-3:
                break
            t *= 0.5
        x, p, r, a_mat, pred, jac = x_try, p_try, r_try, a_try, pred_try, jac_try
        relative = t * float(np.linalg.norm(step)) / (1.0 + float(np.linalg.norm(x)))
        if relative <= step_tolerance and frozen:
            status = 0
            break
        if relative <= 1e-6 or iterations >= max_iterations // 2:
            frozen = True
    assert curve is not None  # max_iterations >= 1
    return _Solution(
        params=p, x=x, lam=float(lam), curve=curve, iterations=iterations, status=status, predicted=pred, jacobian=jac
    )


def identify(
    model: RobotModel,
    campaign: Campaign,
    *,
    lambda_: str | float = "auto",
    max_iterations: int = 40,
    step_tolerance: float = 1e-10,
    accept_unconverged: bool = False,
    weighting: Literal["stated", "variance_components"] = "variance_components",
) -> IdentificationResult:
    """Identify the parameter errors of `model` from `campaign`.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Joint readings [rad] and measured values (points [m] by default; what
        ``campaign.measurement`` says). When ``campaign.frame == "base"`` the base transform
        is the identity and not estimated; when ``"tracker"`` the six base parameters are
        estimated too. The base then starts from whichever of the model's base (when the
        model says it is known) and a rigid fit of the nominal predictions to the measured
        positions fits the data better (the model's base alone when the measurements hold no
        3-D positions), and it is not regularised: it is the pose of the tracker, about which
        the nominal model says nothing.
    lambda_ : {"auto", "gcv"} or float
        ``"auto"``: L-curve corner; ``"gcv"``: generalised cross-validation; a number:
        fixed lambda in the column-scaled units (dimensionless per unit column norm).
    max_iterations : int
        Gauss-Newton iteration cap.
    step_tolerance : float
        Converged when the scaled step falls below this, relative to ``1 + ||x||``.
    accept_unconverged : bool
        Return a result that did not converge (with a warning) instead of raising.
    weighting : {"variance_components", "stated"}
        For measurements whose components have different units (6-DOF poses: m and rad;
        ignored for points). ``stated``: each component whitened by the instrument's stated
        standard uncertainty. ``variance_components`` (default): each component whitened by
        its standard deviation estimated from the residual scatter of the fit (Helmert-type
        variance component estimation, iterated until no weight changes by 2 %, at most 10
        fits: ``s_k^2 = sum r_k^2 / (n (1 - p/m))`` with p the effective parameters of m
        equations), never below the stated uncertainty.
        On a real arm the unmodelled errors (tenths of a millimetre, about a milliradian)
        dwarf the tracker's stated uncertainties (micrometres, tens of microradians), and
        weighting by the latter lets the rotations pull the positions away (measured on the
        UR10 series: held-out position RMS 0.437 mm stated vs 0.416 mm variance components,
        0.420 mm from the points alone). The estimated values are in
        ``result.measurement.weight_std``. With fewer than 10
        residual degrees of freedom per component (a handful of poses), or when the
        re-weighted fit does not converge, the stated weights are used and a warning says why.

    Returns
    -------
    IdentificationResult

    Raises
    ------
    InputError
        Joint names do not match the model.
    IdentifiabilityError
        Fewer equations than identifiable parameters, or a degenerate pose set.
    ConvergenceError
        The iteration did not converge from any starting point (unless
        `accept_unconverged`).
    ConfigError
        Invalid lambda or weighting.
    """
    if weighting not in WEIGHTINGS:
        msg = f"weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}"
        raise ConfigError(msg)
    fit = partial(
        _identify_weighted,
        model,
        lambda_=lambda_,
        max_iterations=max_iterations,
        step_tolerance=step_tolerance,
    )
    return _fit_by_weighting(fit, campaign, weighting, accept_unconverged)


def _fit_by_weighting(
    fit: Callable[..., IdentificationResult], campaign: Campaign, weighting: str, accept_unconverged: bool
) -> IdentificationResult:
    """`fit` of `campaign` with the weights `weighting` names (pose measurements only; points as they are)."""
    measurement = campaign.measurement
    if not isinstance(measurement, PoseMeasurement):
        return fit(campaign, accept_unconverged=accept_unconverged)
    current = dataclasses.replace(measurement, weight_std=None)
    stated_campaign = dataclasses.replace(campaign, measurement=current)
    if weighting == "stated":
        return dataclasses.replace(fit(stated_campaign, accept_unconverged=accept_unconverged), weighting="stated")
    return _variance_component_fit(fit, stated_campaign, accept_unconverged)


_VARIANCE_COMPONENT_FITS = 10
_VARIANCE_COMPONENT_TOL = 0.02
_VARIANCE_COMPONENT_MIN_DOF = 10.0
"""Residual degrees of freedom per component below which a variance is too noisy to weigh by."""


def _variance_component_fit(
    fit: Callable[..., IdentificationResult], campaign: Campaign, accept_unconverged: bool
) -> IdentificationResult:
    """:func:`identify` weighted by variance components (see its ``weighting``).

    Falls back to the stated weights, with a warning that says why, when the campaign leaves
    fewer than 10 residual degrees of freedom per component (a variance from a handful of
    residuals would swing the weights by tens of percent) or when the fit with the estimated
    weights does not converge where the stated one does.
    """
    measurement = campaign.measurement
    assert isinstance(measurement, PoseMeasurement)
    stated = measurement.std
    current = measurement
    first = fit(campaign, accept_unconverged=True)
    n_poses, dim = first.residuals.shape
    dof = n_poses * max(1.0 - first.effective_parameters / (n_poses * dim), 0.0)

    def stated_fit(reason: str) -> IdentificationResult:
        result = first if first.converged else fit(campaign, accept_unconverged=accept_unconverged)
        warning = f"weighted by the stated uncertainties: {reason}"
        return dataclasses.replace(result, weighting="stated", warnings=(*result.warnings, warning))

    if dof < _VARIANCE_COMPONENT_MIN_DOF:
        return stated_fit(
            f"{n_poses} poses leave {dof:.3g} residual degrees of freedom per component, too few to "
            f"estimate its variance (need {_VARIANCE_COMPONENT_MIN_DOF:g})"
        )
    trial, fits, change = first, 1, float("inf")
    while True:
        # Intermediate fits only estimate the weights: an unconverged one is still a guide.
        n_eq = trial.residuals.size
        redundancy = max(1.0 - trial.effective_parameters / n_eq, 1.0 / n_eq)
        scatter = np.sqrt(np.mean(trial.residuals**2, axis=0) / redundancy)
        weight_std = np.maximum(scatter, stated)
        change = float(np.max(np.abs(weight_std * current.weights - 1.0)))
        current = dataclasses.replace(measurement, weight_std=tuple(float(v) for v in weight_std))
        if change < _VARIANCE_COMPONENT_TOL or fits >= _VARIANCE_COMPONENT_FITS:
            break
        trial = fit(dataclasses.replace(campaign, measurement=current), accept_unconverged=True)
        fits += 1
    result = fit(dataclasses.replace(campaign, measurement=current), accept_unconverged=True)
    if not result.converged and first.converged:
        return stated_fit("the fit with the estimated variance components did not converge")
    if not result.converged and not accept_unconverged:
        # The same refusal as a fixed-weight fit: let identify's own check raise it.
        fit(dataclasses.replace(campaign, measurement=current), accept_unconverged=False)
    warns = result.warnings
    if change >= 0.1:
        warns = (
            *warns,
            f"variance components not settled after {fits} fits (last change of a weight "
            f"{100 * change:.3g} %): the weights are approximate",
        )
    return dataclasses.replace(result, weighting="variance_components", weighting_iterations=fits, warnings=warns)


def _check_iteration_settings(max_iterations: int, step_tolerance: float) -> None:
    """Refuse an iteration cap or a step tolerance that no fit could honour."""
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or max_iterations < 1:
        msg = f"max_iterations must be a positive integer, got {max_iterations!r}"
        raise ConfigError(msg)
    if (
        isinstance(step_tolerance, (bool, np.bool_))
        or not isinstance(step_tolerance, numbers.Real)
        or not np.isfinite(step_tolerance)
        or step_tolerance < 0
    ):
        # NaN or a negative tolerance can never be met: every call would end in a ConvergenceError.
        msg = f"step_tolerance must be a finite non-negative number, got {step_tolerance!r}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class _BaseStart:
    """Where the base starts and which parameters are candidates for the fit."""

    params: Array
    candidates: NDArray[np.bool_]
    initialised: Literal["nominal", "rigid_fit", "identity"]
    note: str | None


def _base_start(model: RobotModel, campaign: Campaign, p0: Array) -> _BaseStart:
    """The base fixed at the identity (base-frame campaign) or started as :func:`_initial_base` says."""
    layout = model.layout
    b0 = layout.base_index
    candidates = np.ones(layout.size, dtype=bool)
    if campaign.frame == "base":
        p0[b0 : b0 + 6] = 0.0
        candidates[b0 : b0 + 6] = False
        return _BaseStart(params=p0, candidates=candidates, initialised="identity", note=None)
    p_model = p0
    p0, base_init = _initial_base(model, campaign.measurement, p0, campaign.joint_positions, campaign.points)
    note = None
    if base_init == "rigid_fit":
        # A known base that the data contradict is replaced (correctly): say so.
        note = _replaced_base_note(model, p_model[b0 : b0 + 6], p0[b0 : b0 + 6])
    return _BaseStart(params=p0, candidates=candidates, initialised=base_init, note=note)


def _penalized_columns(model: RobotModel, est: NDArray[np.intp]) -> NDArray[np.bool_]:
    """Which estimated parameters the Tikhonov term holds near nominal."""
    layout = model.layout
    penalized = est < layout.base_index  # the base (last six parameters) is never regularised
    r0 = layout.tool_rotation_index
    if r0 is not None:
        # Nor is the tool rotation: like the base, a mounting the nominal model says little about.
        penalized &= (est < r0) | (est >= r0 + 3)
    if not model.tool_known:
        # Nor is a tool point the model does not know: a penalty would hold it near the tip link.
        t0 = layout.tool_index
        penalized &= (est < t0) | (est >= t0 + 3)
    return penalized


def _check_pose_count(campaign: Campaign, est: NDArray[np.intp]) -> None:
    """Refuse a campaign with fewer equations than identifiable parameters."""
    dim = campaign.measurement.dimension
    n_eq = dim * campaign.n_poses
    if n_eq < est.size:
        msg = (
            f"too few poses: {campaign.n_poses} poses give {n_eq} equations for "
            f"{est.size} identifiable parameters (need at least {int(np.ceil(est.size / dim))} poses)"
        )
        raise IdentifiabilityError(msg)


def _column_scale(layout: ParameterLayout, jac0: Array, est: NDArray[np.intp], n_poses: int) -> Array:
    """Column norms of the nominal Jacobian; refuses a pose set that leaves a direction unseen."""
    scale: Array = np.linalg.norm(jac0, axis=0)
    _, s0, vt0 = np.linalg.svd(jac0 / scale, full_matrices=False)
    if s0[-1] <= _DEGENERATE_RCOND * s0[0]:
        weak = layout.names[est[int(np.argmax(np.abs(vt0[-1])))]]
        msg = (
            f"degenerate pose set: the {n_poses} poses identify only "
            f"{int(np.sum(s0 > _DEGENERATE_RCOND * s0[0]))} of {est.size} identifiable parameters "
            f"(vary the joints more; weakest direction involves {weak})"
        )
        raise IdentifiabilityError(msg)
    return scale


def _solve_with_restart(
    solve: Callable[..., _Solution],
    campaign: Campaign,
    layout: ParameterLayout,
    p0: Array,
    est: NDArray[np.intp],
    scale: Array,
    start: tuple[Array, Array],
) -> tuple[_Solution, int]:
    """Gauss-Newton from the start, and once more from a re-fitted base when it did not converge.

    Returns the better solution and the number of restarts (0 or 1).
    """
    measurement, q, measured = campaign.measurement, campaign.joint_positions, campaign.points
    b0 = layout.base_index
    solution = solve(np.zeros(est.size), start=start)
    if solution.status == 0 or campaign.frame == "base":
        return solution, 0
    # Restart once with the base re-fitted rigidly to the current kinematic estimate:
    # a poor start of the base is the usual reason for a slow or wandering iteration.
    p_kin = solution.params.copy()
    p_kin[b0 : b0 + 6] = 0.0
    base = _rigid_base(layout, measurement, p_kin, q, measured)
    if base is None:
        return solution, 0
    x_restart = solution.x.copy()
    base_cols = est >= b0
    x_restart[base_cols] = (base - p0[b0 : b0 + 6])[est[base_cols] - b0] * scale[base_cols]
    second = solve(x_restart)
    if second.status == 0 or _final_rms(layout, measurement, second.params, q, measured) < _final_rms(
        layout, measurement, solution.params, q, measured
    ):
        return second, 1
    return solution, 1


def _check_converged(
    status: int, restarts: int, max_iterations: int, rms_before: float, rms_after: float, accept_unconverged: bool
) -> None:
    """Refuse an unconverged fit unless the caller accepts it."""
    if status != 0 and not accept_unconverged:
        msg = (
            f"identification did not converge in {max_iterations} iterations"
            f"{' (and a restart)' if restarts else ''}: residual RMS {rms_after * 1e3:.4g} mm "
            f"(before {rms_before * 1e3:.4g} mm); the result would be wrong. Check units, joint names "
            "and the robot model, or accept it explicitly (--accept-unconverged)"
        )
        raise ConvergenceError(msg)


@dataclass(frozen=True)
class _Linearization:
    """First-order statistics of the Tikhonov estimate at the solution, per full parameter."""

    whitened: Array
    singular_values: Array
    effective_parameters: float
    std: Array
    data_only_std: Array
    data_share: Array


def _linearization(
    measurement: MeasurementType,
    residuals: Array,
    jac: Array,
    est: NDArray[np.intp],
    scale: Array,
    penalized: NDArray[np.bool_],
    lam: float,
    size: int,
) -> _Linearization:
    """Covariance of the Tikhonov estimate with residual-scatter noise, and its data share."""
    whitened, unscaled = stack_equations(measurement, residuals, jac, est)
    a_mat = unscaled / scale
    s_final = cast(Array, np.linalg.svd(a_mat, compute_uv=False))
    n_eq = residuals.size
    # First-order covariance of the Tikhonov estimate with residual-scatter noise.
    ata = a_mat.T @ a_mat
    reg = lam**2 * np.diag(penalized.astype(np.float64))
    inv = cast(Array, np.linalg.inv(ata + reg))
    dof_used = float(np.trace(inv @ ata))
    sigma2 = float(np.sum(whitened**2)) / max(n_eq - dof_used, 1.0)
    cov_x = sigma2 * inv @ ata @ inv
    std = np.full(size, np.nan)
    std[est] = np.sqrt(np.diag(cov_x)) / scale
    share, data_std = _data_determination(ata, inv, sigma2)
    data_share = np.full(size, np.nan)
    data_share[est] = share
    data_only_std = np.full(size, np.nan)
    data_only_std[est] = data_std / scale
    return _Linearization(
        whitened=whitened,
        singular_values=s_final,
        effective_parameters=dof_used,
        std=std,
        data_only_std=data_only_std,
        data_share=data_share,
    )


def _fit_warnings(
    base_note: str | None, cond: float, status: int, measurement: MeasurementType, whitened: Array
) -> tuple[str, ...]:
    """The warnings a fit carries: a replaced base, ill-conditioning, acceptance, weighting."""
    warns: list[str] = [] if base_note is None else [base_note]
    if cond > 1e6:
        warns.append(f"ill-conditioned pose set: condition number {cond:.3g} of the scaled Jacobian")
    if status != 0:
        warns.append(IDENTIFICATION_MESSAGES[status] + " (accepted by the caller)")
    mismatch = _weighting_mismatch(measurement, whitened)
    if mismatch is not None:
        warns.append(mismatch)
    return tuple(warns)


def _full_mask(size: int, est: NDArray[np.intp], values: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """A full-parameter mask holding `values` at the estimated columns, False elsewhere."""
    out = np.zeros(size, dtype=bool)
    out[est] = values
    return out


def _full_values(size: int, est: NDArray[np.intp], values: Array) -> Array:
    """A full-parameter vector holding `values` at the estimated columns, zero elsewhere."""
    out = np.zeros(size)
    out[est] = values
    return out


@dataclass(frozen=True)
class _Problem:
    """The linearised problem at the starting point: what is estimated, scaled and penalised."""

    model: RobotModel
    p0: Array
    base: _BaseStart
    observability: Observability
    tool_initialised: Literal["nominal", "fit"]
    est: NDArray[np.intp]
    penalized: NDArray[np.bool_]
    start: tuple[Array, Array]
    scale: Array


def _prepare(model: RobotModel, campaign: Campaign) -> _Problem:
    """Starting point, identifiable columns, penalty and column scale of a fit of `campaign`."""
    measurement = campaign.measurement
    if measurement.measures_orientation:
        # Orientation data identify the tool frame's rotation in the flange frame.
        model = model.with_tool_rotation()
    layout = model.layout
    q = campaign.joint_positions
    measured = campaign.points
    p0 = model.parameter_vector()
    check_point_scale(model, campaign)
    base = _base_start(model, campaign, p0)
    p0 = base.params

    # What the data can tell apart is decided on the nominal geometry (a tool point on the last
    # axis makes some columns exactly alike), before an unknown tool point is fitted: a fitted
    # point a fraction of a millimetre off the axis must not turn those into weak parameters.
    obs = structural_observability(model, p0, base.candidates, measurement=measurement)
    tool_init: Literal["nominal", "fit"] = "nominal"
    if not model.tool_known:
        fitted = _initial_tool(layout, measurement, p0, q, measured, refit_base=campaign.frame != "base")
        if fitted is not None:
            p0, tool_init = fitted, "fit"

    est = np.flatnonzero(obs.identifiable)
    _check_pose_count(campaign, est)
    penalized = _penalized_columns(model, est)
    pred0, jac0_poses = measurement.predict_and_jacobian(layout, p0, q)
    scale = _column_scale(layout, stack_jacobian(measurement, jac0_poses, est), est, campaign.n_poses)
    return _Problem(
        model=model,
        p0=p0,
        base=base,
        observability=obs,
        tool_initialised=tool_init,
        est=est,
        penalized=penalized,
        start=(pred0, jac0_poses),
        scale=scale,
    )


def _identify_weighted(
    model: RobotModel,
    campaign: Campaign,
    *,
    lambda_: str | float,
    max_iterations: int,
    step_tolerance: float,
    accept_unconverged: bool,
) -> IdentificationResult:
    """:func:`identify` with the weights of ``campaign.measurement`` as they are."""
    campaign, method, fixed_lambda = _validate(model, campaign, lambda_)
    _check_iteration_settings(max_iterations, step_tolerance)
    problem = _prepare(model, campaign)
    model, measurement, layout = problem.model, campaign.measurement, problem.model.layout
    q, measured = campaign.joint_positions, campaign.points
    p0, est, scale, penalized = problem.p0, problem.est, problem.scale, problem.penalized
    residuals0 = measurement.residual(measured, problem.start[0])
    rms_before, max_before = residual_stats(_position_part(measurement, residuals0))
    solve = partial(
        _gauss_newton,
        layout=layout,
        measurement=measurement,
        p0=p0,
        est=est,
        scale=scale,
        penalized=penalized,
        q=q,
        measured=measured,
        method=method,
        fixed_lambda=fixed_lambda,
        max_iterations=max_iterations,
        step_tolerance=step_tolerance,
    )
    solution, restarts = _solve_with_restart(solve, campaign, layout, p0, est, scale, problem.start)
    status, lam, p = solution.status, solution.lam, solution.params

    # The last iterate's linearisation: no second evaluation of the chain at the solution.
    residuals = measurement.residual(measured, solution.predicted)
    rms_after, max_after = residual_stats(_position_part(measurement, residuals))
    _check_converged(status, restarts, max_iterations, rms_before, rms_after, accept_unconverged)
    lin = _linearization(measurement, residuals, solution.jacobian, est, scale, penalized, lam, layout.size)
    estimated = _full_mask(layout.size, est, np.ones(est.size, dtype=bool))
    cond = float(lin.singular_values[0] / lin.singular_values[-1])
    return IdentificationResult(
        model=model.with_parameters(p),
        parameter_names=layout.names,
        nominal=p0,
        estimate=p,
        estimated=estimated,
        identifiable=estimated.copy(),
        candidates=problem.base.candidates,
        dependencies=problem.observability.dependencies,
        linearized_std=lin.std,
        data_only_std=lin.data_only_std,
        data_share=lin.data_share,
        lambda_=float(lam),
        lambda_method=method,
        lcurve=solution.curve,
        column_scale=_full_values(layout.size, est, scale),
        singular_values=lin.singular_values,
        condition_number=cond,
        residuals=residuals,
        rms_before=rms_before,
        max_before=max_before,
        rms_after=rms_after,
        max_after=max_after,
        iterations=solution.iterations,
        converged=status == 0,
        status=status,
        message=IDENTIFICATION_MESSAGES[status],
        base_initialised=problem.base.initialised,
        tool_initialised=problem.tool_initialised,
        n_poses=campaign.n_poses,
        penalized=_full_mask(layout.size, est, penalized),
        effective_parameters=lin.effective_parameters,
        warnings=_fit_warnings(problem.base.note, cond, status, measurement, lin.whitened.reshape(residuals.shape)),
        measurement=measurement,
        rotation_rms_before=_rotation_rms(measurement, residuals0),
        rotation_rms_after=_rotation_rms(measurement, residuals),
    )


_WEIGHTING_MISMATCH = 30.0


def _data_determination(ata: Array, inv: Array, sigma2: float) -> tuple[Array, Array]:
    """Data share (resolution-matrix diagonal) and data-only std of each scaled parameter.

    ``ata`` is ``A^T A`` of the scaled problem, ``inv`` the inverse of ``A^T A + lambda^2 P``.
    The data-only covariance is ``sigma2 (A^T A)^-1``; a direction of ``A^T A`` with an
    eigenvalue below ``1e-14`` of the largest carries no information, and every parameter
    with a component along it gets an infinite data-only std.
    """
    share = np.clip(np.einsum("ij,ji->i", inv, ata), 0.0, 1.0)
    evals, evecs = np.linalg.eigh(ata)
    informative = evals > 1e-14 * max(float(evals[-1]), np.finfo(float).tiny)
    with np.errstate(divide="ignore"):
        var = (evecs[:, informative] ** 2) @ (1.0 / evals[informative])
    blind = (evecs[:, ~informative] ** 2).sum(axis=1) > 1e-12
    var = np.where(blind, np.inf, var)
    return share, np.sqrt(sigma2 * var)


def _weighting_mismatch(measurement: MeasurementType, whitened: Array) -> str | None:
    """A warning when the whitened residual scatter of metres and radians components differs by > 30x.

    The weights say how much a rotation residual counts against a position residual; when the
    stated standard uncertainties leave out a dominant error (typically the encoders, which
    turn the tool as well as move it), one kind of equation outweighs the other by orders of
    magnitude, the L-curve regularises the rest away and the calibration is worse than from the
    positions alone, silently. `whitened` has shape (n_poses, dimension).
    """
    if measurement.weights is None:
        return None
    units = np.asarray(measurement.component_units)
    rms = {u: float(np.sqrt(np.mean(whitened[:, units == u] ** 2))) for u in ("m", "rad") if np.any(units == u)}
    if len(rms) < 2 or min(rms.values()) <= 0.0:
        return None
    ratio = max(rms.values()) / min(rms.values())
    if ratio <= _WEIGHTING_MISMATCH:
        return None
    return (
        f"the stated uncertainties do not match the residual scatter: whitened residual RMS "
        f"{rms['m']:.3g} for positions and {rms['rad']:.3g} for rotations ({ratio:.3g}x apart), so one kind "
        "of equation outweighs the other; state standard uncertainties that include every error "
        "source (encoder noise turns the tool too)"
    )


def _position_part(measurement: MeasurementType, residuals: Array) -> Array:
    """The position components (the first three) of orientation-holding residuals; else all."""
    return residuals[..., :3] if measurement.measures_orientation else residuals


def _rotation_rms(measurement: MeasurementType, residuals: Array) -> float:
    """RMS rotation residual angle [rad] (components 3-5) for orientation data; NaN otherwise."""
    if not measurement.measures_orientation:
        return float("nan")
    return residual_stats(residuals[..., 3:6])[0]


def _final_rms(
    layout: ParameterLayout, measurement: MeasurementType, params: Array, q: Array, measured: Array
) -> float:
    """RMS of the whitened residual norms: the comparison the objective makes."""
    residual = measurement.residual(measured, measurement.predict(layout, params, q))
    return residual_stats(stack_residual(measurement, residual).reshape(residual.shape))[0]


def _rigid_base(
    layout: ParameterLayout, measurement: MeasurementType, p_kin: Array, q: Array, measured: Array
) -> Array | None:
    """Base ``(x, y, z, roll, pitch, yaw)`` [m, rad] rigidly fitted to the measured positions.

    `p_kin` has the base set to the identity. None when the measurements hold no 3-D positions.
    """
    positions = measurement.positions(measured)
    if positions is None:
        return None
    xyz, rpy = fit_rigid_base(forward_points(layout, p_kin, q), positions)
    return np.concatenate((xyz, rpy))


SCALE_TOLERANCE = 3.0
"""Largest ratio (either way) of the measured points' spread to the nominal robot's at the same
joints: a calibration changes a robot's size by parts per thousand, a unit slip by 10 (cm),
25.4 (inch) or 1000 (m read as mm)."""


def check_point_scale(model: RobotModel, campaign: Campaign) -> None:
    """Refuse measured points whose spread does not fit the robot's size (a wrong unit).

    The RMS distance of the measured positions from their centroid is compared with that of the
    nominal model's tool positions at the same joint readings: it does not depend on the frame
    (tracker or base) nor on where the tracker stands. The robot's reach (largest distance of
    the nominal tool from the base over these readings) is named in the message.

    Raises
    ------
    InputError
        The ratio is beyond :data:`SCALE_TOLERANCE` either way.
    """
    measurement = campaign.measurement
    positions = measurement.positions(campaign.points)
    if positions is None or campaign.n_poses < 3:
        return
    q = campaign.reorder_joints(model.joint_names).joint_positions
    p_kin = model.parameter_vector()
    b0 = model.layout.base_index
    p_kin[b0 : b0 + 6] = 0.0
    nominal = forward_points(model.layout, p_kin, q)
    spread_nominal = float(np.sqrt(np.mean(np.sum((nominal - nominal.mean(axis=0)) ** 2, axis=1))))
    spread = float(np.sqrt(np.mean(np.sum((positions - positions.mean(axis=0)) ** 2, axis=1))))
    if not (np.isfinite(spread) and spread_nominal > 0.0):
        return
    ratio = spread / spread_nominal
    if 1.0 / SCALE_TOLERANCE <= ratio <= SCALE_TOLERANCE:
        return
    reach = float(np.max(np.linalg.norm(nominal, axis=1)))
    hint = ""
    for factor, words in (
        (1e-3, "metres read as millimetres"),
        (1e3, "millimetres read as metres"),
        (0.1, "centimetres read as millimetres"),
        (10.0, "millimetres read as centimetres"),
        (1 / 25.4, "inches read as millimetres"),
        (25.4, "millimetres read as inches"),
    ):
        if abs(np.log(ratio / factor)) < np.log(1.5):
            hint = f" ({words}?)"
            break
    msg = (
        f"the measured points spread {spread * 1e3:.4g} mm about their centroid, the robot {model.name!r} at the "
        f"same joints {spread_nominal * 1e3:.4g} mm (reach {reach * 1e3:.4g} mm): the points are {ratio:.3g} "
        f"times the robot's size{hint}; check the unit of the points and the robot model"
    )
    raise InputError(msg)


BASE_NOTE_TRANSLATION = 10e-3
"""A known base the rigid fit replaces is reported when it is this far [m] from the fit ..."""
BASE_NOTE_ROTATION = 10e-3
"""... or turned by this angle [rad] from it."""


def _replaced_base_note(model: RobotModel, stated: Array, fitted: Array) -> str | None:
    """One line when the robot config's known base was replaced by the rigid fit and is far from it."""
    if not model.base_known:
        return None
    shift = float(np.linalg.norm(fitted[:3] - stated[:3]))
    turn_cos = (np.trace(rpy_to_matrix(stated[3:]).T @ rpy_to_matrix(fitted[3:])) - 1.0) / 2.0
    turn = float(np.arccos(np.clip(turn_cos, -1.0, 1.0)))
    if shift <= BASE_NOTE_TRANSLATION and turn <= BASE_NOTE_ROTATION:
        return None
    return (
        f"the robot config's known base is {shift * 1e3:.1f} mm and {turn * 1e3:.1f} mrad from the rigid fit "
        "of the nominal model to the measured points, which fits the data better: the base starts from the "
        "fit and is identified (set base.known: false in the robot config if the base is not known)"
    )


_TOOL_FIT_ITERATIONS = 50
_TOOL_FIT_TOLERANCE = 1e-10
"""Alternating tool / rigid base fit: stop when the tool point moves less than this [m]."""


def _initial_tool(
    layout: ParameterLayout,
    measurement: MeasurementType,
    p0: Array,
    q: Array,
    measured: Array,
    *,
    refit_base: bool,
) -> Array | None:
    """`p0` with the tool point fitted to the measured positions (linear least squares).

    The measured point is affine in the tool point (``R_b (R_i t + p_i) + t_b``), so with every
    other parameter nominal the best tool point is one linear solve. With an unknown base
    (`refit_base`: a tracker-frame campaign) the rigid base fit and the tool fit alternate
    until the tool point settles (each step lowers the same sum of squares). None when the
    measurements hold no 3-D positions.
    """
    positions = measurement.positions(measured)
    if positions is None:
        return None
    t0, b0 = layout.tool_index, layout.base_index
    p = p0.copy()
    for _ in range(_TOOL_FIT_ITERATIONS):
        pred, jac = forward_points_and_jacobian(layout, p, q)
        a_mat = jac[:, :, t0 : t0 + 3].reshape(-1, 3)
        step = np.linalg.lstsq(a_mat, (positions - pred).reshape(-1), rcond=None)[0]
        p[t0 : t0 + 3] += step
        if refit_base:
            p_kin = p.copy()
            p_kin[b0 : b0 + 6] = 0.0
            xyz, rpy = fit_rigid_base(forward_points(layout, p_kin, q), positions)
            p[b0 : b0 + 3], p[b0 + 3 : b0 + 6] = xyz, rpy
        if not refit_base or float(np.linalg.norm(step)) < _TOOL_FIT_TOLERANCE:
            break
    return p


def _initial_base(
    model: RobotModel, measurement: MeasurementType, p0: Array, q: Array, measured: Array
) -> tuple[Array, Literal["nominal", "rigid_fit"]]:
    """Start the base at the model's (when known) or a rigid fit, whichever fits better."""
    layout = model.layout
    b0 = layout.base_index
    p_fit = p0.copy()
    p_fit[b0 : b0 + 6] = 0.0
    base = _rigid_base(layout, measurement, p_fit, q, measured)
    if base is None:
        return p0, "nominal"
    p_fit[b0 : b0 + 6] = base
    if not model.base_known:
        return p_fit, "rigid_fit"
    if _final_rms(layout, measurement, p0, q, measured) <= _final_rms(layout, measurement, p_fit, q, measured):
        return p0, "nominal"
    return p_fit, "rigid_fit"
