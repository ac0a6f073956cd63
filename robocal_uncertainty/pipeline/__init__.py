"""ROS-free online pipeline: static-pose collection, sample store, stream merge, calibration
pipeline (sample accumulation, recording, resume) and bag replay into samples and a campaign.

Thin ROS 2 nodes wrap these objects; ``robocal-uncertainty replay`` drives them offline.
The uncertainty evaluation is :func:`robocal_uncertainty.app.evaluate`, above this layer.
Nothing here imports ROS.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.core.sample import CalibrationSample
    from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
    from robocal_uncertainty.pipeline.collector import (
        DROP_CAUSES,
        CollectorSettings,
        LogCallback,
        StaticPoseCollector,
        samples_to_campaign,
    )
    from robocal_uncertainty.pipeline.diagnostics import DiagnosticLevel, DiagnosticStatus, DiagnosticThresholds
    from robocal_uncertainty.pipeline.markers import MarkerSpec, uncertainty_markers
    from robocal_uncertainty.pipeline.replay import ReplayResult, replay_bag
    from robocal_uncertainty.pipeline.sample_store import SampleStore
    from robocal_uncertainty.pipeline.stream_merge import StreamMerger

__all__ = [
    "DROP_CAUSES",
    "CalibrationPipeline",
    "CalibrationSample",
    "CollectorSettings",
    "DiagnosticLevel",
    "DiagnosticStatus",
    "DiagnosticThresholds",
    "LogCallback",
    "MarkerSpec",
    "ReplayResult",
    "SampleStore",
    "StaticPoseCollector",
    "StreamMerger",
    "replay_bag",
    "samples_to_campaign",
    "uncertainty_markers",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
