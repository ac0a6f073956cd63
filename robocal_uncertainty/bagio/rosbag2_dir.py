"""Read the raw messages of chosen topics from a rosbag2 directory (``ros2 bag record``)."""

from __future__ import annotations

from pathlib import Path

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import ReaderError

from robocal_uncertainty.bagio.mcap_stream import ChannelInfo, McapContents, RawMessage
from robocal_uncertainty.bagio.ros_messages import ros_typestore
from robocal_uncertainty.errors import BagError

__all__ = ["is_rosbag2_dir", "read_rosbag2_dir"]

_SCHEMA_ENCODINGS = {"MSG": "ros2msg", "IDL": "ros2idl"}
"""rosbags ``MessageDefinitionFormat`` member names (rosbags >= 0.10.x) to MCAP encodings."""


def _channel(connection: Connection) -> ChannelInfo:
    ext = connection.ext
    encoding = ext.serialization_format if isinstance(ext, ConnectionExtRosbag2) else ""
    definition_format = getattr(getattr(connection.msgdef, "format", None), "name", "")
    schema_encoding = _SCHEMA_ENCODINGS.get(str(definition_format), "")
    return ChannelInfo(connection.topic, connection.msgtype, schema_encoding, encoding)


def is_rosbag2_dir(path: Path) -> bool:
    """Return whether `path` is a directory with a rosbag2 ``metadata.yaml``."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def read_rosbag2_dir(path: Path, topics: tuple[str, ...]) -> McapContents:
    """Read every message on `topics` from the rosbag2 directory `path` (storage mcap or sqlite3).

    Messages come in log-time order. Channels of all topics in the bag are listed, so the
    caller can tell a missing topic from a wrongly typed one. The bag has no campaign
    metadata record (``metadata`` is empty) and is never reported truncated.

    Raises
    ------
    BagError
        If rosbags cannot open or read the bag.
    """
    try:
        with AnyReader([path], default_typestore=ros_typestore()) as reader:
            channels = tuple(_channel(c) for c in reader.connections)
            wanted = [c for c in reader.connections if c.topic in topics]
            messages = tuple(
                RawMessage(_channel(connection), int(stamp), bytes(data))
                for connection, stamp, data in (reader.messages(connections=wanted) if wanted else ())
            )
    except (AnyReaderError, ReaderError, OSError, ValueError, KeyError) as err:
        msg = f"cannot read rosbag2 directory {path}: {type(err).__name__}: {err}"
        raise BagError(msg) from err
    return McapContents(messages, {}, channels, truncated=False)
