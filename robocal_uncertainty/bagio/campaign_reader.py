"""Read a campaign from an MCAP file or a rosbag2 directory.

Accepted inputs:

* a single ``.mcap`` file written by
  :class:`~robocal_uncertainty.bagio.campaign_mcap.CampaignRecorder` (with the
  ``robocal_campaign`` metadata record), also when truncated by a crash;
* any other single MCAP file with ROS 2 CDR messages (e.g. ``ros2 bag record -s mcap``);
* a rosbag2 directory (``metadata.yaml`` with ``.mcap`` or ``.db3`` storage).

Poses are built from the point messages (``geometry_msgs/msg/PointStamped``), in the order
they are read (file order for a single MCAP file, log-time order for a rosbag2 directory).
Each point is paired with the ``sensor_msgs/msg/JointState`` message of identical header
stamp, or, with ``stamp_tolerance_ns > 0`` and no exact match, the nearest one within the
tolerance (see :mod:`~robocal_uncertainty.bagio.pairing`). Unpaired points are dropped with
a warning; unpaired joint states are ignored. Joint positions are mapped by
``JointState.name``, so the joint order may differ between messages.

Without the metadata record the frame comes from the points' ``header.frame_id``: ``"base"``
when it equals `base_frame_id`, ``"tracker"`` otherwise.

6-DOF campaigns (the record's ``measurement`` entry is a pose): each point is joined, by its
stamp, with the ``geometry_msgs/msg/PoseStamped`` on the pose topic and the orientation
standard deviation on ``/tracker/orientation_std``; the campaign then holds
:class:`~robocal_uncertainty.core.pose_measurement.PoseMeasurement` values. A quaternion that
is NaN or not of unit norm (tolerance 1e-6) is an error naming the file and stamp.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.bagio.bag import Bag, open_bag
from robocal_uncertainty.bagio.campaign_format import (
    JOINT_TOPIC,
    METADATA_NAME,
    POINT_STD_TOPIC,
    POINT_TOPIC,
    CampaignHeader,
    parse_header,
)
from robocal_uncertainty.bagio.mcap_stream import RawMessage
from robocal_uncertainty.bagio.pairing import pair_by_stamp
from robocal_uncertainty.bagio.pose_messages import POSE_STAMPED, decode_pose_stamped
from robocal_uncertainty.bagio.ros_messages import (
    DECODE_ERRORS,
    JOINT_STATE,
    POINT_STAMPED,
    VECTOR3_STAMPED,
    JointReading,
    VectorReading,
    decode_joint_state,
    decode_vector_stamped,
)
from robocal_uncertainty.core.campaign import Campaign, PointFrame
from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values
from robocal_uncertainty.core.rotation import quaternion_to_matrix
from robocal_uncertainty.errors import BagError, CampaignError, InputError

__all__ = ["READ_WARNINGS_KEY", "read_campaign"]

READ_WARNINGS_KEY = "warnings"
"""Key of ``Campaign.metadata`` holding the reader's warnings (one-line strings), if any."""


def _decode_joints(raw: list[RawMessage], path: Path) -> list[JointReading]:
    readings = []
    for index, message in enumerate(raw):
        try:
            reading = decode_joint_state(message.data)
        except DECODE_ERRORS as err:
            msg = f"{path}: cannot decode {JOINT_STATE} #{index} on {message.channel.topic}: {err}"
            raise BagError(msg) from err
        if not np.isfinite(reading.positions).all():
            topic = message.channel.topic
            msg = f"{path}: NaN or inf in {topic} message at stamp {reading.stamp_ns} ns"
            raise BagError(msg)
        readings.append(reading)
    return readings


