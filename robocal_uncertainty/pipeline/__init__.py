"""ROS-free online pipeline: static-pose collection, calibration, uncertainty, bag replay.

Thin ROS 2 nodes wrap these objects; ``robocal-uncertainty replay`` drives them offline.
Nothing here imports ROS.
"""

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
from robocal_uncertainty.pipeline.sample import CalibrationSample

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
