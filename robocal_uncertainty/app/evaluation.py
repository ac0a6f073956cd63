"""The evaluation service: calibration, Monte Carlo uncertainty, budget and sweeps of a campaign.

:func:`evaluate` is the one path from a campaign and
:class:`~robocal_uncertainty.uncertainty.calibration.settings.EvaluationSettings` to results:
the command line's ``evaluate``, ``demo`` and ``replay``, the uncertainty node, ``compensate``
and the tests all call it, so the same campaign, settings and seed give the same numbers bit
for bit (with the small-campaign adaptation, the trial floor and the memory check applied for
every caller alike).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.bagio.campaign_reader import READ_WARNINGS_KEY
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.budget import evaluate_budget
from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration.results import CalibrationUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.field_kriging import corrected_uncertainty, field_basis
from robocal_uncertainty.uncertainty.memory import check_fits, evaluation_bytes
from robocal_uncertainty.uncertainty.sources import sources_with_role
from robocal_uncertainty.uncertainty.statement_check import interval_trial_floor, recommended_trials
from robocal_uncertainty.uncertainty.sweeps import Sweep, evaluate_sweeps

__all__ = ["Evaluation", "PhaseProgress", "evaluate", "small_campaign_options"]

PhaseProgress = Callable[[str, int, "int | None"], None]
"""``phase_progress(phase, done, total)`` of the phases after the main run: ``"budget"``
(trials done over all single-source runs, of ``total``) and ``"sweeps"`` (trials done over
all sweep points, of ``total``)."""


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
    notes : tuple of str
        What was adapted to the campaign (e.g. the pose-count defaults of a small
        campaign), one line each; not warnings: the result is as asked.
    """

    calibration: IdentificationResult
    uncertainty: CalibrationUncertainty
    budget: Mapping[str, CalibrationUncertainty]
    sweeps: tuple[Sweep, ...]
    warnings: tuple[str, ...]
    input_warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


def _merge(*groups: Sequence[str]) -> tuple[str, ...]:
    out: list[str] = []
    for group in groups:
        out += [str(w) for w in group if str(w) not in out]
    return tuple(out)


def small_campaign_options(
    campaign: Campaign, calibration: IdentificationResult, options: EvaluationSettings
) -> tuple[EvaluationSettings, tuple[str, ...]]:
    """Adapt the pose-count defaults to a campaign too small for them; return the notes.

    The defaults of ``min_poses`` (40 equations or 1.5 x the identifiable parameters) and
    ``subset_size`` (33/53 of the poses) suit the reference paper's 53 poses. When a default does not
    fit the campaign and the ``n_poses`` or ``pose_choice`` source or the sweeps need it, it
    becomes the fewest poses that identify the model (identifiable parameters / 3); values
    the caller set are never changed.
    """
    settings = options.uncertainty
    sources = settings.sources
    n_poses = campaign.n_poses
    dim = int(campaign.points.shape[1])
    k = int(calibration.estimated.sum())
    fewest = math.ceil(k / dim)
    notes: list[str] = []
    changes: dict[str, Any] = {}
    default_min = max(math.ceil(40 / dim), math.ceil(1.5 * k / dim))
    counts = sources_with_role(sources, "pose_count")
    subsets = sources_with_role(sources, "pose_subset")
    uses_min = bool(counts or subsets) or options.sweeps
    if settings.min_poses is None and uses_min and default_min > n_poses:
        changes["min_poses"] = fewest
        if counts:
            notes.append(
                f"the campaign's {n_poses} poses are fewer than the {default_min} the {counts[0]} source starts from "
                f"by default (40 equations or 1.5 x the {k} identifiable parameters): it draws {fewest} to "
                f"{n_poses} poses ({fewest} = identifiable parameters / {dim}); set min_poses to choose"
            )
    default_subset = round(33 / 53 * n_poses)
    if settings.subset_size is None and subsets and default_subset < fewest:
        changes["subset_size"] = fewest
        notes.append(
            f"33/53 of the campaign's {n_poses} poses ({default_subset}) cannot identify the {k} parameters: "
            f"the {subsets[0]} source draws subsets of {fewest} poses; set subset_size to choose"
        )
    if not changes:
        return options, ()
    adapted = dataclasses.replace(options, uncertainty=dataclasses.replace(settings, **changes))
    return adapted, tuple(notes)