def _decode_vectors(raw: list[RawMessage], typename: str, path: Path) -> list[VectorReading]:
    readings = []
    for index, message in enumerate(raw):
        try:
            reading = decode_vector_stamped(message.data, typename)
        except DECODE_ERRORS as err:
            msg = f"{path}: cannot decode {typename} #{index} on {message.channel.topic}: {err}"
            raise BagError(msg) from err
        if not np.isfinite(reading.xyz).all():
            topic = message.channel.topic
            msg = f"{path}: NaN or inf in {topic} message at stamp {reading.stamp_ns} ns"
            raise BagError(msg)
        readings.append(reading)
    return readings


def _joint_matrix(
    readings: list[JointReading], names: tuple[str, ...] | None, topic: str, path: Path
) -> tuple[tuple[str, ...], NDArray[np.float64]]:
    """Return joint names and positions (n_msgs, n_joints) [rad], mapped by name."""
    reference = names if names is not None else readings[0].names
    column = {name: j for j, name in enumerate(reference)}
    positions = np.empty((len(readings), len(reference)), dtype=np.float64)
    for i, reading in enumerate(readings):
        if len(set(reading.names)) != len(reading.names) or set(reading.names) != set(reference):
            msg = (
                f"{path}: JointState messages on {topic} have differing joint names: "
                f"{list(reference)} vs {list(reading.names)} at stamp {reading.stamp_ns} ns"
            )
            raise BagError(msg)
        positions[i, [column[n] for n in reading.names]] = reading.positions
    return reference, positions


def _unique_stamps(stamps: NDArray[np.int64], topic: str, path: Path) -> None:
    values, counts = np.unique(stamps, return_counts=True)
    if (counts > 1).any():
        msg = f"{path}: several {topic} messages share the stamp {int(values[counts > 1][0])} ns"
        raise BagError(msg)


def _frame(
    points: list[VectorReading], header: CampaignHeader | None, base_frame_id: str, path: Path
) -> tuple[PointFrame, str]:
    frame_ids = sorted({p.frame_id for p in points})
    if header is not None:
        if frame_ids != [header.frame_id]:
            msg = f"{path}: frame ids {frame_ids} differ from the campaign's {header.frame_id!r}"
            raise BagError(msg)
        return header.frame, header.frame_id
    if len(frame_ids) != 1:
        msg = f"{path}: points are given in several frames {frame_ids}"
        raise BagError(msg)
    if not frame_ids[0]:
        msg = f"{path}: PointStamped header.frame_id is empty, the points' frame is unknown"
        raise BagError(msg)
    return ("base" if frame_ids[0] == base_frame_id else "tracker"), frame_ids[0]


def _point_std(
    std_readings: list[VectorReading], stamps: NDArray[np.int64], topic: str, path: Path
) -> NDArray[np.float64] | None:
    if not std_readings:
        return None
    by_stamp = {r.stamp_ns: r.xyz for r in std_readings}
    if len(by_stamp) != len(std_readings):
        _unique_stamps(np.array([r.stamp_ns for r in std_readings], dtype=np.int64), topic, path)
    missing = [int(s) for s in stamps if int(s) not in by_stamp]
    if missing:
        msg = f"{path}: no {topic} message for the point at stamp {missing[0]} ns"
        raise BagError(msg)
    return np.array([by_stamp[int(s)] for s in stamps], dtype=np.float64).reshape(-1, 3)


