"""ROS-free online pipeline: static-pose collection, calibration, uncertainty, bag replay.

Thin ROS 2 nodes wrap these objects; ``robocal-uncertainty replay`` drives them offline.
Nothing here imports ROS.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.core.sample import CalibrationSample
    from robocal_uncertainty.pipeline.calibration_pipeline import (
        CalibrationPipeline,
        EvaluationOptions,
        evaluate_campaign,
    )
    from robocal_uncertainty.pipeline.collector import (
        DROP_CAUSES,
        CollectorSettings,
        LogCallback,
        StaticPoseCollector,
        samples_to_campaign,
    )
    from robocal_uncertainty.pipeline.replay import ReplayResult, replay_bag

__all__ = [
    "DROP_CAUSES",
    "CalibrationPipeline",
    "CalibrationSample",
    "CollectorSettings",
    "EvaluationOptions",
    "LogCallback",
    "ReplayResult",
    "StaticPoseCollector",
    "evaluate_campaign",
    "replay_bag",
    "samples_to_campaign",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
