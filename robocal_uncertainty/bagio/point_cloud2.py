"""``sensor_msgs/msg/PointCloud2`` sections from a bag, and their encoding for tests and tools.

A robot-held scanner records a section as one or more ``PointCloud2`` messages. Their ``x``,
``y``, ``z`` fields (FLOAT32 or FLOAT64, metres per REP 103) become the points of an
:class:`~robocal_uncertainty.inspection.PointCloud`; optional ``normal_x``, ``normal_y``,
``normal_z`` fields become its probe vectors. The header's ``frame_id`` is kept. Messages
that are not dense (``is_dense`` false) may hold invalid points (NaN): those are dropped;
a NaN in a dense cloud is an error. The bag is opened by the one bag opener,
:func:`~robocal_uncertainty.bagio.bag.open_bag` (an MCAP file or a rosbag2 directory).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.bagio.bag import open_bag
from robocal_uncertainty.bagio.raw_bag_simulator import RawRecord, write_raw_records
from robocal_uncertainty.bagio.ros_messages import DECODE_ERRORS, ros_typestore, stamp_parts
from robocal_uncertainty.errors import BagError, InputError
from robocal_uncertainty.inspection.point_cloud import PointCloud

__all__ = ["POINT_CLOUD2", "encode_point_cloud2", "read_point_cloud2", "write_point_cloud2_mcap"]

POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"

_FLOAT32 = 7  # sensor_msgs/msg/PointField datatypes
_FLOAT64 = 8
_FLOAT_TYPES = {_FLOAT32: "f4", _FLOAT64: "f8"}
_XYZ = ("x", "y", "z")
_NORMALS = ("normal_x", "normal_y", "normal_z")


def encode_point_cloud2(
    stamp_ns: int,
    frame_id: str,
    points: ArrayLike,
    normals: ArrayLike | None = None,
    *,
    float64: bool = False,
) -> bytes:
    """Serialise an unorganised (height 1) ``PointCloud2`` to CDR.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns].
    frame_id : str
        Header frame.
    points : array_like, shape (n, 3) [m]
        x, y, z.
    normals : array_like, shape (n, 3), optional
        Probe vectors, written as ``normal_x/y/z``.
    float64 : bool
        FLOAT64 fields (default FLOAT32, as most scanners publish).
    """
    xyz = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        msg = f"points must have shape (n, 3), got {xyz.shape}"
        raise InputError(msg)
    names = _XYZ if normals is None else _XYZ + _NORMALS
    columns = xyz if normals is None else np.column_stack([xyz, np.asarray(normals, dtype=np.float64)])
    code, kind = (_FLOAT64, "<f8") if float64 else (_FLOAT32, "<f4")
    size = np.dtype(kind).itemsize
    data = np.ascontiguousarray(columns, dtype=kind).tobytes()
    store = ros_typestore()
    field_type = store.types["sensor_msgs/msg/PointField"]
    fields = [field_type(name=name, offset=k * size, datatype=code, count=1) for k, name in enumerate(names)]
    sec, nanosec = stamp_parts(stamp_ns)
    header = store.types["std_msgs/msg/Header"](
        stamp=store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id
    )
    message = store.types[POINT_CLOUD2](
        header=header,
        height=1,
        width=xyz.shape[0],
        fields=fields,
        is_bigendian=False,
        point_step=size * len(names),
        row_step=size * len(names) * xyz.shape[0],
        data=np.frombuffer(data, dtype=np.uint8),
        is_dense=bool(np.isfinite(xyz).all()),
    )
    return bytes(store.serialize_cdr(message, POINT_CLOUD2))


def write_point_cloud2_mcap(
    path: str | Path,
    messages: list[bytes],
    *,
    topic: str = "/section/points",
    overwrite: bool = False,
) -> Path:
    """Write CDR ``PointCloud2`` payloads (from :func:`encode_point_cloud2`) to an MCAP file.

    Log times are 1 s apart from t = 1 s [ns]; written by
    :func:`~robocal_uncertainty.bagio.raw_bag_simulator.write_raw_records`. Raises BagError if
    the file exists (without `overwrite`) or cannot be written.
    """
    records = [RawRecord(topic, POINT_CLOUD2, (k + 1) * 1_000_000_000, data) for k, data in enumerate(messages)]
    write_raw_records(path, records, overwrite=overwrite)
    return Path(path)


def _field_columns(message: Any, where: str) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """x/y/z (and normals) of one decoded PointCloud2, shape (n, 3) each [m]."""
    fields = {f.name: f for f in message.fields}
    missing = [name for name in _XYZ if name not in fields]
    if missing:
        msg = f"{where}: PointCloud2 has no field(s) {missing} (fields: {sorted(fields)})"
        raise BagError(msg)
    names = _XYZ + (_NORMALS if all(n in fields for n in _NORMALS) else ())
    order = ">" if message.is_bigendian else "<"
    formats = []
    for name in names:
        field = fields[name]
        if field.datatype not in _FLOAT_TYPES or field.count != 1:
            msg = (
                f"{where}: PointCloud2 field {name!r} must be one FLOAT32 or FLOAT64 "
                f"(datatype 7 or 8), got datatype {field.datatype} count {field.count}"
            )
            raise BagError(msg)
        formats.append(order + _FLOAT_TYPES[field.datatype])
    step = int(message.point_step)
    ends = [fields[n].offset + np.dtype(f).itemsize for n, f in zip(names, formats)]
    width, height, row_step = int(message.width), int(message.height), int(message.row_step)
    data = np.asarray(message.data, dtype=np.uint8).tobytes()
    if step < max(ends) or row_step < step * width or len(data) < row_step * height:
        msg = (
            f"{where}: corrupt PointCloud2: point_step {step}, row_step {row_step}, {width}x{height} points "
            f"need fields up to byte {max(ends)} and {row_step * height} data bytes, got {len(data)}"
        )
        raise BagError(msg)
    record = np.dtype(
        {"names": list(names), "formats": formats, "offsets": [fields[n].offset for n in names], "itemsize": step}
    )
    rows = [np.frombuffer(data, dtype=record, count=width, offset=r * row_step) for r in range(height)]
    table = np.concatenate(rows) if rows else np.zeros(0, dtype=record)
    xyz = np.column_stack([table[n].astype(np.float64) for n in _XYZ]) if table.size else np.zeros((0, 3))
    normals = None
    if len(names) == 6 and table.size:
        normals = np.column_stack([table[n].astype(np.float64) for n in _NORMALS])
    if not message.is_dense:
        keep = np.isfinite(xyz).all(axis=1)
        xyz = xyz[keep]
        normals = None if normals is None else normals[keep]
    return xyz, normals


def read_point_cloud2(path: str | Path, topic: str | None = None, *, message: int | None = None) -> PointCloud:
    """One section from the ``PointCloud2`` messages of a bag.

    Parameters
    ----------
    path : str or Path
        MCAP file or rosbag2 directory.
    topic : str, optional
        PointCloud2 topic; default the bag's only PointCloud2 topic.
    message : int, optional
        0-based index of the message to read; default all messages of the topic together
        (the scan lines of one section; they must share one ``frame_id``).

    Returns
    -------
    PointCloud
        Points [m] (REP 103), probe vectors from ``normal_x/y/z`` when present, the header's
        ``frame_id`` and ``source`` ``"<path>:<topic>"``.

    Raises
    ------
    BagError
        Missing bag or topic, another message type, no PointCloud2 topic or several (without
        `topic`), message index out of range, undecodable message, missing or non-float x/y/z
        fields, sizes that do not fit the data, messages in different frames.
    InputError
        No valid point, NaN in a dense cloud, a zero normal (from :class:`PointCloud`).
    """
    bag = open_bag(path, (topic,) if topic else (), what="bag")
    if topic is None:
        topics = sorted({c.topic for c in bag.contents.channels if c.schema_name == POINT_CLOUD2})
        if len(topics) != 1:
            found = "no PointCloud2 topic" if not topics else f"several PointCloud2 topics {topics}"
            msg = f"{bag.path}: {found}; name one with the topic argument (--topic)"
            raise BagError(msg)
        topic = topics[0]
        if bag.storage == "rosbag2":
            bag = open_bag(path, (topic,), what="bag")
    raw = bag.topic_messages(topic, POINT_CLOUD2)
    if not raw:
        msg = f"{bag.path}: topic {topic} has no messages"
        raise BagError(msg)
    if message is not None:
        if not 0 <= message < len(raw):
            msg = f"{bag.path}: message index {message} is out of range for {len(raw)} messages on {topic}"
            raise BagError(msg)
        raw = [raw[message]]
    points, normals, frames = [], [], set()
    for k, item in enumerate(raw):
        where = f"{bag.path}: {topic} message {k if message is None else message}"
        try:
            decoded: Any = ros_typestore().deserialize_cdr(item.data, POINT_CLOUD2)
        except DECODE_ERRORS as err:
            msg = f"{where}: cannot decode PointCloud2: {err}"
            raise BagError(msg) from err
        xyz, vectors = _field_columns(decoded, where)
        points.append(xyz)
        normals.append(vectors)
        frames.add(str(decoded.header.frame_id))
    if len(frames) > 1:
        msg = f"{bag.path}: {topic} messages are in different frames {sorted(frames)}; read one with --message"
        raise BagError(msg)
    xyz = np.concatenate(points)
    if xyz.shape[0] == 0:
        msg = f"{bag.path}: {topic} holds no valid point"
        raise InputError(msg)
    probe = None if any(v is None for v in normals) else np.concatenate([v for v in normals if v is not None])
    return PointCloud(xyz, probe, f"{bag.path}:{topic}", frame_id=frames.pop())
