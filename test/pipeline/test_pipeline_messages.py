"""The package's three ROS 2 messages: definitions, converters, and a roundtrip through an
MCAP file read back with rosbags."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer
from pipeline_data import REPO, SEED, TEST_JOINTS
from rosbags.highlevel import AnyReader

from robocal_uncertainty.bagio.messages import (
    CALIBRATION_RESULT,
    CALIBRATION_SAMPLE,
    MESSAGE_NAMES,
    POSE_UNCERTAINTY,
    calibration_to_msg,
    decode_message,
    encode_message,
    message_definition,
    msg_to_sample,
    robocal_typestore,
    sample_to_msg,
    uncertainty_to_msgs,
)
from robocal_uncertainty.bagio.ros_messages import message_schema
from robocal_uncertainty.core import RobotModel, SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import BagError, InputError
from robocal_uncertainty.pipeline import CalibrationSample
from robocal_uncertainty.uncertainty import CalibrationUncertainty, UncertaintySettings, evaluate_uncertainty

FIELD = re.compile(r"^(?P<type>[A-Za-z0-9_/]+(\[\d*\])?)\s+(?P<name>[a-z][a-z0-9_]*)$")


@pytest.fixture(scope="module")
def uncertainty(paper_arm: RobotModel) -> CalibrationUncertainty:
    sim = simulate_campaign(paper_arm, SimulationSettings(n_poses=20), seed=3)
    settings = UncertaintySettings(sources=("tracker", "encoder", "lambda"))
    return evaluate_uncertainty(paper_arm, sim.campaign, TEST_JOINTS, uncertainty=settings, trials=200, seed=SEED)


def _sample() -> CalibrationSample:
    rng = np.random.default_rng(5)
    a = rng.normal(size=(3, 3))
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
    )


@pytest.mark.parametrize("typename", MESSAGE_NAMES)
def test_every_field_is_documented_with_a_unit(typename: str) -> None:
    lines = message_definition(typename).splitlines()
    fields = 0
    for k, line in enumerate(lines):
        if line.strip() and not line.startswith("#"):
            assert FIELD.match(line), line
            comment = []
            j = k - 1
            while j >= 0 and lines[j].startswith("#"):
                comment.insert(0, lines[j])
                j -= 1
            text = " ".join(comment)
            assert comment, f"{line} has no comment"
            assert re.search(r"\[[^\]]+\]|unitless|dimensionless|stamp", text), f"{line}: no unit in {text!r}"
            fields += 1
    assert fields >= 8


@pytest.mark.parametrize("typename", MESSAGE_NAMES)
def test_repository_msg_files_are_the_package_definitions(typename: str) -> None:
    path = REPO / "msg" / (typename.rsplit("/", 1)[-1] + ".msg")
    assert path.read_text(encoding="utf-8") == message_definition(typename)


def test_unknown_message_name_is_refused() -> None:
    with pytest.raises(InputError, match="unknown robocal_uncertainty message"):
        message_definition("robocal_uncertainty/msg/Nope")


def test_sample_roundtrip_through_cdr() -> None:
    sample = _sample()
    back = msg_to_sample(decode_message(encode_message(sample_to_msg(sample), CALIBRATION_SAMPLE), CALIBRATION_SAMPLE))
    assert back == sample
    assert _same_sample(back, sample)


def _same_sample(a: CalibrationSample, b: CalibrationSample) -> bool:
    return (
        a.stamp_ns == b.stamp_ns
        and a.frame_id == b.frame_id
        and a.joint_names == b.joint_names
        and all(
            getattr(a, f).tobytes() == getattr(b, f).tobytes()
            for f in ("joint_positions", "joint_position_std", "point", "point_covariance")
        )
        and (a.joint_state_count, a.tracker_point_count) == (b.joint_state_count, b.tracker_point_count)
    )


def test_calibration_message_fields(uncertainty: CalibrationUncertainty) -> None:
    calibration = uncertainty.calibration
    message = calibration_to_msg(calibration, stamp_ns=5_000_000_001)
    assert message.header.frame_id == "base_link"
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (5, 1)
    assert message.model_name == "paper_arm"
    assert message.parameter_names == list(calibration.parameter_names)
    np.testing.assert_array_equal(message.estimate, calibration.estimate)
    np.testing.assert_array_equal(message.standard_uncertainty, calibration.linearized_std)
    assert message.identifiable.tolist() == calibration.identifiable.tolist()
    assert message.lambda_method == calibration.lambda_method
    assert message.sample_count == 20
    with_mc = calibration_to_msg(calibration, stamp_ns=0, frame_id="world", uncertainty=uncertainty)
    assert with_mc.header.frame_id == "world"
    estimated = calibration.estimated
    assert np.isnan(with_mc.standard_uncertainty[~estimated]).all()
    expected = [p.standard_uncertainty for p in uncertainty.parameters]
    np.testing.assert_array_equal(with_mc.standard_uncertainty[estimated], expected)


def test_pose_uncertainty_message_fields(uncertainty: CalibrationUncertainty) -> None:
    messages = uncertainty_to_msgs(uncertainty, stamp_ns=7)
    assert len(messages) == 2
    pose = uncertainty.poses[1]
    message = messages[1]
    np.testing.assert_array_equal(message.joint_positions, TEST_JOINTS[1])
    assert [message.mean.x, message.mean.y, message.mean.z] == pose.mean.tolist()
    np.testing.assert_array_equal(message.covariance, pose.covariance.reshape(9))
    np.testing.assert_array_equal(message.expanded_uncertainty, [a.expanded_uncertainty for a in pose.axes])
    np.testing.assert_array_equal(message.shortest_high, [a.shortest.high for a in pose.axes])
    assert message.trials == 200 and message.adaptive_converged
    assert message.coverage_probability == 0.95
    assert message.sources == ["tracker", "encoder", "lambda"]


def _write_mcap(path: Path, messages: list[tuple[str, str, object]]) -> None:
    robocal_typestore()
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        channels: dict[str, int] = {}
        for k, (topic, typename, message) in enumerate(messages):
            if topic not in channels:
                schema = message_schema(typename)
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.text.encode())
                channels[topic] = writer.register_channel(topic, "cdr", schema_id)
            writer.add_message(channels[topic], k + 1, encode_message(message, typename), k + 1)
        writer.finish()


def test_three_message_types_roundtrip_through_an_mcap_file(
    tmp_path: Path, uncertainty: CalibrationUncertainty
) -> None:
    sample = _sample()
    written = [
        ("/calibration/sample", CALIBRATION_SAMPLE, sample_to_msg(sample)),
        ("/calibration/result", CALIBRATION_RESULT, calibration_to_msg(uncertainty.calibration, stamp_ns=9)),
        *(("/calibration/uncertainty", POSE_UNCERTAINTY, m) for m in uncertainty_to_msgs(uncertainty, stamp_ns=9)),
    ]
    path = tmp_path / "results.mcap"
    _write_mcap(path, written)
    # An independent reader: rosbags parses the schemas stored in the file itself.
    with AnyReader([path]) as reader:
        read = [
            (connection.topic, connection.msgtype, reader.deserialize(data, connection.msgtype))
            for connection, _, data in reader.messages()
        ]
    assert [(t, n) for t, n, _ in read] == [(t, n) for t, n, _ in written]
    for (_, _, a), (_, _, b) in zip(read, written):
        _assert_equal_messages(a, b)
    assert _same_sample(msg_to_sample(read[0][2]), sample)


def _assert_equal_messages(a: object, b: object) -> None:
    assert type(a).__name__ == type(b).__name__
    for name in b.__dataclass_fields__:  # type: ignore[attr-defined]
        x, y = getattr(a, name), getattr(b, name)
        if hasattr(y, "__dataclass_fields__"):
            _assert_equal_messages(x, y)
        elif isinstance(y, np.ndarray):
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
        else:
            assert x == y, name


def test_corrupt_payload_gives_bag_error() -> None:
    with pytest.raises(BagError, match="cannot decode"):
        decode_message(b"\x00\x01\x00\x00\x05", CALIBRATION_RESULT)
