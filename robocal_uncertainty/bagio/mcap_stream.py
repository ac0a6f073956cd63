"""Read every message and metadata record of one MCAP file, tolerating a missing end.

A writer killed before ``finish`` leaves a file without summary, footer and closing magic,
possibly with a half-written last record. :func:`read_mcap_file` first walks the top-level
record framing (opcode, length) to find where the last complete record ends, then feeds
exactly those bytes to mcap's non-seeking :class:`~mcap.stream_reader.StreamReader`. All
complete records are returned and ``truncated`` tells whether the end was missing.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import EndOfFile
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from robocal_uncertainty.errors import BagError

__all__ = ["MCAP_MAGIC", "ChannelInfo", "McapContents", "RawMessage", "is_mcap", "read_mcap_file"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_OPCODE = 0x02
_RECORD_PREFIX = struct.Struct("<BQ")


@dataclass(frozen=True)
class ChannelInfo:
    """Topic, message type and encodings of one MCAP channel."""

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str


@dataclass(frozen=True)
class RawMessage:
    """One undecoded message: its channel, log time [ns] and serialised payload."""

    channel: ChannelInfo
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class McapContents:
    """Messages (file order) and metadata records of an MCAP file.

    Parameters
    ----------
    messages : tuple of RawMessage
        Every complete message, in file order.
    metadata : dict of str to dict of str to str
        Metadata records by name (the last one wins on duplicate names).
    channels : tuple of ChannelInfo
        Every channel declared in the readable part of the file.
    truncated : bool
        True when the file ended before its footer (writer killed); only complete records
        were read.
    """

    messages: tuple[RawMessage, ...]
    metadata: dict[str, dict[str, str]]
    channels: tuple[ChannelInfo, ...]
    truncated: bool


class _Bounded(io.RawIOBase):
    """Raw reader exposing only the first `limit` bytes of `stream`."""

    def __init__(self, stream: BinaryIO, limit: int) -> None:
        super().__init__()
        self._stream = stream
        self._left = limit

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: memoryview) -> int:  # type: ignore[override]
        size = min(len(buffer), self._left)
        if size <= 0:
            return 0
        data = self._stream.read(size)
        buffer[: len(data)] = data
        self._left -= len(data)
        return len(data)


def is_mcap(path: Path) -> bool:
    """Return whether `path` is a file starting with the MCAP magic bytes."""
    with path.open("rb") as stream:
        return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def _complete_length(stream: BinaryIO, size: int) -> tuple[int, bool]:
    """Return (bytes up to the end of the last complete record, whether the footer was seen)."""
    position = len(MCAP_MAGIC)
    stream.seek(position)
    while position + _RECORD_PREFIX.size <= size:
        opcode, length = _RECORD_PREFIX.unpack(stream.read(_RECORD_PREFIX.size))
        end = position + _RECORD_PREFIX.size + length
        if end > size:
            break
        position = end
        if opcode == _FOOTER_OPCODE:
            return position, position + len(MCAP_MAGIC) <= size
        stream.seek(position)
    return position, False


class _Collector:
    """Gathers schemas, channels, messages and metadata records of one file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, ChannelInfo] = {}
        self.messages: list[RawMessage] = []
        self.metadata: dict[str, dict[str, str]] = {}

    def add(self, record: object) -> None:
        if isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            schema = self.schemas.get(record.schema_id)
            self.channels[record.id] = ChannelInfo(
                record.topic,
                "" if schema is None else schema.name,
                "" if schema is None else schema.encoding,
                record.message_encoding,
            )
        elif isinstance(record, Message):
            channel = self.channels.get(record.channel_id)
            if channel is None:
                msg = f"MCAP file {self.path}: message on undeclared channel {record.channel_id}"
                raise BagError(msg)
            self.messages.append(RawMessage(channel, record.log_time, bytes(record.data)))
        elif isinstance(record, Metadata):
            self.metadata[record.name] = dict(record.metadata)


def read_mcap_file(path: Path) -> McapContents:
    """Read all complete messages and metadata records of the MCAP file `path`.

    Raises
    ------
    BagError
        If the file is not an MCAP file or a complete record in it is corrupt.
    """
    collector = _Collector(path)
    size = path.stat().st_size
    with path.open("rb") as stream:
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            msg = f"not a campaign: {path} is not an MCAP file (bad magic bytes)"
            raise BagError(msg)
        limit, complete = _complete_length(stream, size)
        stream.seek(0)
        reader = StreamReader(_Bounded(stream, limit), validate_crcs=True)
        try:
            for record in reader.records:
                if isinstance(record, Footer):
                    break
                collector.add(record)
        except EndOfFile:
            if complete:
                msg = f"MCAP file {path} ends inside its closing magic bytes"
                raise BagError(msg) from None
        except BagError:
            raise
        except Exception as err:  # mcap, struct and the decompressors raise many types
            msg = f"corrupt MCAP file {path}: {type(err).__name__}: {err}"
            raise BagError(msg) from err
    return McapContents(
        tuple(collector.messages),
        collector.metadata,
        tuple(collector.channels.values()),
        truncated=not complete,
    )