def _poses(
    bag: Bag,
    header: CampaignHeader,
    points: NDArray[np.float64],
    stamps: NDArray[np.int64],
    std: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], MeasurementType]:
    """Pose values (n, 12), stds (n, 6) and the measurement of a 6-DOF campaign file."""
    path = bag.path
    record = header.measurement or {}
    try:
        measurement = PoseMeasurement(
            tuple(record["position_std"]),  # type: ignore[arg-type]
            tuple(record["rotation_std"]),  # type: ignore[arg-type]
        )
    except (KeyError, TypeError, InputError) as err:
        msg = f"{path}: invalid pose measurement record {record!r}: {err}"
        raise BagError(msg) from err
    orientation: dict[int, NDArray[np.float64]] = {}
    for index, message in enumerate(bag.topic_messages(header.pose_topic, POSE_STAMPED)):
        try:
            reading = decode_pose_stamped(message.data)
        except DECODE_ERRORS as err:
            msg = f"{path}: cannot decode {POSE_STAMPED} #{index} on {header.pose_topic}: {err}"
            raise BagError(msg) from err
        orientation[reading.stamp_ns] = reading.quaternion
    missing = [int(s) for s in stamps if int(s) not in orientation]
    if missing:
        msg = f"{path}: no {header.pose_topic} message for the point at stamp {missing[0]} ns"
        raise BagError(msg)
    quaternions = np.array([orientation[int(s)] for s in stamps], dtype=np.float64).reshape(-1, 4)
    try:
        rotations = quaternion_to_matrix(quaternions, name=f"orientation on {header.pose_topic}")
    except InputError as err:
        msg = f"{path}: {err}"
        raise BagError(msg) from err
    rot_readings = _decode_vectors(
        bag.topic_messages(header.orientation_std_topic, VECTOR3_STAMPED), VECTOR3_STAMPED, path
    )
    rot_std = _point_std(rot_readings, stamps, header.orientation_std_topic, path)
    assert rot_std is not None
    if std is None:
        std = np.broadcast_to(np.asarray(measurement.position_std), (stamps.size, 3))
    return pose_values(points, rotations), np.concatenate((std, rot_std), axis=1), measurement


def _decode_all(
    bag: Bag, topics: tuple[str, str, str]
) -> tuple[list[JointReading], list[VectorReading], list[VectorReading]]:
    """Decode joint states, points and point std; raise when no pose can be formed."""
    joint_topic, point_topic, std_topic = topics
    path = bag.path
    if bag.truncated and not bag.contents.messages:
        raise BagError(_early(path))
    joints = _decode_joints(bag.topic_messages(joint_topic, JOINT_STATE), path)
    points = _decode_vectors(bag.topic_messages(point_topic, POINT_STAMPED), POINT_STAMPED, path)
    stds = _decode_vectors(bag.topic_messages(std_topic, VECTOR3_STAMPED, required=False), VECTOR3_STAMPED, path)
    if (not joints or not points) and bag.truncated:
        raise BagError(_early(path))
    if not joints or not points:
        msg = f"{path}: no pose found ({len(joints)} {joint_topic} and {len(points)} {point_topic} messages)"
        raise BagError(msg)
    return joints, points, stds


def _early(path: Path) -> str:
    return f"{path} is truncated before its first complete pose (writer stopped early)"


def _nearest_gaps_ms(joint_stamps: NDArray[np.int64], point_stamps: NDArray[np.int64]) -> NDArray[np.float64]:
    """Distance [ms] from each point stamp to the nearest joint stamp (inf without joints)."""
    if joint_stamps.size == 0:
        return np.full(point_stamps.size, np.inf)
    ordered = np.sort(joint_stamps)
    right = np.searchsorted(ordered, point_stamps).clip(0, ordered.size - 1)
    left = (right - 1).clip(0, ordered.size - 1)
    gap = np.minimum(np.abs(ordered[right] - point_stamps), np.abs(ordered[left] - point_stamps))
    return np.asarray(gap / 1e6, dtype=np.float64)


