"""Uncertainty budget: the Monte Carlo run again with each source alone.

Each source's run uses the same calibration, root seed and test configurations as the
full evaluation, with ``options.budget_trials`` trials, so a budget row tells how much of
the combined uncertainty that source alone produces.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration.results import CalibrationUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = ["evaluate_budget"]


def evaluate_budget(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult,
    options: EvaluationSettings,
    *,
    run: RunContext | None = None,
) -> Mapping[str, CalibrationUncertainty]:
    """Each source of ``options.uncertainty`` alone, ``options.budget_trials`` trials each.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
    calibration : IdentificationResult
        Calibration of `campaign` (shared by every run).
    options : EvaluationSettings
        Must have ``test_joints``; its ``trials`` is replaced by ``budget_trials``.
    run : RunContext, optional
        Where the runs go (never changes the result); its ``progress`` is called with the
        trials done over all the sources and their total, as the runs go.

    Returns
    -------
    mapping of str to CalibrationUncertainty
        Read-only, in the order of the sources; empty with fewer than two sources (the
        budget would repeat the full evaluation).
    """
    sources = options.uncertainty.sources
    if len(sources) < 2:
        return MappingProxyType({})
    if options.test_joints is None:
        raise ConfigError("no test joint configurations given for the uncertainty evaluation")
    test_joints = options.test_joints
    run = run or RunContext()
    progress = run.progress
    total = len(sources) * options.budget_trials
    out = {}
    for i, source in enumerate(sources):
        alone = dataclasses.replace(
            options,
            uncertainty=dataclasses.replace(options.uncertainty, sources=(source,)),
            trials=options.budget_trials,
        )
        hook = None
        if progress is not None:
            before = i * options.budget_trials

            def hook(done: int, _target: int | None, before: int = before) -> None:
                progress(before + done, total)

        out[source] = evaluate_uncertainty(
            model, campaign, test_joints, alone, calibration=calibration, run=run.with_progress(hook)
        )
    return MappingProxyType(out)
