"""PointCloud2 sections from MCAP bags: round trip, frames, normals, and one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio.point_cloud2 import (
    POINT_CLOUD2,
    encode_point_cloud2,
    read_point_cloud2,
    write_point_cloud2_mcap,
)
from robocal_uncertainty.bagio.ros_messages import ros_typestore
from robocal_uncertainty.errors import BagError, InputError


def _section(n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    points = np.column_stack([0.03 * np.cos(t), 0.01 * np.sin(t), np.full(n, 0.1)])
    normals = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
    return points, normals


@pytest.mark.parametrize("float64", [False, True])
def test_round_trip_with_normals(tmp_path: Path, float64: bool) -> None:
    points, normals = _section()
    bag = write_point_cloud2_mcap(
        tmp_path / "scan.mcap", [encode_point_cloud2(5, "part", points, normals, float64=float64)]
    )
    cloud = read_point_cloud2(bag)
    tol = 1e-15 if float64 else 1e-8
    assert cloud.points.shape == (50, 3)
    assert cloud.points == pytest.approx(points, abs=tol)
    assert cloud.probe_vectors is not None
    assert cloud.probe_vectors == pytest.approx(normals, abs=1e-6)
    assert cloud.frame_id == "part"
    assert cloud.source.endswith("scan.mcap:/section/points")


def test_scan_lines_are_joined_and_one_can_be_picked(tmp_path: Path) -> None:
    points, _ = _section(60)
    messages = [encode_point_cloud2(k, "part", points[k * 20 : (k + 1) * 20]) for k in range(3)]
    bag = write_point_cloud2_mcap(tmp_path / "lines.mcap", messages, topic="/scanner/points")
    whole = read_point_cloud2(bag, "/scanner/points")
    assert whole.points == pytest.approx(points, abs=1e-8)
    assert whole.probe_vectors is None
    second = read_point_cloud2(bag, message=1)
    assert second.points == pytest.approx(points[20:40], abs=1e-8)
    with pytest.raises(BagError, match=r"message index 3 is out of range for 3 messages"):
        read_point_cloud2(bag, message=3)


def test_non_dense_clouds_drop_invalid_points(tmp_path: Path) -> None:
    points, _ = _section(30)
    points[4] = np.nan
    bag = write_point_cloud2_mcap(tmp_path / "holes.mcap", [encode_point_cloud2(1, "part", points)])
    assert read_point_cloud2(bag).n_points == 29


def _raw_message(**changes: object) -> bytes:
    store = ros_typestore()
    points, _ = _section(10)
    message = store.deserialize_cdr(encode_point_cloud2(1, "part", points), POINT_CLOUD2)
    for key, value in changes.items():
        setattr(message, key, value)
    return bytes(store.serialize_cdr(message, POINT_CLOUD2))


def test_errors_are_one_line(tmp_path: Path) -> None:
    store = ros_typestore()
    field = store.types["sensor_msgs/msg/PointField"]
    wrong = [field(name="x", offset=0, datatype=7, count=1), field(name="y", offset=4, datatype=7, count=1)]
    cases = [
        (_raw_message(fields=wrong), BagError, r"has no field\(s\) \['z'\]"),
        (
            _raw_message(fields=[field(name=n, offset=4 * k, datatype=5, count=1) for k, n in enumerate("xyz")]),
            BagError,
            r"field 'x' must be one FLOAT32 or FLOAT64",
        ),
        (_raw_message(width=11), BagError, r"corrupt PointCloud2"),
        (b"\x00\x01\x00\x00\x01", BagError, r"cannot decode PointCloud2"),
    ]
    for k, (data, error, pattern) in enumerate(cases):
        bag = write_point_cloud2_mcap(tmp_path / f"bad{k}.mcap", [data])
        with pytest.raises(error, match=pattern) as info:
            read_point_cloud2(bag)
        assert "\n" not in str(info.value)
    with pytest.raises(BagError, match=r"not found"):
        read_point_cloud2(tmp_path / "missing.mcap")
    empty = np.zeros((1, 3))
    empty[0] = np.nan
    bag = write_point_cloud2_mcap(tmp_path / "nan.mcap", [encode_point_cloud2(1, "p", empty)])
    with pytest.raises(InputError, match=r"holds no valid point"):
        read_point_cloud2(bag)
    two = write_point_cloud2_mcap(
        tmp_path / "frames.mcap",
        [encode_point_cloud2(1, "a", _section(5)[0]), encode_point_cloud2(2, "b", _section(5)[0])],
    )
    with pytest.raises(BagError, match=r"different frames \['a', 'b'\]"):
        read_point_cloud2(two)
    with pytest.raises(BagError, match=r"topic /other not found"):
        read_point_cloud2(two, "/other")


@pytest.mark.parametrize("bigendian", [False, True])
def test_a_scanner_layout_is_decoded_independently_of_the_encoder(tmp_path: Path, bigendian: bool) -> None:
    # Bytes packed by hand (not by encode_point_cloud2): an organised 2x3 cloud with an
    # intensity field, 4 bytes of point padding, 8 bytes of row padding, z stored as FLOAT64
    # before x and y, normals absent.
    store = ros_typestore()
    field = store.types["sensor_msgs/msg/PointField"]
    fields = [
        field(name="z", offset=0, datatype=8, count=1),
        field(name="x", offset=8, datatype=7, count=1),
        field(name="y", offset=12, datatype=7, count=1),
        field(name="intensity", offset=16, datatype=7, count=1),
    ]
    order = ">" if bigendian else "<"
    expected = np.array(
        [[0.5, -1.25, 2.0], [0.25, 3.0, -0.5], [1.0, 0.125, 4.0], [-2.0, 0.75, 1.5], [0.0, 1.0, 0.5], [6.5, -3.0, 0.25]]
    )
    point_step, row_step = 24, 3 * 24 + 8
    data = bytearray(row_step * 2)
    for k, (x, y, z) in enumerate(expected):
        start = (k // 3) * row_step + (k % 3) * point_step
        data[start : start + 20] = np.array([z], order + "f8").tobytes() + np.array([x, y, 7.0], order + "f4").tobytes()
    message = store.deserialize_cdr(encode_point_cloud2(1, "part", np.zeros((1, 3))), POINT_CLOUD2)
    message.height, message.width, message.fields = 2, 3, fields
    message.is_bigendian, message.point_step, message.row_step = bigendian, point_step, row_step
    message.data = np.frombuffer(bytes(data), dtype=np.uint8)
    bag = write_point_cloud2_mcap(tmp_path / "scanner.mcap", [bytes(store.serialize_cdr(message, POINT_CLOUD2))])
    cloud = read_point_cloud2(bag)
    assert cloud.probe_vectors is None
    assert np.array_equal(cloud.points, expected)
