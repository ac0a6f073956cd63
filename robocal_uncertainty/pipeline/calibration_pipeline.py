"""Samples in, campaign and calibration out: the state a calibration node holds.

:class:`CalibrationPipeline` accumulates calibration samples into a campaign (optionally
recorded to a campaign MCAP file pose by pose, so a crash loses nothing, and resumed from
that file on restart) and identifies the parameters. The uncertainty of that calibration
is the application service's job: ``robocal_uncertainty.app.evaluate(model,
pipeline.campaign, settings, calibration=pipeline.calibrate())``, the call the command line,
the replay and the nodes make, so the same campaign and settings give the same numbers bit
for bit.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.bagio.campaign_mcap import CampaignRecorder, read_campaign
from robocal_uncertainty.bagio.campaign_reader import READ_WARNINGS_KEY
from robocal_uncertainty.core.campaign import Campaign, PointFrame
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values, split_pose_values
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.rotation import quaternion_from_matrix, quaternion_to_matrix
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import CampaignError, ConfigError, IdentifiabilityError, InputError
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = ["CalibrationPipeline"]

Array = NDArray[np.float64]


class CalibrationPipeline:
    """Accumulate calibration samples; calibrate on demand.

    Parameters
    ----------
    model : RobotModel
        Nominal model; samples must carry exactly its joints (any order).
    options : EvaluationSettings, optional
        Its ``lambda_`` and ``accept_unconverged`` set the identification of
        :meth:`calibrate` (defaults: ``EvaluationSettings()``); the rest is carried for the
        evaluation (``robocal_uncertainty.app.evaluate``).
    min_samples : int, optional
        Fewest samples :meth:`calibrate` accepts; None leaves the check to the
        identification (enough equations for the identifiable parameters).
    campaign_path : str or Path, optional
        Campaign MCAP file recording every sample as it is added (flushed and fsynced per
        pose). If it exists, the pipeline resumes from it: its poses are read (a file
        truncated by a crash is recovered up to its last complete pose), rewritten to a
        fresh file that replaces it, and new samples are appended there.
    fsync : bool
        fsync the campaign file after each sample (survives power loss).
    metadata : dict, optional
        Metadata of a new campaign file.

    Raises
    ------
    ConfigError
        Invalid options.
    CampaignError, BagError
        The campaign file cannot be read, written or does not fit the model.

    Notes
    -----
    Frame of the campaign: ``"base"`` when the samples' frame id is the model's
    ``base_frame_id``, ``"tracker"`` otherwise (the base transform is then identified).
    Resuming replaces the file with :func:`os.replace` while the new recorder writes to
    it (POSIX semantics).

    6-DOF samples (with an orientation, from a tracker pose stream) make a 6-DOF campaign:
    positions and orientations, ``point_std`` (n, 6) with the rotation standard
    uncertainties sqrt(diag(orientation_covariance)) [rad], recorded as a pose campaign. Its
    weighting (:class:`PoseMeasurement`) is the first sample's standard uncertainties
    (floored at 1e-12), fixed when the file is created and read back on resume. Point and
    6-DOF samples cannot be mixed.
    """

    def __init__(
        self,
        model: RobotModel,
        *,
        options: EvaluationSettings | None = None,
        min_samples: int | None = None,
        campaign_path: str | Path | None = None,
        fsync: bool = True,
        metadata: dict[str, object] | None = None,
    ) -> None:
        if min_samples is not None and (
            isinstance(min_samples, bool) or not isinstance(min_samples, int) or min_samples < 1
        ):
            msg = f"min_samples must be a positive integer, got {min_samples!r}"
            raise ConfigError(msg)
        self.model = model
        self.min_samples = min_samples
        self.options = EvaluationSettings() if options is None else options
        self.campaign_path = None if campaign_path is None else Path(campaign_path)
        self.resume_warnings: tuple[str, ...] = ()
        """Warnings raised while reading the resumed campaign file (e.g. truncation)."""
        self._fsync = fsync
        self._metadata: dict[str, object] = dict(
            metadata or {"source": "robocal_uncertainty calibration pipeline", "robot": model.name}
        )
        self._frame_id: str | None = None
        self._stamps: list[int] = []
        self._joints: list[Array] = []
        self._points: list[Array] = []
        self._point_std: list[Array] = []
        self._with_std = True
        self._orientations: list[Array] = []
        self._rotation_std: list[Array] = []
        self._measurement: PoseMeasurement | None = None
        self._recorder: CampaignRecorder | None = None
        self._closed = False
        self._calibration: IdentificationResult | None = None
        if self.campaign_path is not None and self.campaign_path.exists():
            self._resume(self.campaign_path)

    # -- state -----------------------------------------------------------------------------

    @property
    def n_samples(self) -> int:
        """Number of samples in the campaign (resumed ones included)."""
        return len(self._stamps)

    @property
    def ready(self) -> bool:
        """True when :meth:`calibrate` has enough samples to try."""
        return self.n_samples >= max(1, self.min_samples or 1)

    @property
    def frame(self) -> PointFrame:
        """Frame of the campaign's points (see the class notes)."""
        return "base" if self._frame_id == self.model.base_frame_id else "tracker"

    @property
    def campaign(self) -> Campaign | None:
        """The campaign so far (model joint order), None before the first sample."""
        if not self._stamps or self._frame_id is None:
            return None
        points = np.array(self._points)
        point_std = np.array(self._point_std) if self._with_std else None
        if self._measurement is not None:
            points = pose_values(points, quaternion_to_matrix(np.array(self._orientations)))
            if point_std is not None:
                point_std = np.concatenate((point_std, np.array(self._rotation_std)), axis=1)
        return Campaign(
            joint_names=self.model.joint_names,
            joint_positions=np.array(self._joints),
            points=points,
            frame=self.frame,
            frame_id=self._frame_id,
            point_std=point_std,
            stamps_ns=np.array(self._stamps, dtype=np.int64),
            metadata=dict(self._metadata),
            **({} if self._measurement is None else {"measurement": self._measurement}),
        )

    # -- input -----------------------------------------------------------------------------

    def add_sample(self, sample: CalibrationSample) -> None:
        """Append one sample (and record it to the campaign file first, when there is one).

        Raises
        ------
        InputError
            Joints other than the model's, another frame id than earlier samples, or a
            stamp already in the campaign.
        CampaignError
            The campaign file cannot be written, or the pipeline was closed.
        """
        if self._closed:
            msg = f"calibration pipeline recording to {self.campaign_path} is closed"
            raise CampaignError(msg)
        names = self.model.joint_names
        if set(sample.joint_names) != set(names):
            msg = f"sample joints {list(sample.joint_names)} differ from the model's {list(names)}"
            raise InputError(msg)
        if self._frame_id is not None and sample.frame_id != self._frame_id:
            msg = f"sample in frame {sample.frame_id!r}, the campaign is in {self._frame_id!r}"
            raise InputError(msg)
        if sample.stamp_ns in self._stamps:
            msg = f"a sample with stamp {sample.stamp_ns} ns is already in the campaign"
            raise InputError(msg)
        pose = sample.orientation is not None
        if self._stamps and pose != (self._measurement is not None):
            kind = "6-DOF" if self._measurement is not None else "point"
            msg = f"sample {'with' if pose else 'without'} an orientation, the campaign is a {kind} campaign"
            raise InputError(msg)
        order = [sample.joint_names.index(n) for n in names]
        q = np.array(sample.joint_positions[order])
        std = np.array(sample.point_std)
        rotation_std = None
        if pose:
            rotation_std = np.sqrt(np.diag(np.asarray(sample.orientation_covariance, dtype=np.float64)))
            if self._measurement is None:
                floor = np.maximum(np.concatenate((std, rotation_std)), 1e-12)
                self._measurement = PoseMeasurement(
                    (float(floor[0]), float(floor[1]), float(floor[2])),
                    (float(floor[3]), float(floor[4]), float(floor[5])),
                )
        if self.campaign_path is not None:
            if self._recorder is None:
                self._recorder = self._open_recorder(self.campaign_path, sample.frame_id)
            self._recorder.append(
                sample.stamp_ns,
                q,
                sample.point,
                std if self._with_std else None,
                **({} if not pose else {"orientation": sample.orientation, "orientation_std": rotation_std}),
            )
        if pose:
            assert sample.orientation is not None and rotation_std is not None
            self._orientations.append(np.array(sample.orientation, dtype=np.float64))
            self._rotation_std.append(rotation_std)
        self._frame_id = sample.frame_id
        self._stamps.append(sample.stamp_ns)
        self._joints.append(q)
        self._points.append(np.array(sample.point))
        self._point_std.append(std)
        self._calibration = None

    # -- results ---------------------------------------------------------------------------

    def calibrate(self) -> IdentificationResult:
        """Identify the parameters from the samples so far (cached until the next sample).

        Raises
        ------
        IdentifiabilityError
            Fewer samples than `min_samples`, or too few/degenerate poses to identify.
        """
        campaign = self.campaign
        if campaign is None or not self.ready:
            need = max(1, self.min_samples or 1)
            msg = f"only {self.n_samples} calibration samples, need at least {need}"
            raise IdentifiabilityError(msg)
        if self._calibration is None:
            self._calibration = identify(
                self.model,
                campaign,
                lambda_=self.options.lambda_,
                accept_unconverged=self.options.accept_unconverged,
            )
        return self._calibration

    # -- campaign file ---------------------------------------------------------------------

    def _open_recorder(self, path: Path, frame_id: str, *, overwrite: bool = False) -> CampaignRecorder:
        frame: PointFrame = "base" if frame_id == self.model.base_frame_id else "tracker"
        return CampaignRecorder(
            path,
            joint_names=self.model.joint_names,
            frame=frame,
            frame_id=frame_id,
            metadata=self._metadata,
            overwrite=overwrite,
            fsync=self._fsync,
            measurement=self._measurement,
        )

    def _resume(self, path: Path) -> None:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            campaign = read_campaign(path)
        self.resume_warnings = tuple(str(w.message) for w in caught)
        campaign = campaign.reorder_joints(self.model.joint_names)
        if campaign.stamps_ns is None:
            msg = f"cannot resume campaign {path}: it has no pose stamps"
            raise InputError(msg)
        # The reader's warnings (truncation) are kept in resume_warnings, not re-recorded:
        # the rewritten file is complete.
        self._metadata = {k: v for k, v in campaign.metadata.items() if k != READ_WARNINGS_KEY}
        self._frame_id = campaign.frame_id
        self._with_std = campaign.point_std is not None
        positions, orientations, rotation_std = campaign.points, None, None
        if isinstance(campaign.measurement, PoseMeasurement):
            self._measurement = campaign.measurement
            positions, rotations = split_pose_values(campaign.points)
            orientations = quaternion_from_matrix(rotations)
            if campaign.point_std is None:
                rotation_std = np.broadcast_to(np.asarray(campaign.measurement.rotation_std), (campaign.n_poses, 3))
            else:
                rotation_std = campaign.point_std[:, 3:]
        temporary = path.with_name(path.name + ".resume")
        recorder = self._open_recorder(temporary, campaign.frame_id, overwrite=True)
        try:
            for i in range(campaign.n_poses):
                std = None if campaign.point_std is None else campaign.point_std[i, :3]
                extra = {}
                if orientations is not None and rotation_std is not None:
                    extra = {"orientation": orientations[i], "orientation_std": rotation_std[i]}
                    self._orientations.append(np.array(orientations[i]))
                    self._rotation_std.append(np.array(rotation_std[i]))
                recorder.append(int(campaign.stamps_ns[i]), campaign.joint_positions[i], positions[i], std, **extra)
                self._stamps.append(int(campaign.stamps_ns[i]))
                self._joints.append(np.array(campaign.joint_positions[i]))
                self._points.append(np.array(positions[i]))
                if std is not None:
                    self._point_std.append(np.array(std))
            os.replace(temporary, path)
        except BaseException:
            recorder.close()
            temporary.unlink(missing_ok=True)
            raise
        self._recorder = recorder

    def close(self) -> None:
        """Finish the campaign file (if any); calibrate and evaluate still work, adding does not."""
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        self._closed = self.campaign_path is not None

    def __enter__(self) -> CalibrationPipeline:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
