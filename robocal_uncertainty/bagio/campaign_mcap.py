"""A campaign as one MCAP file, as a robot records it; incremental writer and reader.

File layout (see :mod:`~robocal_uncertainty.bagio.campaign_format`): MCAP profile ``ros2``,
ROS 2 CDR messages, schemas with encoding ``ros2msg`` and the full definition text, so
``ros2 bag info/play`` and Foxglove read the file. Per pose, with the same header stamp (and
log time): a ``sensor_msgs/msg/JointState`` on ``/joint_states``, a
``geometry_msgs/msg/Vector3Stamped`` with the point standard deviation on
``/tracker/point_std`` (only when given) and a ``geometry_msgs/msg/PointStamped`` on
``/tracker/point``. The ``robocal_campaign`` JSON metadata record is written when the file is
opened.

Crash safety: :class:`CampaignRecorder` closes one uncompressed MCAP chunk per pose (with an
mcap package lacking ``Writer.flush``: unchunked records) and flushes, by default also
fsyncs, it before ``append`` returns, so a crash loses no appended pose, including its
standard deviation; :func:`read_campaign` recovers such a truncated file with a warning.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, final

import numpy as np
from mcap.writer import CompressionType, Writer
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.bagio.campaign_format import (
    JOINT_TOPIC,
    METADATA_NAME,
    ORIENTATION_STD_TOPIC,
    POINT_STD_TOPIC,
    POINT_TOPIC,
    POSE_TOPIC,
    CampaignHeader,
)
from robocal_uncertainty.bagio.campaign_reader import read_campaign
from robocal_uncertainty.bagio.pose_messages import POSE_STAMPED, encode_pose_stamped
from robocal_uncertainty.bagio.ros_messages import (
    JOINT_STATE,
    POINT_STAMPED,
    VECTOR3_STAMPED,
    encode_joint_state,
    encode_point_stamped,
    encode_vector3_stamped,
    message_schema,
    stamp_parts,
)
from robocal_uncertainty.core.campaign import Campaign, PointFrame
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, split_pose_values
from robocal_uncertainty.core.rotation import quaternion_from_matrix, quaternion_to_matrix
from robocal_uncertainty.errors import CampaignError, InputError

__all__ = ["CampaignRecorder", "read_campaign", "write_campaign"]

_LIBRARY = "robocal_uncertainty campaign recorder"
_CHUNKED = hasattr(Writer, "flush")
"""One chunk per pose needs ``Writer.flush`` (recent mcap); older mcap writes unchunked."""
_SYNTHETIC_STEP_NS = 1_000_000_000
"""Stamp spacing used by :func:`write_campaign` for a campaign without stamps (1 s)."""


def _vector(name: str, value: object, size: int) -> NDArray[np.float64]:
    array = np.array(value, dtype=np.float64)
    if array.shape != (size,):
        msg = f"{name} must have shape ({size},), got {array.shape}"
        raise InputError(msg)
    if not np.isfinite(array).all():
        msg = f"{name} contains NaN or inf: {array.tolist()}"
        raise InputError(msg)
    return array


@final
class CampaignRecorder:
    """Write a campaign MCAP file pose by pose; every appended pose is on disk at once.

    Use as a context manager; the file is finished (summary, footer) on exit, also when the
    block raises. The file must not exist yet unless ``overwrite=True``.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create.
    joint_names : sequence of str, length n_joints
        Joint names, in the order of the positions given to :meth:`append`.
    frame : {"base", "tracker"}
        Frame of the points.
    frame_id : str
        ``header.frame_id`` written on the points.
    metadata : dict, optional
        Free-form campaign metadata, stored as JSON (numpy values become lists).
    overwrite : bool
        Replace an existing file.
    fsync : bool
        Also ``os.fsync`` after each pose (survives power loss, not only a process crash).
    stamps_synthetic : bool
        Mark the stamps as made up, so that :func:`read_campaign` returns ``stamps_ns=None``.

    Raises
    ------
    InputError
        Bad joint names, frame, frame id or metadata.
    CampaignError
        If the file exists (without `overwrite`) or cannot be created.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        joint_names: tuple[str, ...] | list[str],
        frame: PointFrame,
        frame_id: str,
        metadata: dict[str, object] | None = None,
        overwrite: bool = False,
        fsync: bool = True,
        stamps_synthetic: bool = False,
        measurement: PoseMeasurement | None = None,
    ) -> None:
        names = tuple(str(n) for n in joint_names)
        if not names or len(set(names)) != len(names) or not all(names):
            msg = f"joint_names must be unique, non-empty strings, got {list(names)}"
            raise InputError(msg)
        if frame not in ("base", "tracker"):
            msg = f"frame must be 'base' or 'tracker', got {frame!r}"
            raise InputError(msg)
        if not frame_id:
            raise InputError("frame_id must be a non-empty string")
        header = CampaignHeader(
            frame=frame,
            frame_id=frame_id,
            joint_names=names,
            stamps_synthetic=stamps_synthetic,
            metadata=dict(metadata or {}),
            measurement=None
            if measurement is None
            else {
                "type": "pose",
                "position_std": list(measurement.position_std),
                "rotation_std": list(measurement.rotation_std),
            },
        )
        record = header.to_record()
        self._poses = measurement is not None
        self.path = Path(path)
        self._names = names
        self._frame_id = frame_id
        self._fsync = fsync
        self._stamps: set[int] = set()
        self._with_std: bool | None = None
        self._std_channel = 0
        try:
            self._stream: BinaryIO = self.path.open("wb" if overwrite else "xb")
        except FileExistsError as err:
            msg = f"campaign file {self.path} exists already (pass overwrite=True to replace it)"
            raise CampaignError(msg) from err
        except OSError as err:
            msg = f"cannot create campaign file {self.path}: {err.strerror or err}"
            raise CampaignError(msg) from err
        self._chunked = _CHUNKED
        self._writer: Writer | None = Writer(self._stream, compression=CompressionType.NONE, use_chunking=self._chunked)
        try:
            self._writer.start(profile="ros2", library=_LIBRARY)
            self._writer.add_metadata(METADATA_NAME, record)
            self._joint_channel = self._channel(JOINT_TOPIC, JOINT_STATE)
            self._point_channel = self._channel(POINT_TOPIC, POINT_STAMPED)
            if self._poses:
                self._pose_channel = self._channel(POSE_TOPIC, POSE_STAMPED)
                self._orientation_std_channel = self._channel(ORIENTATION_STD_TOPIC, VECTOR3_STAMPED)
            self._sync()
        except OSError as err:
            self._stream.close()
            msg = f"cannot write campaign file {self.path}: {err.strerror or err}"
            raise CampaignError(msg) from err

    def _channel(self, topic: str, typename: str) -> int:
        assert self._writer is not None
        schema = message_schema(typename)
        schema_id = self._writer.register_schema(schema.name, schema.encoding, schema.text.encode("utf-8"))
        metadata = {"offered_qos_profiles": "", "topic_type_hash": schema.rihs01}
        return self._writer.register_channel(topic, "cdr", schema_id, metadata)

    def _sync(self) -> None:
        assert self._writer is not None
        if self._chunked:
            self._writer.flush()
        self._stream.flush()
        if self._fsync:
            os.fsync(self._stream.fileno())

    @property
    def n_poses(self) -> int:
        """Number of poses appended so far."""
        return len(self._stamps)

    def append(
        self,
        stamp_ns: int,
        joint_positions: ArrayLike,
        point: ArrayLike,
        point_std: ArrayLike | None = None,
        orientation: ArrayLike | None = None,
        orientation_std: ArrayLike | None = None,
    ) -> None:
        """Write one pose and flush it to disk.

        Parameters
        ----------
        stamp_ns : int
            Acquisition time [ns since the epoch], unique within the campaign, >= 0.
        joint_positions : array_like, shape (n_joints,) [rad]
            Joint readings in the order of ``joint_names``.
        point : array_like, shape (3,) [m]
            Measured point in ``frame_id``.
        point_std : array_like, shape (3,) [m], optional
            Standard deviation of each coordinate; give it for every pose or for none.
        orientation : array_like, shape (4,), optional
            6-DOF recorders only (required there): measured orientation, unit quaternion
            ``(x, y, z, w)`` in ``frame_id``.
        orientation_std : array_like, shape (3,) [rad], optional
            6-DOF recorders only (required there): standard deviation about x, y, z.

        Raises
        ------
        InputError
            Wrong shapes, NaN/inf, negative std, a repeated or out-of-range stamp, or
            point_std given for some poses only.
        CampaignError
            If the recorder is closed.
        """
        if self._writer is None:
            msg = f"campaign recorder for {self.path} is closed"
            raise CampaignError(msg)
        stamp = self._checked_stamp(stamp_ns)
        q = _vector("joint_positions", joint_positions, len(self._names))
        xyz = _vector("point", point, 3)
        std = self._checked_point_std(point_std)
        rotation = self._checked_orientation(orientation, orientation_std)
        sequence = self.n_poses
        if rotation is not None:
            quaternion, rot_std = rotation
            self._writer.add_message(
                self._orientation_std_channel,
                stamp,
                encode_vector3_stamped(stamp, self._frame_id, rot_std),
                stamp,
                sequence,
            )
            self._writer.add_message(
                self._pose_channel, stamp, encode_pose_stamped(stamp, self._frame_id, xyz, quaternion), stamp, sequence
            )
        self._writer.add_message(self._joint_channel, stamp, encode_joint_state(stamp, self._names, q), stamp, sequence)
        if std is not None:
            self._writer.add_message(
                self._std_channel,
                stamp,
                encode_vector3_stamped(stamp, self._frame_id, std),
                stamp,
                sequence,
            )
        self._writer.add_message(
            self._point_channel,
            stamp,
            encode_point_stamped(stamp, self._frame_id, xyz),
            stamp,
            sequence,
        )
        self._sync()
        self._stamps.add(stamp)

    def _checked_stamp(self, stamp_ns: int) -> int:
        """The stamp as an int [ns]; refuses a non-integer, out-of-range or repeated one."""
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int | np.integer):
            msg = f"stamp_ns must be an integer number of ns, got {stamp_ns!r}"
            raise InputError(msg)
        stamp = int(stamp_ns)
        stamp_parts(stamp)
        if stamp in self._stamps:
            msg = f"stamp {stamp} ns was already appended to {self.path}"
            raise InputError(msg)
        return stamp

    def _checked_point_std(self, point_std: ArrayLike | None) -> NDArray[np.float64] | None:
        """The point std [m], given for every pose or for none (the first pose decides)."""
        std = None if point_std is None else _vector("point_std", point_std, 3)
        if std is not None and (std < 0).any():
            msg = f"point_std must be non-negative, got {std.tolist()}"
            raise InputError(msg)
        if self._with_std is not None and self._with_std != (std is not None):
            msg = f"point_std must be given for every pose or for none (pose {self.n_poses})"
            raise InputError(msg)
        if self._with_std is None:
            self._with_std = std is not None
            if std is not None:
                self._std_channel = self._channel(POINT_STD_TOPIC, VECTOR3_STAMPED)
        return std

    def _checked_orientation(
        self, orientation: ArrayLike | None, orientation_std: ArrayLike | None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """Quaternion and rotation std [rad] of a 6-DOF pose; None for a point recorder."""
        if self._poses:
            if orientation is None or orientation_std is None:
                msg = f"a 6-DOF campaign needs an orientation and its std for every pose (pose {self.n_poses})"
                raise InputError(msg)
            quaternion = _vector("orientation", orientation, 4)
            quaternion_to_matrix(quaternion, name="orientation")  # unit and finite, one-line error
            rot_std = _vector("orientation_std", orientation_std, 3)
            if (rot_std < 0).any():
                msg = f"orientation_std must be non-negative, got {rot_std.tolist()}"
                raise InputError(msg)
            return quaternion, rot_std
        if orientation is not None or orientation_std is not None:
            msg = "orientation given to a point campaign recorder (create it with a PoseMeasurement)"
            raise InputError(msg)
        return None

    def close(self) -> None:
        """Finish the file (summary and footer) and close it; closing twice is a no-op."""
        if self._writer is None:
            return
        writer, self._writer = self._writer, None
        try:
            writer.finish()
            self._stream.flush()
            if self._fsync:
                os.fsync(self._stream.fileno())
        finally:
            self._stream.close()

    def __enter__(self) -> CampaignRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def write_campaign(path: str | Path, campaign: Campaign, *, overwrite: bool = False) -> None:
    """Write `campaign` to the single MCAP file `path`.

    A campaign without stamps gets synthetic ones (pose i at i s), marked as such so that
    :func:`read_campaign` gives ``stamps_ns=None`` back. Stamps must be unique and >= 0.

    Raises
    ------
    CampaignError
        If `path` exists (without `overwrite`) or cannot be written.
    InputError
        If stamps repeat or are negative, or the metadata is not JSON-serialisable.
    """
    synthetic = campaign.stamps_ns is None
    stamps = (
        np.arange(campaign.n_poses, dtype=np.int64) * _SYNTHETIC_STEP_NS
        if campaign.stamps_ns is None
        else campaign.stamps_ns
    )
    for stamp in (int(stamps.min()), int(stamps.max())):
        stamp_parts(stamp)
    values, counts = np.unique(stamps, return_counts=True)
    if (counts > 1).any():
        repeated = int(values[counts > 1][0])
        msg = f"campaign stamps_ns must be unique to be written, {repeated} ns repeats"
        raise InputError(msg)
    measurement = campaign.measurement
    positions, point_std = campaign.points, campaign.point_std
    quaternions = rotation_std = None
    if isinstance(measurement, PoseMeasurement):
        positions, rotations = split_pose_values(campaign.points)
        quaternions = quaternion_from_matrix(rotations)
        if campaign.point_std is None:
            rotation_std = np.broadcast_to(np.asarray(measurement.rotation_std), (campaign.n_poses, 3))
        else:
            point_std, rotation_std = campaign.point_std[:, :3], campaign.point_std[:, 3:]
    elif measurement.value_size != 3:
        msg = f"campaign files store points and poses, not {measurement.quantity}s"
        raise InputError(msg)
    with CampaignRecorder(
        path,
        joint_names=campaign.joint_names,
        frame=campaign.frame,
        frame_id=campaign.frame_id,
        metadata=campaign.metadata,
        overwrite=overwrite,
        fsync=False,
        stamps_synthetic=synthetic,
        measurement=measurement if isinstance(measurement, PoseMeasurement) else None,
    ) as recorder:
        for i in range(campaign.n_poses):
            recorder.append(
                int(stamps[i]),
                campaign.joint_positions[i],
                positions[i],
                None if point_std is None else point_std[i],
                None if quaternions is None else quaternions[i],
                None if rotation_std is None else rotation_std[i],
            )
