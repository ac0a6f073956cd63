"""Read every message and metadata record of one MCAP file, tolerating a missing end.

A writer killed before ``finish`` leaves a file without summary, footer and closing magic,
possibly with a half-written last record. :func:`read_mcap_file` first walks the top-level
record framing (opcode, length) to find where the last complete record ends, then reads
exactly those bytes, record by record, up to the footer. All complete records are returned
and ``truncated`` tells whether the end was missing.

Messages (in chunks, where a recorder puts them, or at top level) are unpacked here, one
``struct`` call each on the (decompressed) bytes; schemas, channels, metadata and chunk
headers are read by mcap's record classes; indexes and statistics are not parsed (a replay
reads every message in file order). The chunk and data-section CRCs are checked, as mcap's
``StreamReader(validate_crcs=True)`` checks them.
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema

from robocal_uncertainty.errors import BagError

__all__ = ["MCAP_MAGIC", "ChannelInfo", "McapContents", "RawMessage", "is_mcap", "read_mcap_file"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_OPCODE = 0x02
_RECORD_PREFIX = struct.Struct("<BQ")
_MESSAGE_HEADER = struct.Struct("<HIQQ")
"""Message record: channel id, sequence, log time [ns], publish time [ns]; the data follow."""


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
    damaged_at : int or None
        Byte offset where the record framing breaks although the file ends with an intact
        footer and closing magic: the file was finished and then damaged (not truncated by a
        killed writer); only the records before that offset were read. None otherwise.
    """

    messages: tuple[RawMessage, ...]
    metadata: dict[str, dict[str, str]]
    channels: tuple[ChannelInfo, ...]
    truncated: bool
    damaged_at: int | None = None


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
        elif isinstance(record, Metadata):
            self.metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Chunk):
            self.add_chunk(record)

    def add_message(self, channel_id: int, log_time: int, data: bytes) -> None:
        channel = self.channels.get(channel_id)
        if channel is None:
            msg = f"MCAP file {self.path}: message on undeclared channel {channel_id}"
            raise BagError(msg)
        self.messages.append(RawMessage(channel, log_time, data))

    def add_chunk(self, chunk: Chunk) -> None:
        """The records of one chunk, in order (messages without mcap's record objects)."""
        data = _chunk_bytes(chunk)
        size = len(data)
        offset = 0
        prefix, header = _RECORD_PREFIX, _MESSAGE_HEADER
        append, channels = self.messages.append, self.channels
        while offset < size:
            opcode, length = prefix.unpack_from(data, offset)
            body = offset + prefix.size
            offset = body + length
            if offset > size:
                msg = f"record of {length} bytes past the end of its chunk ({size} bytes)"
                raise ValueError(msg)
            if opcode == Opcode.MESSAGE:
                channel_id, _, log_time, _ = header.unpack_from(data, body)
                channel = channels.get(channel_id)
                if channel is None:
                    msg = f"MCAP file {self.path}: message on undeclared channel {channel_id}"
                    raise BagError(msg)
                append(RawMessage(channel, log_time, data[body + header.size : offset]))
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                stream = ReadDataStream(io.BytesIO(data[body:offset]))
                self.add(Schema.read(stream) if opcode == Opcode.SCHEMA else Channel.read(stream))


def _chunk_bytes(chunk: Chunk) -> bytes:
    """Decompressed records of `chunk`, its CRC checked (as mcap's ``validate_crcs`` does)."""
    # The decompressors mcap uses, imported when needed (as mcap does, an error without them).
    if chunk.compression == "zstd":
        try:
            import zstandard
        except ImportError:  # pragma: no cover - installed with mcap's ros2 support
            raise BagError("MCAP chunk compressed with zstd, but the zstandard module is not installed") from None
        data: bytes = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        try:
            import lz4.frame
        except ImportError:  # pragma: no cover
            raise BagError("MCAP chunk compressed with lz4, but the lz4 module is not installed") from None
        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = bytes(chunk.data)
    else:
        msg = f"MCAP chunk with unknown compression {chunk.compression!r}"
        raise BagError(msg)
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        msg = f"chunk CRC {zlib.crc32(data)} does not match the recorded {chunk.uncompressed_crc}"
        raise ValueError(msg)
    return data


_RECORD_TYPES: dict[int, type[Schema] | type[Channel] | type[Metadata] | type[Chunk]] = {
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.METADATA: Metadata,
    Opcode.CHUNK: Chunk,
}


def _read_records(collector: _Collector, data: bytes, limit: int) -> None:
    """Walk the top-level records in ``data[8:limit]`` (all complete) up to the footer.

    Messages are unpacked in place; schemas, channels, metadata and chunks are read by mcap's
    record classes; the data section's CRC (in the DataEnd record) is checked, as mcap's
    ``StreamReader(validate_crcs=True)`` does.
    """
    offset = len(MCAP_MAGIC)
    prefix, header = _RECORD_PREFIX, _MESSAGE_HEADER
    while offset + prefix.size <= limit:
        opcode, length = prefix.unpack_from(data, offset)
        body = offset + prefix.size
        end = body + length
        if opcode == Opcode.FOOTER:
            return
        if opcode == Opcode.MESSAGE:
            channel_id, _, log_time, _ = header.unpack_from(data, body)
            collector.add_message(channel_id, log_time, data[body + header.size : end])
        elif opcode == Opcode.DATA_END:
            (recorded,) = struct.unpack_from("<I", data, body)
            if recorded != 0 and zlib.crc32(data[:offset]) != recorded:
                msg = f"data section CRC {zlib.crc32(data[:offset])} does not match the recorded {recorded}"
                raise ValueError(msg)
        elif opcode in _RECORD_TYPES:
            collector.add(_RECORD_TYPES[opcode].read(ReadDataStream(io.BytesIO(data[body:end]))))
        # Other records (header, indexes, statistics, attachments, unknown opcodes) are skipped.
        offset = end


_FOOTER_LENGTH = 20
"""Body length of an MCAP footer record (summary start, summary offset start, summary CRC)."""


def _footer_intact(stream: BinaryIO, size: int) -> bool:
    """Whether the file ends with a footer record and the closing magic (it was finished)."""
    tail = _RECORD_PREFIX.size + _FOOTER_LENGTH + len(MCAP_MAGIC)
    if size < len(MCAP_MAGIC) + tail:
        return False
    stream.seek(size - tail)
    data = stream.read(tail)
    opcode, length = _RECORD_PREFIX.unpack_from(data, 0)
    return bool(opcode == _FOOTER_OPCODE and length == _FOOTER_LENGTH and data.endswith(MCAP_MAGIC))


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
        damaged_at = limit if not complete and _footer_intact(stream, size) else None
        stream.seek(0)
        data = stream.read(limit)
    try:
        _read_records(collector, data, limit)
    except BagError:
        raise
    except Exception as err:  # struct, mcap's record readers and the decompressors raise many types
        msg = f"corrupt MCAP file {path}: {type(err).__name__}: {err}"
        raise BagError(msg) from err
    return McapContents(
        tuple(collector.messages),
        collector.metadata,
        tuple(collector.channels.values()),
        truncated=not complete,
        damaged_at=damaged_at,
    )
