"""The CalibrationSample message carries a 6-DOF sample's mean orientation and its covariance:
exact CDR round trips for 6-DOF and point samples, the fields at their CDR offsets, and bad
orientations in a received message refused in one line."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from robocal_uncertainty.bagio.messages import (
    CALIBRATION_SAMPLE,
    decode_message,
    encode_message,
    msg_to_sample,
    sample_to_msg,
)
from robocal_uncertainty.core.rotation import quaternion_from_matrix, rotation_exp
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import InputError


def _sample(*, six_dof: bool) -> CalibrationSample:
    rng = np.random.default_rng(11)
    a, b = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    return CalibrationSample(
        stamp_ns=1_700_000_123_456_789_012,
        frame_id="laser_tracker",
        joint_names=("joint1", "joint2", "joint3"),
        joint_positions=rng.uniform(-3, 3, 3),
        joint_position_std=rng.uniform(0, 1e-4, 3),
        point=rng.normal(size=3),
        point_covariance=a @ a.T * 1e-12,
        joint_state_count=250,
        tracker_point_count=1000,
        orientation=quaternion_from_matrix(rotation_exp(rng.normal(size=3))) if six_dof else None,
        orientation_covariance=b @ b.T * 1e-10 if six_dof else None,
    )


def _through_cdr(sample: CalibrationSample) -> tuple[bytes, CalibrationSample]:
    data = encode_message(sample_to_msg(sample), CALIBRATION_SAMPLE)
    return data, msg_to_sample(decode_message(data, CALIBRATION_SAMPLE))


def test_6dof_sample_round_trips_bit_for_bit() -> None:
    sample = _sample(six_dof=True)
    data, back = _through_cdr(sample)
    assert back == sample
    assert back.orientation is not None and back.orientation_covariance is not None
    assert sample.orientation is not None and sample.orientation_covariance is not None
    assert back.orientation.tobytes() == sample.orientation.tobytes()
    assert back.orientation_covariance.tobytes() == sample.orientation_covariance.tobytes()
    assert back.orientation_covariance.shape == (3, 3)
    # The wire layout, read without rosbags: the message ends with the quaternion (4 float64,
    # 8-aligned after the bool) and the 3x3 covariance, little-endian CDR.
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    body = data[4:]
    assert struct.unpack("<9d", body[-72:]) == tuple(sample.orientation_covariance.reshape(-1))
    assert struct.unpack("<4d", body[-104:-72]) == tuple(sample.orientation)
    assert _flag(body) == 1


def _flag(body: bytes) -> int:
    """The has_orientation byte: after tracker_point_count (uint32 1000), padded with zeros to
    the 8-aligned quaternion (3 or 7 bytes, depending on where the uint32 ended)."""
    prefix = body[:-104]
    flags = [
        prefix[-(pad + 1)]
        for pad in (3, 7)
        if prefix[-(pad + 5) : -(pad + 1)] == struct.pack("<I", 1000) and prefix[-pad:] == bytes(pad)
    ]
    assert len(flags) == 1, prefix[-12:]
    return flags[0]


def test_6dof_message_fields() -> None:
    sample = _sample(six_dof=True)
    message = sample_to_msg(sample)
    assert message.has_orientation is True
    o = message.orientation
    assert sample.orientation is not None
    assert [o.x, o.y, o.z, o.w] == sample.orientation.tolist()
    assert sample.orientation_covariance is not None
    assert message.orientation_covariance.tolist() == sample.orientation_covariance.reshape(-1).tolist()


def test_point_sample_round_trips_without_orientation() -> None:
    sample = _sample(six_dof=False)
    message = sample_to_msg(sample)
    assert message.has_orientation is False
    o = message.orientation
    assert [o.x, o.y, o.z, o.w] == [0.0, 0.0, 0.0, 1.0]
    assert message.orientation_covariance.tolist() == [0.0] * 9
    data, back = _through_cdr(sample)
    assert back == sample
    assert back.orientation is None and back.orientation_covariance is None
    # The only difference on the wire to the 6-DOF sample's tail: the flag, identity, zeros.
    assert struct.unpack("<4d", data[4:][-104:-72]) == (0.0, 0.0, 0.0, 1.0)
    assert struct.unpack("<9d", data[4:][-72:]) == (0.0,) * 9
    assert _flag(data[4:]) == 0


def _received(**changes: object) -> object:
    message = sample_to_msg(_sample(six_dof=True))
    for name, value in changes.items():
        setattr(message, name, value)
    return decode_message(encode_message(message, CALIBRATION_SAMPLE), CALIBRATION_SAMPLE)


def test_point_message_ignores_its_orientation_fields() -> None:
    """With has_orientation false the orientation fields are not read (even if garbage)."""
    message = _received(has_orientation=False)
    message.orientation.w = float("nan")  # type: ignore[attr-defined]
    back = msg_to_sample(message)
    assert back.orientation is None and back.orientation_covariance is None


@pytest.mark.parametrize(
    ("quaternion", "match"),
    [
        ((0.0, 0.0, 0.0, 1.01), "not a unit quaternion: norm 1.01"),
        ((np.nan, 0.0, 0.0, 1.0), "orientation contains NaN"),
    ],
)
def test_bad_orientation_in_a_message_is_a_one_line_input_error(quaternion: tuple[float, ...], match: str) -> None:
    message = _received()
    o = message.orientation  # type: ignore[attr-defined]
    o.x, o.y, o.z, o.w = quaternion
    with pytest.raises(InputError, match=match) as caught:
        msg_to_sample(message)
    assert "\n" not in str(caught.value)


def test_negative_orientation_variance_in_a_message_is_refused() -> None:
    message = _received()
    message.orientation_covariance = -np.eye(3).reshape(-1) * 1e-9  # type: ignore[attr-defined]
    with pytest.raises(InputError, match="orientation_covariance has a negative variance"):
        msg_to_sample(message)
