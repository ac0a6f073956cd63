"""Next-best calibration poses: which configuration to measure next.

The calibration is linearised at its estimate (column-scaled parameters x of the estimated
parameters, point Jacobian ``A_i`` (3, n) per pose). Each measured point carries the noise
``R_i = s_t(d_i)^2 I + s_q^2 J_q,i J_q,i^T`` (tracker standard deviation at its distance,
encoder standard deviation through the joint Jacobian; the sources off in the settings
contribute nothing), and the Tikhonov penalty acts as a prior of precision
``lambda^2 / s_ref^2`` on the penalised columns (``s_ref^2`` the mean tracker variance: the
unweighted objective ``||r||^2 + lambda^2 ||x_pen||^2`` is ``s^2`` times the whitened one).
The information matrix is

    H = sum_i A_i^T R_i^-1 A_i + (lambda / s_ref)^2 P,

the first-order covariance of the tool position at test configuration k is
``C_k = G_k H^-1 G_k^T`` (plus the encoder noise of the test configuration itself), and
measuring a candidate c adds ``A_c^T R_c^-1 A_c`` to H. By the Woodbury identity the
reduction of ``sum_k trace C_k`` is

    trace(S_c^-1 A_c B A_c^T),   S_c = R_c + A_c H^-1 A_c^T,   B = H^-1 (sum_k G_k^T G_k) H^-1,

a 3x3 solve per candidate, so thousands of candidates rank in milliseconds. The best few can
then be checked by Monte Carlo: the campaign with the candidate added as a simulated
measurement at its predicted point (the calibrated model's prediction) is evaluated with the
same settings and seed, and the RMS over the test configurations of
``u_pos = sqrt(trace C_k)`` is reported next to the first-order prediction.

``robocal-uncertainty suggest`` and the uncertainty node's ``~/suggest_poses`` service call
:func:`suggest_poses`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.joint_limits import check_joint_limits
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import joint_columns
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel
from robocal_uncertainty.core.simulation import draw_joint_positions
from robocal_uncertainty.errors import ConvergenceError, InputError
from robocal_uncertainty.kernels import BackendInfo, get_backend, resolve_backend
from robocal_uncertainty.uncertainty.calibration import EvaluationSettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = [
    "Linearization",
    "PoseSuggestion",
    "Suggestions",
    "linearize",
    "rank_candidates",
    "service_arguments",
    "service_response",
    "suggest_poses",
    "with_simulated_pose",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Linearization:
    """The linearised calibration the ranking works on (column-scaled estimated parameters).

    Attributes
    ----------
    information : ndarray, shape (n, n)
        H [1/(scaled unit)^2].
    covariance : ndarray, shape (n, n)
        H^-1.
    test_jacobian : ndarray, shape (n_test, 3, n) [m per scaled unit]
        G_k, output frame.
    test_encoder_covariance : ndarray, shape (n_test, 3, 3) [m^2]
        Encoder noise of the test configurations themselves (campaign-independent).
    estimate : ndarray, shape (n_params,) [m, rad]
        Calibrated parameters (linearisation point).
    estimated : ndarray of int, shape (n,)
        Indices of the estimated parameters.
    scale : ndarray, shape (n,)
        Column scale of each estimated parameter.
    frame_id : str
        TF name of the output positions.
    campaign_frame : {"base", "tracker"}
    tracker_origin : ndarray, shape (3,) [m]
        Tracker position in the campaign frame (for distance-dependent noise).
    tracker_a, tracker_b : float [m, m/m]
        Tracker MPE a + b L (0 when the tracker source is off).
    encoder_var : float [rad^2] or ndarray, shape (n_joints,) [rad^2; m^2 for prismatic joints]
        Encoder variance per joint (0 when the encoder source is off); one per joint when the
        robot has a prismatic joint.
    """

    information: Array
    covariance: Array
    test_jacobian: Array
    test_encoder_covariance: Array
    estimate: Array
    estimated: NDArray[np.intp]
    scale: Array
    frame_id: str
    campaign_frame: str
    tracker_origin: Array
    tracker_a: float
    tracker_b: float
    encoder_var: float | Array

    def test_covariances(self, information: Array | None = None) -> Array:
        """C_k for `information` (default: the campaign's), shape (n_test, 3, 3) [m^2]."""
        cov = self.covariance if information is None else np.linalg.inv(information)
        g = self.test_jacobian
        return np.asarray(np.einsum("kan,nm,kbm->kab", g, cov, g) + self.test_encoder_covariance, dtype=np.float64)


@dataclass(frozen=True)
class PoseSuggestion:
    """One suggested configuration.

    Attributes
    ----------
    joint_positions : ndarray, shape (n_joints,) [rad]
    reduction_m2 : float [m^2]
        First-order reduction of ``sum_k trace C_k`` if it alone is measured.
    predicted_u_m : float [m]
        First-order RMS over the test configurations of ``u_pos`` after measuring it and
        every better-ranked suggestion.
    monte_carlo_u_m : float or None [m]
        Monte Carlo RMS ``u_pos`` with it and every better-ranked suggestion added as
        simulated measurements (None: not checked).
    """

    joint_positions: Array
    reduction_m2: float
    predicted_u_m: float
    monte_carlo_u_m: float | None = None


@dataclass(frozen=True)
class Suggestions:
    """Result of :func:`suggest_poses`.

    Attributes
    ----------
    suggestions : tuple of PoseSuggestion
        Best first, chosen greedily: each is the best candidate once the ones before it
        are measured.
    current_u_m : float [m]
        First-order RMS ``u_pos`` of the campaign as it is.
    monte_carlo_current_u_m : float or None [m]
        Its Monte Carlo counterpart (None: no check ran).
    candidates : ndarray, shape (n_candidates, n_joints) [rad]
    reductions_m2 : ndarray, shape (n_candidates,) [m^2]
        First-order reduction of every candidate.
    joint_names : tuple of str
    frame_id : str
        Frame of the ranked positions.
    trials : int
        Monte Carlo trials per check (0: none).
    seed : int
    backend : BackendInfo or None
        The trial kernels of the Monte Carlo checks (None: no check ran).
    """

    suggestions: tuple[PoseSuggestion, ...]
    current_u_m: float
    monte_carlo_current_u_m: float | None
    candidates: Array
    reductions_m2: Array
    joint_names: tuple[str, ...]
    frame_id: str
    trials: int
    seed: int
    backend: BackendInfo | None = None


def _rms_u(covariances: Array) -> float:
    """RMS over configurations of sqrt(trace C_k) [m]."""
    return math.sqrt(float(np.mean(np.trace(covariances, axis1=1, axis2=2))))


def _checked_test_joints(model: RobotModel, campaign: Campaign, test_joints: ArrayLike, frame: str) -> Array:
    """The test joints (n_test, n_joints) [rad]; refuses a non-point campaign, an unknown frame, a wrong shape."""
    if campaign.measurement.dimension != 3 or campaign.measurement.positions(campaign.points) is None:
        msg = f"next-best poses need point measurements, got {campaign.measurement.quantity}"
        raise InputError(msg)
    if frame not in ("measurement", "base"):
        msg = f"frame must be 'measurement' or 'base', got {frame!r}"
        raise InputError(msg)
    q_test = np.atleast_2d(np.asarray(test_joints, dtype=np.float64))
    if q_test.ndim != 2 or q_test.shape[1] != model.n_joints:
        msg = f"test_joints must have shape (n_test, {model.n_joints}), got {q_test.shape}"
        raise InputError(msg)
    return q_test


def _noise_levels(model: RobotModel, settings: UncertaintySettings) -> tuple[float, float, float | Array]:
    """Tracker a [m], b [m/m] and encoder variance [rad^2, m^2] of the enabled sources (zero when off)."""
    from robocal_uncertainty.uncertainty.sources.registry import source_with_role

    tracker_on = source_with_role("point_noise") in settings.sources
    encoder_on = source_with_role("reading_noise") in settings.sources
    a = settings.tracker_noise.a if tracker_on else 0.0
    b = settings.tracker_noise.b if tracker_on else 0.0
    encoder_var: float | Array = (settings.encoder_noise.half_width**2 / 3.0) if encoder_on else 0.0
    if encoder_on and any(model.prismatic):
        encoder_var = settings.encoder_noise.variances(model.prismatic)  # rad^2 and m^2
    if a == b == 0.0 and not np.any(encoder_var):
        msg = "no tracker or encoder noise in the settings: nothing to weight the poses with"
        raise InputError(msg)
    return a, b, encoder_var


def _test_jacobians(
    layout: ParameterLayout,
    estimate: Array,
    q_test: Array,
    estimated: NDArray[np.intp],
    scale: Array,
    *,
    drop_base: bool,
) -> tuple[Array, Array]:
    """Jacobians of the test points in the estimated (scaled) parameters and in the joints.

    With `drop_base` (base-frame output of a tracker campaign) the base is the identity and its
    columns are zero.
    """
    p_out = estimate.copy()
    b0 = layout.base_index
    if drop_base:
        p_out[b0 : b0 + 6] = 0.0
    _, gy = forward_points_and_jacobian(layout, p_out, q_test)
    if drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    return gy[:, :, estimated] / scale, gy[:, :, joint_columns(layout)]


def linearize(
    model: RobotModel,
    campaign: Campaign,
    test_joints: ArrayLike,
    calibration: IdentificationResult,
    settings: UncertaintySettings,
    *,
    frame: str = "measurement",
) -> Linearization:
    """Information matrix of the linearised calibration and the test Jacobians.

    Parameters
    ----------
    model : RobotModel
    campaign : Campaign
        Point measurements (``measurement.dimension == 3``).
    test_joints : array_like, shape (n_test, n_joints) [rad]
    calibration : IdentificationResult
        Of `campaign`.
    settings : UncertaintySettings
        Tracker and encoder noise (each only if its source is enabled).
    frame : {"measurement", "base"}
        Output frame, as in :func:`~robocal_uncertainty.uncertainty.evaluate_uncertainty`.

    Raises
    ------
    InputError
        Not a point campaign, no noise to weight with, a singular information matrix.
    """
    q_test = _checked_test_joints(model, campaign, test_joints, frame)
    a, b, encoder_var = _noise_levels(model, settings)
    layout = model.layout
    estimated = np.flatnonzero(calibration.estimated)
    scale = calibration.column_scale[estimated]
    estimate = calibration.estimate
    origin = np.zeros(3) if campaign.frame == "tracker" else np.asarray(settings.tracker_xyz, dtype=np.float64)
    lin = Linearization(
        information=np.zeros((0, 0)),
        covariance=np.zeros((0, 0)),
        test_jacobian=np.zeros((0, 3, 0)),
        test_encoder_covariance=np.zeros((0, 3, 3)),
        estimate=estimate,
        estimated=estimated,
        scale=scale,
        frame_id="",
        campaign_frame=campaign.frame,
        tracker_origin=origin,
        tracker_a=a,
        tracker_b=b,
        encoder_var=encoder_var,
    )
    jac, noise = _pose_terms(model, lin, campaign.joint_positions)
    information = np.einsum("pan,pab,pbm->nm", jac, np.linalg.inv(noise), jac)
    tracker_var = (a + b * np.linalg.norm(campaign.points - origin, axis=1)) ** 2 / 3.0
    reference = float(np.mean(tracker_var)) if np.any(tracker_var > 0) else float(np.mean(noise[:, 0, 0]))
    penalized = calibration.penalized[estimated]
    information += np.diag(penalized * calibration.lambda_**2 / reference)
    if np.linalg.cond(information) > 1e14:
        msg = "the linearised calibration is singular: too few or too alike poses to rank candidates"
        raise InputError(msg)
    g, gq = _test_jacobians(
        layout, estimate, q_test, estimated, scale, drop_base=frame == "base" and campaign.frame == "tracker"
    )
    frame_id = model.base_frame_id if frame == "base" or campaign.frame == "base" else campaign.frame_id
    return replace(
        lin,
        information=information,
        covariance=np.linalg.inv(information),
        test_jacobian=g,
        test_encoder_covariance=_encoder_covariance(encoder_var, gq),
        frame_id=frame_id,
    )


def _encoder_covariance(encoder_var: float | Array, jq: Array) -> Array:
    """``J diag(var) J^T`` per pose of joint Jacobians `jq` (n, 3, n_joints)."""
    if np.ndim(encoder_var) == 0:
        return np.asarray(encoder_var * np.einsum("paj,pbj->pab", jq, jq), dtype=np.float64)
    return np.asarray(np.einsum("paj,j,pbj->pab", jq, encoder_var, jq), dtype=np.float64)


def _pose_terms(model: RobotModel, lin: Linearization, joints: Array) -> tuple[Array, Array]:
    """Scaled point Jacobians (n, 3, n_est) and noise covariances (n, 3, 3) at `joints`."""
    points, jac = forward_points_and_jacobian(model.layout, lin.estimate, joints)
    a_mat = jac[:, :, lin.estimated] / lin.scale
    jq = jac[:, :, joint_columns(model.layout)]
    distance = np.linalg.norm(points - lin.tracker_origin, axis=1)
    tracker_var = (lin.tracker_a + lin.tracker_b * distance) ** 2 / 3.0
    noise = tracker_var[:, None, None] * np.eye(3) + _encoder_covariance(lin.encoder_var, jq)
    # A floor keeps R invertible when only one source is on and a Jacobian is degenerate.
    noise += np.eye(3) * 1e-30
    return a_mat, noise


def rank_candidates(
    model: RobotModel, lin: Linearization, candidates: ArrayLike, *, covariance: Array | None = None
) -> Array:
    """First-order reduction of ``sum_k trace C_k`` for each candidate, shape (n,) [m^2].

    Parameters
    ----------
    model : RobotModel
    lin : Linearization
    candidates : array_like, shape (n, n_joints) [rad]
    covariance : ndarray, shape (n_est, n_est), optional
        H^-1 to start from (default: the campaign's), e.g. after earlier suggestions.
    """
    q = np.atleast_2d(np.asarray(candidates, dtype=np.float64))
    if q.ndim != 2 or q.shape[1] != model.n_joints:
        msg = f"candidates must have shape (n, {model.n_joints}), got {q.shape}"
        raise InputError(msg)
    a_c, r_c = _pose_terms(model, lin, q)
    cov = lin.covariance if covariance is None else covariance
    gtg = np.einsum("kan,kam->nm", lin.test_jacobian, lin.test_jacobian)
    b_mat = cov @ gtg @ cov
    s = r_c + np.einsum("can,nm,cbm->cab", a_c, cov, a_c)
    t = np.einsum("can,nm,cbm->cab", a_c, b_mat, a_c)
    return np.asarray(np.trace(np.linalg.solve(s, t), axis1=1, axis2=2), dtype=np.float64)


def with_simulated_pose(campaign: Campaign, model: RobotModel, estimate: Array, joints: ArrayLike) -> Campaign:
    """`campaign` plus poses measured at the calibrated model's predicted points.

    Parameters
    ----------
    joints : array_like, shape (n_new, n_joints) [rad]
    """
    q = np.atleast_2d(np.asarray(joints, dtype=np.float64))
    points = forward_points(model.layout, estimate, q)
    point_std = None
    if campaign.point_std is not None:
        point_std = np.vstack([campaign.point_std, np.repeat(campaign.point_std.mean(axis=0)[None], len(q), axis=0)])
    stamps = None
    if campaign.stamps_ns is not None:
        last = int(campaign.stamps_ns.max())
        stamps = np.concatenate([campaign.stamps_ns, last + 1 + np.arange(len(q), dtype=np.int64)])
    return replace(
        campaign,
        joint_positions=np.vstack([campaign.joint_positions, q]),
        points=np.vstack([campaign.points, points]),
        point_std=point_std,
        stamps_ns=stamps,
    )


def _check_counts(*, n_candidates: int, count: int, monte_carlo_check: int, trials: int) -> None:
    """Refuse counts that are not integers at or above their least value."""
    for name, value, low in (
        ("n_candidates", n_candidates, 1),
        ("count", count, 1),
        ("monte_carlo_check", monte_carlo_check, 0),
        ("trials", trials, 1),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            msg = f"{name} must be an integer >= {low}, got {value!r}"
            raise InputError(msg)


def _candidate_joints(
    model: RobotModel, candidates: ArrayLike | None, n_candidates: int, rng: np.random.Generator, margin_rad: float
) -> Array:
    """The given candidates (checked against the joint limits), or `n_candidates` drawn inside them."""
    if candidates is None:
        return draw_joint_positions(model, n_candidates, rng=rng, margin=margin_rad)
    q_c = np.atleast_2d(np.asarray(candidates, dtype=np.float64))
    check_joint_limits(model, q_c, what="candidate")
    return q_c


def _greedy_order(model: RobotModel, lin: Linearization, q_c: Array, count: int) -> tuple[list[int], list[float]]:
    """Candidate indices in suggestion order, and the predicted RMS u [m] after each is added.

    Each next suggestion is the best given the ones before it measured (information update), so
    the suggestions complement each other.
    """
    order: list[int] = []
    predicted: list[float] = []
    information = lin.information.copy()
    covariance = lin.covariance
    a_all, r_all = _pose_terms(model, lin, q_c)
    for _ in range(min(count, len(q_c))):
        gains = rank_candidates(model, lin, q_c, covariance=covariance)
        gains[order] = -np.inf
        best = int(np.argmax(gains))
        order.append(best)
        information = information + a_all[best].T @ np.linalg.solve(r_all[best], a_all[best])
        covariance = np.linalg.inv(information)
        predicted.append(_rms_u(lin.test_covariances(information)))
    return order, predicted


@dataclass(frozen=True)
class _MonteCarloCheck:
    """Monte Carlo RMS u [m] of the current campaign and with the first suggestions added."""

    current: float
    checked: dict[int, float]


def _monte_carlo_check(
    model: RobotModel,
    campaign: Campaign,
    q_test: Array,
    evaluation: EvaluationSettings,
    estimate: Array,
    added: list[Array],
) -> _MonteCarloCheck:
    """Evaluate the current campaign and, for each entry of `added`, the campaign with those poses simulated."""

    def mc_u(c: Campaign) -> float:
        result = evaluate_uncertainty(model, c, q_test, evaluation)
        if result.not_converged:  # diverged trials: no statement to rank by
            msg = f"the Monte Carlo check did not converge to a statement: {result.not_converged[0]}"
            raise ConvergenceError(msg)
        return _rms_u(np.array([pose.covariance for pose in result.poses]))

    current = mc_u(campaign)
    checked = {j: mc_u(with_simulated_pose(campaign, model, estimate, joints)) for j, joints in enumerate(added)}
    return _MonteCarloCheck(current, checked)


def _suggestions(
    model: RobotModel,
    lin: Linearization,
    q_c: Array,
    order: list[int],
    predicted: list[float],
    check: _MonteCarloCheck | None,
    *,
    seed: int,
    trials: int,
    backend: str,
) -> Suggestions:
    """The ranked suggestions with the reductions of every candidate and, where made, the checks."""
    reductions = rank_candidates(model, lin, q_c)
    checked = {} if check is None else check.checked
    suggestions = tuple(
        PoseSuggestion(
            joint_positions=q_c[i].copy(),
            reduction_m2=float(reductions[i]),
            predicted_u_m=predicted[j],
            monte_carlo_u_m=checked.get(j),
        )
        for j, i in enumerate(order)
    )
    return Suggestions(
        suggestions=suggestions,
        current_u_m=_rms_u(lin.test_covariances()),
        monte_carlo_current_u_m=None if check is None else check.current,
        candidates=q_c,
        reductions_m2=reductions,
        joint_names=model.joint_names,
        frame_id=lin.frame_id,
        trials=0 if check is None else trials,
        seed=seed,
        backend=None if check is None else resolve_backend(backend),
    )


def suggest_poses(
    model: RobotModel,
    campaign: Campaign,
    test_joints: ArrayLike,
    *,
    settings: UncertaintySettings | None = None,
    calibration: IdentificationResult | None = None,
    lambda_: str | float = "auto",
    candidates: ArrayLike | None = None,
    n_candidates: int = 500,
    count: int = 5,
    monte_carlo_check: int = 0,
    trials: int = 2000,
    seed: int = 0,
    margin_rad: float = 0.05,
    frame: str = "measurement",
    backend: str = "numpy",
) -> Suggestions:
    """Rank candidate configurations by the uncertainty they would remove (module docstring).

    Parameters
    ----------
    model : RobotModel
    campaign : Campaign
        Point campaign measured so far.
    test_joints : array_like, shape (n_test, n_joints) [rad]
        Configurations whose tool-position uncertainty should fall.
    settings : UncertaintySettings, optional
        Noise models and sources (also of the Monte Carlo checks).
    calibration : IdentificationResult, optional
        Of `campaign`; identified with `lambda_` when omitted.
    lambda_ : {"auto", "gcv"} or float
    candidates : array_like, shape (n, n_joints) [rad], optional
        Configurations to rank; default `n_candidates` drawn uniformly inside the joint
        limits shrunk by `margin_rad`.
    n_candidates : int
    count : int
        Suggestions returned.
    monte_carlo_check : int
        The first this many suggestions are checked by Monte Carlo (0: none): suggestion j
        with suggestions 1..j added, and the current campaign as reference.
    trials : int
        Monte Carlo trials per evaluation.
    seed : int
        Seed of the candidate draw and of every Monte Carlo evaluation (the same for all,
        so the checks differ by the added pose only).
    margin_rad : float [rad]
    frame : {"measurement", "base"}
    backend : {"numpy", "numba", "cupy", "auto"}
        Trial kernels of the Monte Carlo checks (see
        :attr:`~robocal_uncertainty.uncertainty.EvaluationSettings.backend`).

    Returns
    -------
    Suggestions

    Raises
    ------
    InputError
        Bad shapes, candidates outside the joint limits, non-point campaign, singular problem.
    """
    settings = settings or UncertaintySettings()
    _check_counts(n_candidates=n_candidates, count=count, monte_carlo_check=monte_carlo_check, trials=trials)
    get_backend(backend)  # an unknown or missing backend stops here, before any work
    q_c = _candidate_joints(model, candidates, n_candidates, np.random.default_rng(seed), margin_rad)
    if calibration is None:
        calibration = identify(model, campaign, lambda_=lambda_)
    q_test = np.atleast_2d(np.asarray(test_joints, dtype=np.float64))
    lin = linearize(model, campaign, q_test, calibration, settings, frame=frame)
    order, predicted = _greedy_order(model, lin, q_c, count)
    check = None
    if monte_carlo_check:
        evaluation = EvaluationSettings(
            uncertainty=settings, lambda_=lambda_, trials=trials, seed=seed, frame=frame, backend=backend
        )
        added = [q_c[order[: j + 1]] for j in range(min(monte_carlo_check, len(order)))]
        check = _monte_carlo_check(model, campaign, q_test, evaluation, calibration.estimate, added)
    return _suggestions(model, lin, q_c, order, predicted, check, seed=seed, trials=trials, backend=backend)


DEFAULT_COUNT = 5
DEFAULT_CANDIDATES = 500
DEFAULT_TRIALS = 2000


def service_arguments(
    *,
    n_joints: int,
    count: int,
    candidates: ArrayLike,
    candidate_count: int,
    monte_carlo_check: int,
    trials: int,
    seed: int,
) -> dict[str, object]:
    """Keyword arguments of :func:`suggest_poses` from a ``SuggestPoses`` request's fields.

    Zeros mean the defaults (5 suggestions, 500 sampled candidates, 2000 trials); an empty
    `candidates` means sampling; a non-empty one holds `n_joints` values per configuration.

    Raises
    ------
    InputError
        `candidates` is not a whole number of configurations.
    """
    flat = np.asarray(candidates, dtype=np.float64).reshape(-1)
    if flat.size % n_joints:
        msg = f"candidates: {flat.size} values are not a multiple of the {n_joints} joints"
        raise InputError(msg)
    return {
        "candidates": flat.reshape(-1, n_joints) if flat.size else None,
        "n_candidates": int(candidate_count) or DEFAULT_CANDIDATES,
        "count": int(count) or DEFAULT_COUNT,
        "monte_carlo_check": int(monte_carlo_check),
        "trials": int(trials) or DEFAULT_TRIALS,
        "seed": int(seed),
    }


def service_response(result: Suggestions) -> dict[str, object]:
    """The fields of a ``SuggestPoses`` response (see ``srv/SuggestPoses.srv``) for `result`."""
    nan = float("nan")
    n = len(result.suggestions)
    message = (
        f"{n} pose(s) from {len(result.candidates)} candidates: first-order RMS u_pos "
        f"{result.current_u_m * 1e6:.2f} -> {result.suggestions[-1].predicted_u_m * 1e6:.2f} um"
        if n
        else "no candidate"
    )
    if result.monte_carlo_current_u_m is not None:
        message += f"; Monte Carlo ({result.trials} trials) now {result.monte_carlo_current_u_m * 1e6:.2f} um"
    return {
        "success": bool(n),
        "message": message,
        "joint_names": list(result.joint_names),
        "joint_positions": [float(v) for s in result.suggestions for v in s.joint_positions],
        "current_u": float(result.current_u_m),
        "predicted_u": [float(s.predicted_u_m) for s in result.suggestions],
        "monte_carlo_current_u": nan
        if result.monte_carlo_current_u_m is None
        else float(result.monte_carlo_current_u_m),
        "monte_carlo_u": [nan if s.monte_carlo_u_m is None else float(s.monte_carlo_u_m) for s in result.suggestions],
        "frame_id": result.frame_id,
    }
