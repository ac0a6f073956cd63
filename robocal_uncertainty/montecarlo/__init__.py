"""General Monte Carlo propagation of distributions (JCGM 101, GUM Supplement 1).

``run_trials`` is the reproducible block engine for any batched trial function;
``monte_carlo`` propagates input distributions through a vectorised model;
``propagate_gum`` and ``validate_gum`` give the GUM comparison of JCGM 101 §8;
``coverage_region`` gives the JCGM 102 hyper-ellipsoidal region for vector outputs.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.montecarlo.distributions import (
        Arcsine,
        CorrelatedNormal,
        CurvilinearTrapezoid,
        Distribution,
        Empirical,
        IndependentCopies,
        IndependentRectangular,
        Normal,
        Rectangular,
        StudentT,
        Triangular,
    )
    from robocal_uncertainty.montecarlo.engine import (
        AdaptiveReport,
        AdaptiveSettings,
        DistributionTrials,
        ModelOutputError,
        MonteCarloResult,
        NonFinitePolicy,
        ProgressCallback,
        ReducedTrials,
        StagedTrialBlock,
        TrialBlock,
        TrialsResult,
        block_rng,
        monte_carlo,
        reduce_trials,
        run_trials,
    )
    from robocal_uncertainty.montecarlo.executor import WorkerPool, open_executor
    from robocal_uncertainty.montecarlo.gum import GumOutput, GumResult, propagate_gum
    from robocal_uncertainty.montecarlo.region import EllipsoidalRegion, coverage_region
    from robocal_uncertainty.montecarlo.streaming import Moments, Reduction
    from robocal_uncertainty.montecarlo.summary import (
        CoverageInterval,
        Histogram,
        IntervalKind,
        MonteCarloIntervalKind,
        OutputSummary,
        Summary,
        numerical_tolerance,
        summarize,
    )
    from robocal_uncertainty.montecarlo.validation import GumValidation, MonteCarloOutputs, validate_gum

__all__ = [
    "AdaptiveReport",
    "AdaptiveSettings",
    "Arcsine",
    "CorrelatedNormal",
    "CoverageInterval",
    "CurvilinearTrapezoid",
    "Distribution",
    "DistributionTrials",
    "EllipsoidalRegion",
    "Empirical",
    "GumOutput",
    "GumResult",
    "GumValidation",
    "Histogram",
    "IndependentCopies",
    "IndependentRectangular",
    "IntervalKind",
    "ModelOutputError",
    "Moments",
    "MonteCarloIntervalKind",
    "MonteCarloOutputs",
    "MonteCarloResult",
    "NonFinitePolicy",
    "Normal",
    "OutputSummary",
    "ProgressCallback",
    "Rectangular",
    "ReducedTrials",
    "Reduction",
    "StagedTrialBlock",
    "StudentT",
    "Summary",
    "TrialBlock",
    "TrialsResult",
    "Triangular",
    "WorkerPool",
    "block_rng",
    "coverage_region",
    "monte_carlo",
    "numerical_tolerance",
    "open_executor",
    "propagate_gum",
    "reduce_trials",
    "run_trials",
    "summarize",
    "validate_gum",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
