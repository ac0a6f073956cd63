"""Monte Carlo uncertainty of a calibration: sources, batched re-identification, GUM check."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.budget import evaluate_budget
    from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
    from robocal_uncertainty.uncertainty.calibration.preparation import prepare_calibration_trials
    from robocal_uncertainty.uncertainty.calibration.results import (
        CalibrationUncertainty,
        GumPose,
        OrientationUncertainty,
        PoseUncertainty,
    )
    from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings, build_evaluation_settings
    from robocal_uncertainty.uncertainty.calibration.trials import CalibrationTrials
    from robocal_uncertainty.uncertainty.reidentification import (
        BatchProblem,
        ChordSolver,
        reidentify_batch,
    )
    from robocal_uncertainty.uncertainty.sources import (
        SOURCE_DESCRIPTIONS,
        SOURCE_REGISTRY,
        SOURCES,
        AdditiveSource,
        Source,
        SourceSpec,
        TrialBatch,
        TrialContext,
        UncertaintySettings,
        default_sources,
        parse_sources,
        register_source,
        sources_help,
    )
    from robocal_uncertainty.uncertainty.sweeps import Sweep, evaluate_sweeps, sweep_equations, sweep_lambda
    from robocal_uncertainty.uncertainty.workspace_map import (
        WorkspaceMap,
        grid_configurations,
        map_workspace,
        sample_configurations,
    )

__all__ = [
    "SOURCES",
    "SOURCE_DESCRIPTIONS",
    "SOURCE_REGISTRY",
    "AdditiveSource",
    "BatchProblem",
    "CalibrationTrials",
    "CalibrationUncertainty",
    "ChordSolver",
    "EvaluationSettings",
    "GumPose",
    "OrientationUncertainty",
    "PoseUncertainty",
    "Source",
    "SourceSpec",
    "Sweep",
    "TrialBatch",
    "TrialContext",
    "UncertaintySettings",
    "WorkspaceMap",
    "build_evaluation_settings",
    "default_sources",
    "evaluate_budget",
    "evaluate_sweeps",
    "evaluate_uncertainty",
    "grid_configurations",
    "map_workspace",
    "parse_sources",
    "prepare_calibration_trials",
    "register_source",
    "reidentify_batch",
    "sample_configurations",
    "sources_help",
    "sweep_equations",
    "sweep_lambda",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
