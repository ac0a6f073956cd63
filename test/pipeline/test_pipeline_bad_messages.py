"""Bad messages in a raw bag are counted per cause, logged (throttled) and dropped; the
collector keeps finding every other pose, with exactly the samples of the clean bag."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pipeline_data import BASE_BAG, COLLECTOR

from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagTruth, RawRecord, write_raw_records
from robocal_uncertainty.bagio.ros_messages import (
    JOINT_STATE,
    POINT_STAMPED,
    encode_joint_state,
    encode_point_stamped,
    ros_typestore,
)
from robocal_uncertainty.core import RobotModel
from robocal_uncertainty.pipeline import ReplayResult, replay_bag

NAMES = ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")


def _stamp(data: bytes, typename: str) -> int:
    header = ros_typestore().deserialize_cdr(data, typename).header
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _inject(path: Path, truth: RawBagTruth) -> Counter[str]:
    """Copy the base bag with bad messages slipped in during dwells and moves."""
    messages = read_mcap_file(BASE_BAG).messages
    records = [RawRecord(m.channel.topic, m.channel.schema_name, m.log_time_ns, m.data) for m in messages]
    joints = [r for r in records if r.typename == JOINT_STATE]
    points = [r for r in records if r.typename == POINT_STAMPED]
    q = np.zeros(6)
    xyz = np.array([0.5, 0.1, 0.3])
    bad: list[tuple[str, RawRecord, str, bytes]] = []
    # Every 50th joint state and every 100th point get a bad follower 1 ns after them
    # (in log time and stamp), so it arrives between valid messages, moving or static.
    for i, after in enumerate(joints[10::50]):
        s = _stamp(after.data, JOINT_STATE) + 1
        kind = i % 5
        if kind == 0:
            bad.append(("nan", after, JOINT_STATE, encode_joint_state(s, NAMES, np.r_[q[:5], np.nan])))
        elif kind == 1:
            names = (*NAMES[:5], "gripper_joint")
            bad.append(("unknown_joint", after, JOINT_STATE, encode_joint_state(s, names, q)))
        elif kind == 2:
            bad.append(("missing_joint", after, JOINT_STATE, encode_joint_state(s, NAMES[:5], q[:5])))
        elif kind == 3:
            bad.append(("backwards_time", after, JOINT_STATE, encode_joint_state(s - 20_000_000, NAMES, q)))
        else:
            bad.append(("undecodable", after, JOINT_STATE, after.data[:9]))
    for i, after in enumerate(points[25::100]):
        s = _stamp(after.data, POINT_STAMPED) + 1
        kind = i % 3
        if kind == 0:
            bad.append(("wrong_frame", after, POINT_STAMPED, encode_point_stamped(s, "camera_link", xyz)))
        elif kind == 1:
            bad.append(("nan", after, POINT_STAMPED, encode_point_stamped(s, truth.frame_id, np.r_[np.inf, 0, 0])))
        else:
            bad.append(
                ("backwards_time", after, POINT_STAMPED, encode_point_stamped(s - 10_000_000, truth.frame_id, xyz))
            )
    for _, after, typename, data in bad:
        records.append(RawRecord(after.topic, typename, after.log_time_ns + 1, data))
    records.sort(key=lambda r: r.log_time_ns)
    write_raw_records(path, records)
    return Counter(cause for cause, *_ in bad)


@pytest.fixture(scope="module")
def clean(paper_arm: RobotModel) -> ReplayResult:
    return replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False)


def test_bad_messages_are_counted_per_cause_and_dropped(
    tmp_path: Path, paper_arm: RobotModel, base_truth: RawBagTruth, clean: ReplayResult
) -> None:
    path = tmp_path / "dirty.mcap"
    injected = _inject(path, base_truth)
    assert set(injected) == {"nan", "unknown_joint", "missing_joint", "backwards_time", "undecodable", "wrong_frame"}
    logged: list[tuple[str, str]] = []
    result = replay_bag(path, paper_arm, collector=COLLECTOR, calibrate=False, log=lambda c, m: logged.append((c, m)))
    expected = dict.fromkeys(result.dropped, 0) | dict(injected)
    assert result.dropped == expected
    # Every pose is still found, with bit-identical samples: dropped messages leave no trace.
    assert len(result.samples) == len(clean.samples) == len(base_truth.windows)
    for dirty_sample, clean_sample in zip(result.samples, clean.samples):
        assert dirty_sample.stamp_ns == clean_sample.stamp_ns
        assert dirty_sample.joint_positions.tobytes() == clean_sample.joint_positions.tobytes()
        assert dirty_sample.point.tobytes() == clean_sample.point.tobytes()
    # Logged at most once per cause per 5 s of message time (the bag lasts ~14 s).
    per_cause = Counter(cause for cause, _ in logged)
    assert set(per_cause) == set(injected) - {"undecodable"}
    assert all(1 <= n <= 3 for n in per_cause.values())
    assert all("\n" not in message and message.startswith("dropped: ") for _, message in logged)


def test_a_point_frame_can_be_forced(paper_arm: RobotModel, base_truth: RawBagTruth) -> None:
    result = replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False, tracker_frame_id="laser_tracker")
    assert result.samples == ()
    assert result.dropped["wrong_frame"] == base_truth.point_count
