"""The one bag opener: a single MCAP file or a rosbag2 directory, and its typed topics.

Both readers of recordings use it: :func:`~robocal_uncertainty.bagio.campaign_reader.read_campaign`
(campaign MCAP files and other recordings of poses) and the raw-stream replay
(:func:`~robocal_uncertainty.pipeline.replay.replay_bag`). They differ in what they do with
the messages, not in how a bag is found, opened, or its topics checked.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from robocal_uncertainty.bagio.mcap_stream import McapContents, RawMessage, is_mcap, read_mcap_file
from robocal_uncertainty.bagio.ros_messages import DECODE_ERRORS, ros_typestore
from robocal_uncertainty.bagio.rosbag2_dir import is_rosbag2_dir, read_rosbag2_dir
from robocal_uncertainty.errors import BagError

__all__ = ["Bag", "open_bag"]


@dataclass(frozen=True)
class Bag:
    """An opened recording: its messages, metadata records and channels.

    Attributes
    ----------
    path : Path
        The MCAP file or rosbag2 directory.
    contents : McapContents
        Messages (file order for one MCAP file, log-time order for a rosbag2 directory),
        metadata records (none for a rosbag2 directory), channels of every topic, and
        whether the file ended without its footer.
    storage : {"mcap", "rosbag2"}
        What `path` is.
    """

    path: Path
    contents: McapContents
    storage: Literal["mcap", "rosbag2"]

    @property
    def truncated(self) -> bool:
        """The MCAP file ended without its footer (its writer was killed)."""
        return self.contents.truncated

    def topic_messages(self, topic: str, typename: str, *, required: bool = True) -> list[RawMessage]:
        """Messages on `topic`, after checking that it carries CDR messages of `typename`.

        Parameters
        ----------
        topic : str
        typename : str
            ROS 2 message type, e.g. ``sensor_msgs/msg/JointState``.
        required : bool
            A missing topic is an error (else: no messages).

        Raises
        ------
        BagError
            Missing topic (when `required`), another message type or another encoding.
        """
        channels = {c for c in self.contents.channels if c.topic == topic}
        if not channels:
            if not required:
                return []
            known = sorted({c.topic for c in self.contents.channels})
            msg = f"{self.path}: topic {topic} not found (topics: {known})"
            raise BagError(msg)
        for channel in channels:
            if channel.schema_name != typename:
                msg = f"{self.path}: topic {topic} has type {channel.schema_name!r}, expected {typename}"
                raise BagError(msg)
            if channel.message_encoding != "cdr":
                msg = f"{self.path}: topic {topic} has encoding {channel.message_encoding!r}, expected 'cdr'"
                raise BagError(msg)
        return [m for m in self.contents.messages if m.channel.topic == topic]

    @staticmethod
    def try_decode(message: RawMessage, typename: str) -> Any | None:
        """The rosbags message object of `message`, or None when its payload is not valid CDR."""
        try:
            return ros_typestore().deserialize_cdr(message.data, typename)
        except DECODE_ERRORS:
            return None


def open_bag(path: str | Path, topics: tuple[str, ...], *, what: str = "bag") -> Bag:
    """Open a single MCAP file or a rosbag2 directory (storage mcap or sqlite3).

    Parameters
    ----------
    path : str or Path
    topics : tuple of str
        Topics whose messages are read from a rosbag2 directory (an MCAP file is read whole).
    what : str
        What the caller expects, for messages: ``"bag"`` or ``"campaign"``.

    Raises
    ------
    BagError
        Missing path, unreadable or corrupt file, or neither an MCAP file nor a rosbag2
        directory. (A :class:`~robocal_uncertainty.errors.CampaignError` too.)
    """
    path = Path(path)
    if not path.exists():
        msg = f"{what} file not found: {path}"
        raise BagError(msg)
    try:
        if is_rosbag2_dir(path):
            return Bag(path, read_rosbag2_dir(path, topics), "rosbag2")
        if path.is_file() and is_mcap(path):
            return Bag(path, read_mcap_file(path), "mcap")
    except OSError as err:
        msg = f"cannot read {what} {path}: {err.strerror or err}"
        raise BagError(msg) from err
    msg = f"not a {what}: {path} is neither an MCAP file nor a rosbag2 directory"
    raise BagError(msg)
