"""Monte Carlo uncertainty of a calibration: sources, batched re-identification, GUM check."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.budget import evaluate_budget
    from robocal_uncertainty.uncertainty.calibration_mc import (
        CalibrationTrials,
        CalibrationUncertainty,
        GumPose,
        PoseUncertainty,
        evaluate_uncertainty,
    )
    from robocal_uncertainty.uncertainty.options import EvaluationOptions, evaluate_campaign
    from robocal_uncertainty.uncertainty.reidentification import (
        BatchProblem,
        ChordSolver,
        reidentify_batch,
    )
    from robocal_uncertainty.uncertainty.sources import (
        SOURCE_DESCRIPTIONS,
        SOURCES,
        UncertaintySettings,
        parse_sources,
    )
    from robocal_uncertainty.uncertainty.sweeps import Sweep, evaluate_sweeps, sweep_equations, sweep_lambda

__all__ = [
    "SOURCES",
    "SOURCE_DESCRIPTIONS",
    "BatchProblem",
    "CalibrationTrials",
    "CalibrationUncertainty",
    "ChordSolver",
    "EvaluationOptions",
    "GumPose",
    "PoseUncertainty",
    "Sweep",
    "UncertaintySettings",
    "evaluate_budget",
    "evaluate_campaign",
    "evaluate_sweeps",
    "evaluate_uncertainty",
    "parse_sources",
    "reidentify_batch",
    "sweep_equations",
    "sweep_lambda",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