def evaluate(
    model: RobotModel,
    campaign: Campaign,
    settings: EvaluationSettings,
    *,
    calibration: IdentificationResult | None = None,
    run: RunContext | None = None,
    phase_progress: PhaseProgress | None = None,
    input_warnings: Sequence[str] = (),
    field_correction: bool = False,
) -> Evaluation:
    """Calibrate `campaign` and evaluate its uncertainty, budget and sweeps as `settings` say.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Joint readings [rad] and points [m]. Its reader's warnings
        (``campaign.metadata["warnings"]``) are carried into the result's warnings.
    settings : EvaluationSettings
        Must have ``test_joints``.
    calibration : IdentificationResult, optional
        ``identify(model, campaign, lambda_=settings.lambda_,
        accept_unconverged=settings.accept_unconverged)`` if already computed (a node's
        pipeline has it); computed so when omitted, so the result does not depend on it.
    run : RunContext, optional
        Where the trial blocks run (executor, local workers) and the main run's
        ``progress(done, target)``; never changes the result. Default: in this process.
    phase_progress : callable, optional
        Progress of the budget and the sweeps (see :data:`PhaseProgress`).
    input_warnings : sequence of str
        Further warnings about the inputs (e.g. dropped messages of a replay), listed after
        the campaign's.
    field_correction : bool
        Add the model-error field's conditional mean given the calibration residuals (kriging)
        to every test configuration's position, with the kriging covariance in the statement
        (:func:`~robocal_uncertainty.uncertainty.field_kriging.corrected_uncertainty`, as
        ``fk`` and ``map`` do; the budget and sweeps stay uncorrected). Refused (one line)
        when the calibration estimates no field.

    Returns
    -------
    Evaluation
        Pose-count defaults that do not fit a small campaign are adapted first (see
        :func:`small_campaign_options`; said in ``notes``).

    Raises
    ------
    ConfigError
        No test joints, invalid settings, a fixed trial count below 2/(1-p) for the
        coverage probability asked (no trial beyond the interval's ends), a size that
        cannot fit in memory, or `field_correction` for a calibration without a field.
    IdentifiabilityError, ConvergenceError
        The campaign cannot identify the model (see
        :func:`~robocal_uncertainty.core.identification.identify`).
    """
    run = run or RunContext()
    test_joints = _check_trials(settings)
    if calibration is None:
        calibration = identify(
            model, campaign, lambda_=settings.lambda_, accept_unconverged=settings.accept_unconverged
        )
    settings, notes = small_campaign_options(campaign, calibration, settings)
    _check_memory(model, campaign, calibration, settings, run)
    uncertainty = evaluate_uncertainty(model, campaign, test_joints, settings, calibration=calibration, run=run)
    if field_correction:
        uncertainty = corrected_uncertainty(uncertainty, field_basis(calibration, campaign, settings.uncertainty))
    budget, sweeps, sweep_notes = _phases(model, campaign, calibration, settings, run, phase_progress)
    read_warnings: Any = campaign.metadata.get(READ_WARNINGS_KEY) or ()  # strings the reader stored
    inputs = _merge(read_warnings, input_warnings)
    return Evaluation(
        calibration=calibration,
        uncertainty=uncertainty,
        budget=budget,
        sweeps=sweeps,
        warnings=_merge(inputs, uncertainty.warnings),
        input_warnings=inputs,
        notes=(*notes, *sweep_notes),
    )


def _check_trials(settings: EvaluationSettings) -> NDArray[np.float64]:
    """The test joints of `settings`; refuse a fixed trial count that cannot state the interval."""
    if settings.test_joints is None:
        raise ConfigError("no test joint configurations given for the uncertainty evaluation")
    if settings.trials != "auto" and int(settings.trials) < interval_trial_floor(settings.coverage):
        # Below 2/(1-p) not one trial lies beyond either end of the interval: no statement
        # (the command line says the same of --trials before this; the nodes and compensate
        # meet it here).
        floor = interval_trial_floor(settings.coverage)
        msg = (
            f"trials {int(settings.trials)} cannot state a {settings.coverage * 100:g} % coverage interval: below "
            f"2/(1-p) = {floor} trials not one trial lies beyond either end (JCGM 101 7.2); use "
            f"{recommended_trials(settings.coverage)} or more, or the adaptive procedure"
        )
        raise ConfigError(msg)
    return settings.test_joints


def _check_memory(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult,
    settings: EvaluationSettings,
    run: RunContext,
) -> None:
    """Refuse a size that cannot fit before the work, naming it, instead of an allocation
    traceback after minutes (the adaptive procedure is bounded by its own cap)."""
    if settings.trials == "auto":
        return
    n_test = 0 if settings.test_joints is None else int(np.atleast_2d(settings.test_joints).shape[0])
    check_fits(
        evaluation_bytes(
            int(settings.trials),
            n_test,
            int(np.count_nonzero(calibration.estimated)),
            n_poses=campaign.n_poses,
            n_joints=model.n_joints,
            block_rows=settings.block_size,
            workers=run.workers if run.executor is None else 1,
        ),
        f"--trials {int(settings.trials)} at {n_test} test configuration{'s' if n_test != 1 else ''}",
        "use fewer --trials (or fewer test configurations)",
    )


def _phases(
    model: RobotModel,
    campaign: Campaign,
    calibration: IdentificationResult,
    settings: EvaluationSettings,
    run: RunContext,
    phase_progress: PhaseProgress | None,
) -> tuple[Mapping[str, CalibrationUncertainty], tuple[Sweep, ...], tuple[str, ...]]:
    """The budget and the sweeps `settings` ask for, and a note for a sweep skipped."""

    def phase(name: str) -> RunContext:
        if phase_progress is None:
            return run.with_progress(None)
        return run.with_progress(lambda d, t: phase_progress(name, d, t))

    budget: Mapping[str, CalibrationUncertainty] = MappingProxyType({})
    if settings.budget:
        budget = evaluate_budget(model, campaign, calibration, settings, run=phase("budget"))
    sweeps: tuple[Sweep, ...] = ()
    notes: tuple[str, ...] = ()
    if settings.sweeps:
        sweeps = evaluate_sweeps(model, campaign, calibration, settings, run=phase("sweeps"))
        short = [sw for sw in sweeps if sw.name == "equations" and len(sw.values) < 2]
        if short:
            sweeps = tuple(sw for sw in sweeps if sw not in short)
            notes = (
                f"the sweep over the number of equations is skipped: the campaign's {campaign.n_poses} poses "
                "are fewer than the smallest pose count it starts from (40 equations or 1.5 x the identifiable "
                "parameters)",
            )
    return budget, sweeps, notes
