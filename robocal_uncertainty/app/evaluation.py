"""The evaluation service: calibration, Monte Carlo uncertainty, budget and sweeps of a campaign.

:func:`evaluate` is the one path from a campaign and
:class:`~robocal_uncertainty.uncertainty.options.EvaluationOptions` to results: the command
line's ``evaluate``, ``demo`` and ``replay``, the uncertainty node and the tests all call
it, so the same campaign, options and seed give the same numbers bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from robocal_uncertainty.bagio.campaign_reader import READ_WARNINGS_KEY
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.budget import evaluate_budget
from robocal_uncertainty.uncertainty.calibration_mc import CalibrationUncertainty
from robocal_uncertainty.uncertainty.options import EvaluationOptions, Progress, evaluate_campaign
from robocal_uncertainty.uncertainty.sweeps import Sweep, evaluate_sweeps

__all__ = ["Evaluation", "evaluate"]


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Everything :func:`evaluate` produced.

    Attributes
    ----------
    calibration : IdentificationResult
        The identification of the whole campaign (shared by every run below).
    uncertainty : CalibrationUncertainty
        The Monte Carlo result of ``options`` (positions [m] at the test configurations).
    budget : mapping of str to CalibrationUncertainty
        Each source alone (read-only; empty unless ``options.budget`` and two or more sources).
    sweeps : tuple of Sweep
        u against lambda and against the number of equations (empty unless ``options.sweeps``).
    warnings : tuple of str
        One-line warnings about the inputs (e.g. the campaign file was truncated and
        recovered), then the result's own (``uncertainty.warnings``), each once.
    input_warnings : tuple of str
        The first group of `warnings` alone (reports list them apart).
    """

    calibration: IdentificationResult
    uncertainty: CalibrationUncertainty
    budget: Mapping[str, CalibrationUncertainty]
    sweeps: tuple[Sweep, ...]
    warnings: tuple[str, ...]
    input_warnings: tuple[str, ...] = ()


def _merge(*groups: Sequence[str]) -> tuple[str, ...]:
    out: list[str] = []
    for group in groups:
        out += [str(w) for w in group if str(w) not in out]
    return tuple(out)


def evaluate(
    model: RobotModel,
    campaign: Campaign,
    options: EvaluationOptions,
    *,
    calibration: IdentificationResult | None = None,
    executor: Any | None = None,
    workers: int = 1,
    progress: Progress | None = None,
    input_warnings: Sequence[str] = (),
) -> Evaluation:
    """Calibrate `campaign` and evaluate its uncertainty, budget and sweeps as `options` say.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Joint readings [rad] and points [m]. Its reader's warnings
        (``campaign.metadata["warnings"]``) are carried into the result's warnings.
    options : EvaluationOptions
        Must have ``test_joints``.
    calibration : IdentificationResult, optional
        ``identify(model, campaign, lambda_=options.lambda_,
        accept_unconverged=options.accept_unconverged)`` if already computed (a node's
        pipeline has it); computed so when omitted, so the result does not depend on it.
    executor : concurrent.futures.Executor-like, optional
        Runs the Monte Carlo trial blocks (forwarded only when given); never changes the result.
    workers : int
        Local worker processes when no `executor` is given; never changes the result.
    progress : callable, optional
        ``progress(done, target)`` of the main Monte Carlo run.
    input_warnings : sequence of str
        Further warnings about the inputs (e.g. dropped messages of a replay), listed after
        the campaign's.

    Returns
    -------
    Evaluation

    Raises
    ------
    ConfigError
        No test joints, or invalid options.
    IdentifiabilityError, ConvergenceError
        The campaign cannot identify the model (see
        :func:`~robocal_uncertainty.core.identification.identify`).
    """
    if options.test_joints is None:
        raise ConfigError("no test joint configurations given for the uncertainty evaluation")
    if calibration is None:
        calibration = identify(model, campaign, lambda_=options.lambda_, accept_unconverged=options.accept_unconverged)
    uncertainty = evaluate_campaign(
        model, campaign, options, calibration=calibration, workers=workers, progress=progress, executor=executor
    )
    budget: Mapping[str, CalibrationUncertainty] = MappingProxyType({})
    if options.budget:
        budget = evaluate_budget(model, campaign, calibration, options, workers=workers, executor=executor)
    sweeps: tuple[Sweep, ...] = ()
    if options.sweeps:
        sweeps = evaluate_sweeps(model, campaign, calibration, options, workers=workers, executor=executor)
    inputs = _merge(campaign.metadata.get(READ_WARNINGS_KEY) or (), input_warnings)
    return Evaluation(
        calibration=calibration,
        uncertainty=uncertainty,
        budget=budget,
        sweeps=sweeps,
        warnings=_merge(inputs, uncertainty.warnings),
        input_warnings=inputs,
    )
