"""Uncertainty of the tool position as one setting varies (the robot reference paper's Figs. 7-9).

Each point is a small Monte Carlo run (a few hundred trials by default): the curves show
trends, not uncertainty statements. Every point uses the same root seed, so differences
between points come from the setting, not from the random stream.

:func:`evaluate_sweeps` gives the report's two standard curves (against lambda and against
the number of equations) from :class:`~robocal_uncertainty.uncertainty.calibration.settings.EvaluationSettings`;
:mod:`robocal_uncertainty.report` only plots and tabulates the :class:`Sweep` results.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration.preparation import held_field_correlation
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.sources import (
    UncertaintySettings,
    source_with_role,
    sources_in_sweeps,
    sources_with_role,
)
from robocal_uncertainty.uncertainty.sources.instrument import ENCODER, TRACKER

__all__ = ["DEFAULT_SWEEP_TRIALS", "Sweep", "evaluate_sweeps", "sweep_equations", "sweep_lambda"]

Array = NDArray[np.float64]
DEFAULT_SWEEP_TRIALS = 300


@dataclass(frozen=True, eq=False)
class Sweep:
    """A named uncertainty curve, for reports and plots.

    Attributes
    ----------
    name : str
        Short identifier, e.g. ``"lambda"`` or ``"equations"``.
    xlabel : str
        Axis label of `values`, with its unit.
    values : ndarray, shape (n_points,)
        The swept setting (lambda in scaled units, or a number of equations).
    standard_uncertainty : ndarray, shape (n_points, 3) [m]
        u(x), u(y), u(z) at each point.
    reference : float or None
        Value to mark (the calibration's lambda, or the campaign's equation count).
    log_x : bool
        Plot `values` on a logarithmic axis.
    n_trials : int or None
        Trials per point.
    seed : int or None
        Root seed of every point.
    """

    name: str
    xlabel: str
    values: Array
    standard_uncertainty: Array
    reference: float | None = None
    log_x: bool = False
    n_trials: int | None = None
    seed: int | None = None

    def __post_init__(self) -> None:
        values = np.asarray(self.values, dtype=np.float64).reshape(-1)
        u = np.asarray(self.standard_uncertainty, dtype=np.float64)
        if u.shape != (values.size, 3):
            msg = f"sweep {self.name!r}: standard_uncertainty must have shape ({values.size}, 3), got {u.shape}"
            raise ConfigError(msg)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "standard_uncertainty", u)


def _check_pose(pose: int, test_joints: ArrayLike) -> None:
    n_test = 1 if np.ndim(test_joints) == 1 else int(np.shape(test_joints)[0])
    if not 0 <= pose < n_test:
        msg = f"pose index {pose} out of range for {n_test} test configuration(s)"
        raise ConfigError(msg)


def _check_points(name: str, values: ArrayLike) -> Array:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size == 0 or not np.isfinite(arr).all():
        msg = f"{name} must be a non-empty sequence of finite numbers, got {values!r}"
        raise ConfigError(msg)
    return arr


def sweep_lambda(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult | None,
    test_joints: ArrayLike,
    lambdas: ArrayLike,
    *,
    trials: int = DEFAULT_SWEEP_TRIALS,
    seed: int = 0,
    settings: UncertaintySettings | None = None,
    pose: int = 0,
    frame: str = "measurement",
    backend: str = "numpy",
    run: RunContext | None = None,
) -> Array:
    """Standard uncertainty of the tool position with lambda fixed at each value (Fig. 7).

    At each lambda the campaign is re-identified with ``identify(model, campaign,
    lambda_=value)`` and that calibration is passed to ``evaluate_uncertainty``. The
    ``lambda`` source is dropped from `settings` (lambda is the swept, fixed value). A
    model-error field (``model_error="field"``) keeps `calibration`'s correlation and shape at
    every point, its per-pose covariance re-estimated from the point's residuals
    (:func:`~robocal_uncertainty.uncertainty.model_error_draws.rescaled_field`): the curve shows
    the effect of lambda, not a re-estimate of the field's hyperparameters (in full per point
    when `calibration` is None).

    Parameters
    ----------
    model : RobotModel
    campaign : Campaign
    calibration : IdentificationResult or None
        The reference calibration; reused (not re-identified) where a point's lambda
        equals its lambda.
    test_joints : ndarray, shape (n_test, n_joints) or (n_joints,) [rad]
    lambdas : array_like, shape (n_points,) [-]
        Lambdas in the column-scaled units of the identification, each >= 0.
    trials : int
        Monte Carlo trials per point.
    seed : int
        Root seed used for every point.
    settings : UncertaintySettings, optional
        Sources and their models (default: tracker and encoder).
    pose : int
        Which test configuration to report.
    frame : {"measurement", "base"}
        Frame of the output positions.
    backend : str
        Trial kernels (:attr:`~robocal_uncertainty.uncertainty.EvaluationSettings.backend`).
    run : RunContext, optional
        Where the points run (never changes the result); its ``progress`` is called after
        each point with the trials done and the total.

    Returns
    -------
    ndarray, shape (n_points, 3) [m]
        u(x), u(y), u(z) at each lambda.
    """
    lams = _check_points("lambdas", lambdas)
    if (lams < 0).any():
        msg = f"lambdas must be >= 0, got {lams.min()}"
        raise ConfigError(msg)
    _check_pose(pose, test_joints)
    settings = settings or UncertaintySettings()
    # lambda is the swept variable: the source that draws it is off at every point.
    swept = sources_with_role(settings.sources, "lambda")
    sources = tuple(s for s in settings.sources if s not in swept) or (TRACKER.name,)
    fixed = dataclasses.replace(settings, sources=sources)
    out = np.empty((lams.size, 3))
    # A model-error field keeps the reference calibration's correlation and shape at every point,
    # its per-pose covariance re-estimated from that point's residuals (see held_field_correlation).
    with held_field_correlation(calibration):
        for i, lam in enumerate(lams):
            if calibration is not None and float(lam) == calibration.lambda_:
                cal = calibration
            else:
                cal = identify(model, campaign, lambda_=float(lam))
            out[i] = _point_u(
                model,
                campaign,
                test_joints,
                fixed,
                cal,
                trials=trials,
                seed=seed,
                frame=frame,
                run=run,
                pose=pose,
                backend=backend,
            )
            if run is not None and run.progress is not None:
                run.progress((i + 1) * trials, lams.size * trials)
    return out


def _point_u(
    model: RobotModel,
    campaign: Campaign,
    test_joints: ArrayLike,
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    *,
    trials: int,
    seed: int,
    frame: str,
    run: RunContext | None,
    pose: int,
    backend: str = "numpy",
) -> list[float]:
    """u(x), u(y), u(z) of test configuration `pose` for one sweep point (its own progress: none)."""
    res = evaluate_uncertainty(
        model,
        campaign,
        test_joints,
        EvaluationSettings(uncertainty=settings, trials=trials, seed=seed, frame=frame, backend=backend),
        calibration=calibration,
        run=None if run is None else run.with_progress(None),
    )
    return [a.standard_uncertainty for a in res.poses[pose].axes]


def sweep_equations(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult | None,
    test_joints: ArrayLike,
    pose_counts: Sequence[int] | ArrayLike,
    *,
    trials: int = DEFAULT_SWEEP_TRIALS,
    seed: int = 0,
    settings: UncertaintySettings | None = None,
    pose: int = 0,
    frame: str = "measurement",
    backend: str = "numpy",
    run: RunContext | None = None,
) -> Array:
    """Standard uncertainty when each trial re-identifies from n random poses (Figs. 8-9).

    Each point runs ``evaluate_uncertainty`` with the ``pose_choice`` source at
    ``subset_size = n`` (3 n equations) on top of the given sources; the ``n_poses``
    source is dropped, since the number of equations is what is fixed per point.

    Parameters
    ----------
    model : RobotModel
    campaign : Campaign
    calibration : IdentificationResult or None
        Calibration of the whole campaign (identified once when None).
    test_joints : ndarray, shape (n_test, n_joints) or (n_joints,) [rad]
    pose_counts : sequence of int, length n_points
        Poses per subset, each between ceil(n_identifiable / 3) and the campaign size.
    trials, seed, settings, pose, frame, backend, run
        As for :func:`sweep_lambda`.

    Returns
    -------
    ndarray, shape (n_points, 3) [m]
        u(x), u(y), u(z) at each pose count.

    Raises
    ------
    ConfigError
        A pose count that is not an integer, or outside the identifiable range.
    """
    counts_f = _check_points("pose_counts", pose_counts)
    if (counts_f != np.round(counts_f)).any():
        msg = f"pose_counts must be integers, got {pose_counts!r}"
        raise ConfigError(msg)
    _check_pose(pose, test_joints)
    settings = settings or UncertaintySettings()
    # Each point draws subsets of its pose count: the pose-subset source on, the pose-count one off.
    swept = sources_with_role(settings.sources, "pose_count")
    sources = tuple(s for s in settings.sources if s not in swept)
    subsets = source_with_role("pose_subset")
    if subsets not in sources:
        sources = (*sources, subsets)
    if calibration is None:
        calibration = identify(model, campaign)
    out = np.empty((counts_f.size, 3))
    for i, n in enumerate(counts_f.astype(int)):
        point = dataclasses.replace(settings, sources=sources, subset_size=int(n))
        out[i] = _point_u(
            model,
            campaign,
            test_joints,
            point,
            calibration,
            trials=trials,
            seed=seed,
            frame=frame,
            run=run,
            pose=pose,
            backend=backend,
        )
        if run is not None and run.progress is not None:
            run.progress((i + 1) * trials, counts_f.size * trials)
    return out


def _sweep_points(calibration: IdentificationResult, n_poses: int) -> tuple[Array, NDArray[np.int_]]:
    """The lambdas and pose counts of the report's sweeps (see :func:`evaluate_sweeps`)."""
    lam = calibration.lambda_
    lambdas = np.geomspace(lam / 10.0, lam * 10.0, 9) if lam > 0 else np.geomspace(1e-4, 1e-1, 9)
    n_est = int(calibration.estimated.sum())
    lowest = max(int(np.ceil(1.5 * n_est / 3)), int(np.ceil(40 / 3)))
    counts = np.unique(np.linspace(min(lowest, n_poses), n_poses, 8).round().astype(int))
    return lambdas, counts