def _pair(
    joints: list[JointReading],
    point_stamps: NDArray[np.int64],
    tolerance_ns: int,
    topics: tuple[str, str, str],
    path: Path,
    *,
    truncated: bool | str,
    notes: list[str],
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pair points with joint states; warn about dropped points and truncation (the
    messages are also appended to `notes`)."""
    joint_topic, point_topic, _ = topics
    joint_stamps = np.array([r.stamp_ns for r in joints], dtype=np.int64)
    _unique_stamps(joint_stamps, joint_topic, path)
    _unique_stamps(point_stamps, point_topic, path)
    point_index, joint_index = pair_by_stamp(joint_stamps, point_stamps, tolerance_ns)
    if point_index.size == 0 and truncated:
        raise BagError(_early(path))
    unpaired = np.setdiff1d(np.arange(point_stamps.size), point_index)
    if unpaired.size:
        gaps = _nearest_gaps_ms(joint_stamps, point_stamps[unpaired])
        worst = int(np.argmax(gaps))
        first = (
            f"pose {int(unpaired[0]) + 1} of {point_stamps.size}: the {joint_topic} message nearest to its "
            f"{point_topic} stamp is {gaps[0]:.3g} ms away"
            + ("" if unpaired.size == 1 else f"; pose {int(unpaired[worst]) + 1}: {gaps[worst]:.3g} ms")
        )
        tolerance = f"the pairing tolerance of {tolerance_ns / 1e6:g} ms"
        if point_index.size == 0:
            msg = f"{path}: no pose found: {first}, more than {tolerance}"
            raise BagError(msg)
        notes.append(
            f"{path}: {unpaired.size} of {point_stamps.size} points on {point_topic} have no "
            f"{joint_topic} message within {tolerance} and were dropped ({first})"
        )
    if truncated == "damaged":
        notes.append(
            f"{path} is damaged (its records break off before its intact footer); read "
            f"{point_index.size} poses before the damage, the rest dropped (--accept-damaged)"
        )
    elif truncated:
        notes.append(
            f"{path} is truncated (writer stopped before the footer); recovered "
            f"{point_index.size} poses up to the last complete record"
        )
    for note in notes:
        warnings.warn(note, stacklevel=3)
    return point_index, joint_index


def _refuse_damaged(bag: Bag, accept_damaged: bool) -> None:
    """Refuse a finished file whose records break off in the middle, unless the caller accepts it."""
    path = bag.path
    damaged_at = getattr(bag.contents, "damaged_at", None)
    if damaged_at is not None and not accept_damaged:
        msg = (
            f"{path} is damaged: its records break off at byte {damaged_at} of {path.stat().st_size} although "
            "the file ends with an intact footer (finished, then corrupted; not a writer stopped early); "
            "refusing to drop the poses after the damage (--accept-damaged reads the poses before it)"
        )
        raise BagError(msg)


def _read_metadata(
    header: CampaignHeader | None, bag: Bag, wanted: tuple[str, str, str], stamp_tolerance_ns: int, dropped: int
) -> dict[str, object]:
    """The stored metadata, or the provenance of a file without a metadata record."""
    if header is not None:
        return dict(header.metadata)
    joint_topic, point_topic, _ = wanted
    return {
        "source_file": bag.path.name,
        "source_format": bag.storage,
        "joint_topic": joint_topic,
        "point_topic": point_topic,
        "stamp_tolerance_ns": stamp_tolerance_ns,
        "points_dropped": dropped,
    }


def _campaign(
    bag: Bag,
    header: CampaignHeader | None,
    wanted: tuple[str, str, str],
    *,
    base_frame_id: str,
    stamp_tolerance_ns: int,
) -> Campaign:
    """Decode, pair by stamp and assemble the campaign of an opened recording."""
    path, contents = bag.path, bag.contents
    damaged_at = getattr(contents, "damaged_at", None)
    joint_topic, _, point_std_topic = wanted
    joints, points, stds = _decode_all(bag, wanted)
    names, positions = _joint_matrix(joints, header.joint_names if header else None, joint_topic, path)
    point_stamps = np.array([r.stamp_ns for r in points], dtype=np.int64)
    notes: list[str] = []
    point_index, joint_index = _pair(
        joints,
        point_stamps,
        stamp_tolerance_ns,
        wanted,
        path,
        truncated="damaged" if damaged_at is not None else contents.truncated,
        notes=notes,
    )
    dropped = len(points) - point_index.size
    kept = [points[i] for i in point_index]
    stamps = point_stamps[point_index]
    frame, frame_id = _frame(kept, header, base_frame_id, path)
    metadata = _read_metadata(header, bag, wanted, stamp_tolerance_ns, dropped)
    # Warnings describe this reading of this file: a stored list (a recovered campaign
    # written back) is replaced, so a complete rewritten file does not claim truncation.
    metadata.pop(READ_WARNINGS_KEY, None)
    if notes:
        metadata[READ_WARNINGS_KEY] = notes
    values = np.array([p.xyz for p in kept], dtype=np.float64).reshape(-1, 3)
    std = _point_std(stds, stamps, point_std_topic, path)
    measurement: MeasurementType = POINT
    if header is not None and header.measurement is not None:
        values, std, measurement = _poses(bag, header, values, stamps, std)
    try:
        return Campaign(
            joint_names=names,
            joint_positions=positions[joint_index],
            points=values,
            frame=frame,
            frame_id=frame_id,
            point_std=std,
            stamps_ns=None if header is not None and header.stamps_synthetic else stamps,
            metadata=metadata,
            measurement=measurement,
        )
    except InputError as err:
        if isinstance(err, CampaignError):
            raise
        msg = f"{path}: {err}"
        raise BagError(msg) from err


def read_campaign(
    path: str | Path,
    *,
    base_frame_id: str = "base_link",
    joint_topic: str | None = None,
    point_topic: str | None = None,
    point_std_topic: str | None = None,
    stamp_tolerance_ns: int = 0,
    accept_damaged: bool = False,
) -> Campaign:
    """Read a campaign from an MCAP file or a rosbag2 directory.

    Parameters
    ----------
    path : str or Path
        A single ``.mcap`` file or a rosbag2 directory.
    base_frame_id : str
        Without a campaign metadata record, points whose ``header.frame_id`` equals this are
        taken as in the robot base frame (``frame="base"``), others as ``"tracker"``.
    joint_topic, point_topic, point_std_topic : str, optional
        Topic names; default: those in the metadata record, else ``/joint_states``,
        ``/tracker/point`` and ``/tracker/point_std``.
    stamp_tolerance_ns : int
        Largest stamp difference [ns] accepted when a point has no joint state with the same
        stamp (default 0: exact match only).
    accept_damaged : bool
        Read the poses before the damage of a finished file whose records break off in the
        middle (its footer intact: damaged, not truncated), dropping the rest with a warning.
        Default: refuse such a file; dropping measurements needs the caller's consent.

    Returns
    -------
    Campaign
        Joint positions [rad], points [m], optional point_std [m], stamps_ns [ns] (None when
        the writer synthesised them) and metadata (the stored dict, or provenance for files
        without a metadata record). When reading found problems it did not refuse (the file
        was truncated and recovered, points were dropped), ``metadata["warnings"]``
        (:data:`READ_WARNINGS_KEY`) lists them as one-line strings; otherwise that key is
        absent (a stored ``warnings`` entry is not kept: it described an earlier reading).

    Raises
    ------
    BagError
        (a :class:`CampaignError`) The path is missing or is not an MCAP file or rosbag2
        directory (see :func:`~robocal_uncertainty.bagio.bag.open_bag`); missing topics,
        wrong message types or encodings, undecodable messages, NaN, differing joint names,
        repeated stamps or no pose at all.

    Warns
    -----
    UserWarning
        When the file was truncated (recovered up to the last complete record) or when
        points without a matching joint state were dropped; the same messages as in
        ``metadata["warnings"]``.
    """
    path = Path(path)
    wanted = (
        joint_topic or JOINT_TOPIC,
        point_topic or POINT_TOPIC,
        point_std_topic or POINT_STD_TOPIC,
    )
    bag = open_bag(path, wanted, what="campaign")
    _refuse_damaged(bag, accept_damaged)
    record = bag.contents.metadata.get(METADATA_NAME)
    header = None if record is None else parse_header(record, str(path))
    if header is not None:
        wanted = (
            joint_topic or header.joint_topic,
            point_topic or header.point_topic,
            point_std_topic or header.point_std_topic,
        )
    return _campaign(bag, header, wanted, base_frame_id=base_frame_id, stamp_tolerance_ns=stamp_tolerance_ns)
