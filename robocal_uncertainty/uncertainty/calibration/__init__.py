"""Monte Carlo uncertainty of a calibrated arm's tool pose (JCGM 101), one job per module.

``results``: the frozen result types; ``trials``: the picklable trial block (perturb,
re-identify, evaluate at the test configurations); ``preparation``: what an evaluation
derives before the trials; ``gum``: the first-order propagation and its §8 check;
``orientation``: the orientation statement and the rotations the data cannot fix;
``statement``: the statement of the trials; ``settings``: what determines the result;
``evaluation``: the one service call, :func:`evaluate_uncertainty`.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
    from robocal_uncertainty.uncertainty.calibration.gum import first_order_standard_uncertainty
    from robocal_uncertainty.uncertainty.calibration.preparation import prepare_calibration_trials
    from robocal_uncertainty.uncertainty.calibration.results import (
        OUTPUT_FRAMES,
        ROTATION_AXES,
        UNDETERMINED_VARIANCE,
        CalibrationUncertainty,
        GumPose,
        OrientationUncertainty,
        PoseUncertainty,
    )
    from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
    from robocal_uncertainty.uncertainty.calibration.trials import CalibrationTrials

__all__ = [
    "OUTPUT_FRAMES",
    "ROTATION_AXES",
    "UNDETERMINED_VARIANCE",
    "CalibrationTrials",
    "CalibrationUncertainty",
    "EvaluationSettings",
    "GumPose",
    "OrientationUncertainty",
    "PoseUncertainty",
    "evaluate_uncertainty",
    "first_order_standard_uncertainty",
    "prepare_calibration_trials",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