def evaluate_sweeps(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult,
    options: EvaluationSettings,
    *,
    run: RunContext | None = None,
) -> tuple[Sweep, ...]:
    """The report's sweeps: u against lambda (reference paper Fig. 7) and against the number of equations (Figs. 8-9).

    Lambda: 9 values spaced logarithmically from lambda*/10 to 10 lambda* (1e-4 .. 1e-1
    when lambda* = 0). Equations: 8 pose counts from max(1.5 n_estimated / 3, 40 / 3) poses
    to the whole campaign. Each point runs ``options.sweep_trials`` trials with
    ``options.seed`` and the noise sources of ``options.uncertainty`` (tracker, encoder,
    residual; tracker and encoder when it has none of them), at the first test configuration.

    Parameters
    ----------
    model : RobotModel
    campaign : Campaign
    calibration : IdentificationResult
        Calibration of the whole campaign (the reference lambda and pose count).
    options : EvaluationSettings
        Must have ``test_joints``.
    run : RunContext, optional
        Where the points run (never changes the result); its ``progress`` is called after
        each point with the trials done over both sweeps and their total.

    Returns
    -------
    tuple of Sweep
        ``"lambda"`` then ``"equations"``; standard uncertainties [m].
    """
    if options.test_joints is None:
        raise ConfigError("no test joint configurations given for the sweeps")
    settings = options.uncertainty
    noise = dataclasses.replace(
        settings,
        sources=sources_in_sweeps(settings.sources) or (TRACKER.name, ENCODER.name),
    )
    lam = calibration.lambda_
    lambdas, counts = _sweep_points(calibration, campaign.n_poses)
    trials, seed = options.sweep_trials, options.seed
    common: dict[str, Any] = {
        "trials": trials,
        "seed": seed,
        "settings": noise,
        "frame": options.frame,
        "backend": options.backend,
    }
    run = run or RunContext()
    progress = run.progress
    total = (lambdas.size + counts.size) * trials

    def _shifted(offset: int) -> RunContext:
        if progress is None:
            return run
        return run.with_progress(lambda done, _total: progress(offset + done, total))

    u_lam = sweep_lambda(model, campaign, calibration, options.test_joints, lambdas, run=_shifted(0), **common)
    u_eq = sweep_equations(
        model, campaign, calibration, options.test_joints, counts, run=_shifted(lambdas.size * trials), **common
    )
    return _as_sweeps(lambdas, u_lam, lam, counts, u_eq, campaign.n_poses, trials, seed)


def _as_sweeps(
    lambdas: Array,
    u_lam: Array,
    lam: float,
    counts: NDArray[np.int_],
    u_eq: Array,
    n_poses: int,
    trials: int,
    seed: int,
) -> tuple[Sweep, Sweep]:
    """The two curves of :func:`evaluate_sweeps` as :class:`Sweep` results."""
    return (
        Sweep(
            name="lambda",
            xlabel="lambda (scaled units)",
            values=lambdas,
            standard_uncertainty=u_lam,
            reference=lam,
            log_x=True,
            n_trials=trials,
            seed=seed,
        ),
        Sweep(
            name="equations",
            xlabel="number of equations (3 per pose)",
            values=3 * counts.astype(float),
            standard_uncertainty=u_eq,
            reference=float(3 * n_poses),
            log_x=False,
            n_trials=trials,
            seed=seed,
        ),
    )
