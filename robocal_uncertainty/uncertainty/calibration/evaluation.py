"""Monte Carlo uncertainty of a calibrated arm's tool pose (JCGM 101): the one service call.

A trial perturbs the campaign according to the enabled sources, re-identifies the
parameters, and evaluates the tool pose at every requested joint configuration: the tool
point and, unless switched off, the tool orientation (:mod:`.trials`). Trials run in blocks
with independent seeded streams (see :mod:`robocal_uncertainty.montecarlo.engine`), so the
result is the same whatever the chunk size or the number of workers.
"""

from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.engine import AdaptiveSettings, run_trials
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.calibration.preparation import prepare, validate_inputs
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, OUTPUT_FRAMES, CalibrationUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.calibration.statement import state_uncertainty

__all__ = ["evaluate_uncertainty"]


def evaluate_uncertainty(
    model: RobotModel,
    campaign: Campaign,
    test_joint_positions: ArrayLike,
    evaluation: EvaluationSettings | None = None,
    *,
    calibration: IdentificationResult | None = None,
    run: RunContext | None = None,
    per_pose: bool = False,
    **fields: Any,
) -> CalibrationUncertainty:
    """Monte Carlo uncertainty of the calibrated tool pose at test configurations.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration data (joint readings [rad], points [m]).
    test_joint_positions : ndarray, shape (n_test, n_joints) or (n_joints,) [rad]
        Configurations at which the tool pose is evaluated.
    evaluation : EvaluationSettings, optional
        What determines the result (sources, lambda method, trials, coverage, seed, ...);
        the defaults when omitted. Its ``test_joints``, budget and sweep fields are not read.
    calibration : IdentificationResult, optional
        An existing calibration of `campaign`; computed with ``evaluation.lambda_`` when omitted.
    run : RunContext, optional
        Where and how the trial blocks run (executor, workers, progress, chunking, start
        method); never changes the result. Default: in this process.
    per_pose : bool
        A statement of each test configuration alone, for a caller of thousands that reads each
        one's samples, standard uncertainties and GUM check (the held-out check): no JCGM 102
        coverage regions (``PoseUncertainty.region`` is None) and the first-order covariance
        within each configuration only (zero between configurations, each one's the same to
        rounding). The samples and the Monte Carlo summaries are the same, bit for bit.
    **fields
        Fields of :class:`EvaluationSettings` replaced in `evaluation` (``trials=``,
        ``seed=``, ``frame=``, ``uncertainty=``, ...), see :meth:`EvaluationSettings.replace`.

    Returns
    -------
    CalibrationUncertainty

    Raises
    ------
    ConfigError
        Bad settings (trials, coverage, test joints, lambda range, pose counts).
    """
    ev = (evaluation or EvaluationSettings()).replace(**fields)
    run = run or RunContext()
    if ev.frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {ev.frame!r}"
        raise ConfigError(msg)
    test_q, n_trials = validate_inputs(model, test_joint_positions, ev.coverage, ev.trials)
    prep = prepare(
        model, campaign, test_q, ev.uncertainty, calibration, ev.lambda_, ev.frame,
        orientation=ev.orientation, backend=ev.backend,
    )  # fmt: skip
    result = run_trials(
        prep.trials,
        seed=ev.seed,
        n_trials=n_trials,
        adaptive=None if n_trials is not None else _adaptive(ev, test_q.shape[0]),
        block_size=ev.block_size,
        chunk_blocks=run.chunk_blocks,
        workers=run.workers,
        executor=run.executor,
        progress=run.progress,
        mp_context=run.mp_context,
    )
    return state_uncertainty(prep, ev, result, per_pose=per_pose)


def _adaptive(ev: EvaluationSettings, n_test: int) -> AdaptiveSettings:
    """The JCGM 101 §7.9 procedure of `ev`.

    The measurand is the tool position: its components decide convergence; the parameter
    columns ride along and report the tolerance they reached.
    """
    return AdaptiveSettings(
        n_dig=ev.n_dig, coverage=ev.coverage, max_trials=ev.max_trials, monitored=tuple(range(N_AXES * n_test))
    )
