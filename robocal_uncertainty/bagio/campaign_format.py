"""The campaign MCAP layout: topic names and the JSON metadata record.

A campaign MCAP file holds, per measured pose, one message on each topic below, all with
the same header stamp:

* ``/joint_states`` - ``sensor_msgs/msg/JointState``: joint names and positions [rad];
* ``/tracker/point`` - ``geometry_msgs/msg/PointStamped``: measured point [m] in
  ``header.frame_id``;
* ``/tracker/point_std`` - ``geometry_msgs/msg/Vector3Stamped`` (only when the instrument
  reports it): standard deviation of each coordinate of the point [m].
* 6-DOF campaigns only: ``/tracker/pose`` - ``geometry_msgs/msg/PoseStamped``: the measured
  position (equal to the point) and orientation (unit quaternion x, y, z, w) of the probe in
  ``header.frame_id``; ``/tracker/orientation_std`` - ``geometry_msgs/msg/Vector3Stamped``:
  standard deviation [rad] of the orientation about the frame's fixed x, y, z axes. The
  record's ``measurement`` entry (``{"type": "pose", "position_std": [3 m],
  "rotation_std": [3 rad]}``) gives the weights; files without it (all earlier files) are
  point campaigns, and a point-only reader still finds ``/tracker/point``.

One MCAP metadata record named ``robocal_campaign`` is written when the file is opened, so
it survives a crash. Its ``campaign`` entry is a JSON object holding the format version,
the units, frame and frame id, joint names, topic names, whether stamps were synthesised
and the campaign's free-form metadata.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from robocal_uncertainty.core.campaign import PointFrame
from robocal_uncertainty.errors import BagError, InputError

__all__ = [
    "FORMAT_VERSION",
    "JOINT_TOPIC",
    "METADATA_NAME",
    "ORIENTATION_STD_TOPIC",
    "POINT_STD_TOPIC",
    "POINT_TOPIC",
    "POSE_TOPIC",
    "UNITS",
    "CampaignHeader",
    "parse_header",
]

FORMAT_VERSION = 1
METADATA_NAME = "robocal_campaign"
JOINT_TOPIC = "/joint_states"
POINT_TOPIC = "/tracker/point"
POINT_STD_TOPIC = "/tracker/point_std"
POSE_TOPIC = "/tracker/pose"
ORIENTATION_STD_TOPIC = "/tracker/orientation_std"
UNITS: dict[str, str] = {"joint_positions": "rad", "points": "m", "point_std": "m", "stamps": "ns"}
"""Units of every quantity in a campaign file (stamps: ns since the epoch)."""


def _to_json(value: object) -> object:
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    msg = f"campaign metadata value of type {type(value).__name__} is not JSON-serialisable"
    raise TypeError(msg)


@dataclass(frozen=True)
class CampaignHeader:
    """Everything about a campaign file that is not per pose.

    Parameters
    ----------
    frame : {"base", "tracker"}
        Frame of the points (see :class:`~robocal_uncertainty.core.campaign.Campaign`).
    frame_id : str
        ``header.frame_id`` of the points.
    joint_names : tuple of str
        Joint names, in column order.
    stamps_synthetic : bool
        True when the stamps were made up by the writer (the campaign had none); the reader
        then returns ``stamps_ns=None``.
    metadata : dict
        The campaign's free-form metadata (JSON-serialisable; numpy values become lists).
    joint_topic, point_topic, point_std_topic : str
        Topic names used in the file.
    measurement : dict or None
        ``{"type": "pose", "position_std": [...], "rotation_std": [...]}`` for 6-DOF
        campaigns (SI units); None for points.
    pose_topic, orientation_std_topic : str
        Topics of the 6-DOF messages.
    """

    frame: PointFrame
    frame_id: str
    joint_names: tuple[str, ...]
    stamps_synthetic: bool = False
    metadata: dict[str, object] = field(default_factory=dict)
    joint_topic: str = JOINT_TOPIC
    point_topic: str = POINT_TOPIC
    point_std_topic: str = POINT_STD_TOPIC
    measurement: dict[str, object] | None = None
    pose_topic: str = POSE_TOPIC
    orientation_std_topic: str = ORIENTATION_STD_TOPIC

    def to_record(self) -> dict[str, str]:
        """Return the MCAP metadata record (string map) describing this header.

        Raises
        ------
        InputError
            If the metadata is not JSON-serialisable or holds NaN/inf.
        """
        content: dict[str, object] = {
            "format": METADATA_NAME,
            "format_version": FORMAT_VERSION,
            "units": UNITS,
            "frame": self.frame,
            "frame_id": self.frame_id,
            "joint_names": list(self.joint_names),
            "topics": {
                "joint_states": self.joint_topic,
                "point": self.point_topic,
                "point_std": self.point_std_topic,
            },
            "stamps_synthetic": self.stamps_synthetic,
            "metadata": self.metadata,
        }
        if self.measurement is not None:
            # Only for 6-DOF campaigns: point campaigns keep the record they always had.
            content["measurement"] = self.measurement
            topics = content["topics"]
            assert isinstance(topics, dict)
            topics["pose"] = self.pose_topic
            topics["orientation_std"] = self.orientation_std_topic
        try:
            text = json.dumps(content, allow_nan=False, default=_to_json, sort_keys=True)
        except (TypeError, ValueError) as err:
            msg = f"campaign metadata cannot be stored as JSON: {err}"
            raise InputError(msg) from err
        return {"format_version": str(FORMAT_VERSION), "campaign": text}


_T = TypeVar("_T")


def _field(content: dict[str, object], key: str, kind: type[_T], where: str) -> _T:
    value = content.get(key)
    if not isinstance(value, kind):
        msg = f"{where}: metadata record field {key!r} is missing or not a {kind.__name__}"
        raise BagError(msg)
    return value


def parse_header(record: dict[str, str], where: str) -> CampaignHeader:
    """Parse the ``robocal_campaign`` metadata record of the file named by `where`.

    Raises
    ------
    BagError
        If the record is not valid JSON, has another format version or other units.
    """
    try:
        content = json.loads(record["campaign"])
    except (KeyError, json.JSONDecodeError) as err:
        msg = f"{where}: metadata record {METADATA_NAME!r} has no valid 'campaign' JSON ({err})"
        raise BagError(msg) from err
    if not isinstance(content, dict):
        msg = f"{where}: metadata record {METADATA_NAME!r} is not a JSON object"
        raise BagError(msg)
    version = content.get("format_version")
    if version != FORMAT_VERSION:
        msg = f"{where}: campaign format version {version!r} is not supported (expected {FORMAT_VERSION})"
        raise BagError(msg)
    if content.get("units") != UNITS:
        msg = f"{where}: campaign units {content.get('units')!r} differ from {UNITS!r}"
        raise BagError(msg)
    frame = _field(content, "frame", str, where)
    if frame not in ("base", "tracker"):
        msg = f"{where}: campaign frame {frame!r} is not 'base' or 'tracker'"
        raise BagError(msg)
    topics = _field(content, "topics", dict, where)
    frame_literal: PointFrame = "base" if frame == "base" else "tracker"
    measurement = content.get("measurement")
    if measurement is not None and not (isinstance(measurement, dict) and measurement.get("type") == "pose"):
        msg = f"{where}: campaign measurement {measurement!r} is not a pose measurement record"
        raise BagError(msg)
    return CampaignHeader(
        frame=frame_literal,
        frame_id=_field(content, "frame_id", str, where),
        joint_names=tuple(str(n) for n in _field(content, "joint_names", list, where)),
        stamps_synthetic=_field(content, "stamps_synthetic", bool, where),
        metadata=_field(content, "metadata", dict, where),
        joint_topic=str(topics.get("joint_states", JOINT_TOPIC)),
        point_topic=str(topics.get("point", POINT_TOPIC)),
        point_std_topic=str(topics.get("point_std", POINT_STD_TOPIC)),
        measurement=measurement,
        pose_topic=str(topics.get("pose", POSE_TOPIC)),
        orientation_std_topic=str(topics.get("orientation_std", ORIENTATION_STD_TOPIC)),
    )
