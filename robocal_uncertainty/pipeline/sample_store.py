"""Calibration samples keyed by stamp, merged from a campaign file and from a live topic.

Where the downstream nodes get their samples (the documented choice): the collector records
every sample to the campaign MCAP *before* publishing it on ``robocal/samples``. The
calibration and uncertainty nodes subscribe to ``robocal/samples`` and, at start, also read
the campaign file (read-only; a file still being written reads up to its last complete
pose). Samples are keyed by their stamp, so a sample seen both ways counts once, and a node
started late or restarted still has every sample taken so far. Both nodes order samples by
stamp, so "the first n samples" names the same campaign in both.

ROS-free: the nodes hold one, and the tests drive it without ROS.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from robocal_uncertainty.bagio.campaign_mcap import read_campaign
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, split_pose_values
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.rotation import quaternion_from_matrix
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = ["SampleStore"]


class SampleStore:
    """Calibration samples keyed by stamp: from the campaign file and from the topic.

    Parameters
    ----------
    model : RobotModel
        Samples must carry exactly its joints.
    """

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._samples: dict[int, CalibrationSample] = {}
        self._frame_id: str | None = None
        self.duplicates = 0
        self.refused = 0

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def latest_stamp_ns(self) -> int | None:
        """Stamp of the latest sample held [ns], None when empty."""
        return max(self._samples) if self._samples else None

    def add(self, sample: CalibrationSample) -> bool:
        """Add a sample; False for one already held (same stamp).

        Raises
        ------
        InputError
            Other joints than the model's, or another frame than the samples held.
        """
        if sample.stamp_ns in self._samples:
            self.duplicates += 1
            return False
        if set(sample.joint_names) != set(self.model.joint_names):
            self.refused += 1
            msg = f"sample joints {list(sample.joint_names)} differ from the model's {list(self.model.joint_names)}"
            raise InputError(msg)
        if self._frame_id is not None and sample.frame_id != self._frame_id:
            self.refused += 1
            msg = f"sample in frame {sample.frame_id!r}, the campaign is in {self._frame_id!r}"
            raise InputError(msg)
        self._frame_id = sample.frame_id
        self._samples[sample.stamp_ns] = sample
        return True

    def load_campaign_file(self, path: Path) -> tuple[int, tuple[str, ...]]:
        """Add the poses of a campaign MCAP (read-only); returns (added, reader warnings).

        A pose carries no per-reading statistics: it becomes a sample with the point
        covariance diag(point_std^2) (so ``point_std`` is the recorded one exactly),
        zero joint scatter and counts of 1. A 6-DOF campaign's poses keep their orientation,
        with the covariance diag(rotation_std^2).
        """
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            campaign = read_campaign(path)
        if campaign.stamps_ns is None:
            msg = f"campaign {path} has no pose stamps; cannot merge it with live samples"
            raise InputError(msg)
        positions, orientations, rotation_std = campaign.points, None, None
        if isinstance(campaign.measurement, PoseMeasurement):
            positions, rotations = split_pose_values(campaign.points)
            orientations = quaternion_from_matrix(rotations)
            rotation_std = (
                np.broadcast_to(np.asarray(campaign.measurement.rotation_std), (campaign.n_poses, 3))
                if campaign.point_std is None
                else campaign.point_std[:, 3:]
            )
        added = 0
        for i in range(campaign.n_poses):
            std = np.zeros(3) if campaign.point_std is None else campaign.point_std[i, :3]
            sample = CalibrationSample(
                stamp_ns=int(campaign.stamps_ns[i]),
                frame_id=campaign.frame_id,
                joint_names=campaign.joint_names,
                joint_positions=campaign.joint_positions[i],
                joint_position_std=np.zeros(len(campaign.joint_names)),
                point=positions[i],
                point_covariance=np.diag(np.square(std)),
                joint_state_count=1,
                tracker_point_count=1,
                orientation=None if orientations is None else orientations[i],
                orientation_covariance=None if rotation_std is None else np.diag(np.square(rotation_std[i])),
            )
            added += self.add(sample)
        return added, tuple(str(w.message) for w in caught)

    def first(self, n: int | None = None) -> list[CalibrationSample]:
        """The `n` earliest samples (all when None), in stamp order."""
        stamps = sorted(self._samples)
        if n is not None:
            stamps = stamps[:n]
        return [self._samples[s] for s in stamps]

    def pipeline(
        self, n: int | None = None, *, options: EvaluationSettings | None = None, min_samples: int | None = None
    ) -> CalibrationPipeline:
        """A fresh in-memory :class:`CalibrationPipeline` of the `n` earliest samples."""
        return self.pipeline_of(self.model, self.first(n), options=options, min_samples=min_samples)

    @staticmethod
    def pipeline_of(
        model: RobotModel,
        samples: Iterable[CalibrationSample],
        *,
        options: EvaluationSettings | None = None,
        min_samples: int | None = None,
    ) -> CalibrationPipeline:
        """A fresh in-memory :class:`CalibrationPipeline` of `samples` (see its parameters)."""
        pipeline = CalibrationPipeline(model, options=options, min_samples=min_samples)
        for sample in samples:
            pipeline.add_sample(sample)
        return pipeline
