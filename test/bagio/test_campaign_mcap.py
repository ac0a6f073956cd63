"""Campaign MCAP files and rosbag2 directories: roundtrip, interoperability, crashes, errors."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer

from robocal_uncertainty.bagio import CampaignRecorder, campaign_mcap, read_campaign, write_campaign
from robocal_uncertainty.bagio.ros_messages import (
    JOINT_STATE,
    POINT_STAMPED,
    VECTOR3_STAMPED,
    encode_joint_state,
    encode_point_stamped,
    encode_vector3_stamped,
    message_schema,
    ros_typestore,
)
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.errors import BagError, CampaignError, InputError

NAMES = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint")
T0 = 1_700_000_000_123_456_789


def _campaign(n: int = 7, *, stamps: bool = True, std: bool = True) -> Campaign:
    rng = np.random.default_rng(42)
    return Campaign(
        joint_names=NAMES,
        joint_positions=rng.uniform(-np.pi, np.pi, size=(n, 3)),
        points=rng.normal(scale=1.5, size=(n, 3)),
        frame="tracker",
        frame_id="laser_tracker",
        point_std=rng.uniform(1e-6, 1e-4, size=(n, 3)) if std else None,
        stamps_ns=T0 + np.arange(n, dtype=np.int64) * 2_500_000_017 if stamps else None,
        metadata={"source": "simulated", "seed": 42, "nested": {"a": [1, 2.5, None]}, "ü": "µm"},
    )


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _write_foreign(
    path: Path,
    messages: list[tuple[str, str, int, bytes]],
    *,
    message_encoding: str = "cdr",
) -> None:
    """Write an MCAP file like ``ros2 bag record`` (no campaign metadata record)."""
    with path.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="test")
        channels: dict[str, int] = {}
        for topic, typename, stamp, data in messages:
            if topic not in channels:
                schema = message_schema(typename)
                schema_id = writer.register_schema(typename, "ros2msg", schema.text.encode())
                channels[topic] = writer.register_channel(topic, message_encoding, schema_id)
            writer.add_message(channels[topic], stamp, data, stamp)
        writer.finish()


def _pose_messages(
    n: int, *, frame_id: str = "world", names: tuple[str, ...] = NAMES
) -> list[tuple[str, str, int, bytes]]:
    out = []
    for i in range(n):
        stamp = T0 + i * 1_000_000
        q = np.array([0.1 * i, -0.2, 0.3 + i], dtype=np.float64)
        out.append(("/joint_states", JOINT_STATE, stamp, encode_joint_state(stamp, names, q)))
        xyz = np.array([1.0 + i, 2.0, 3.0])
        out.append(("/tracker/point", POINT_STAMPED, stamp, encode_point_stamped(stamp, frame_id, xyz)))
    return out


# --------------------------------------------------------------------------- roundtrip


def test_roundtrip_is_bit_exact(tmp_path: Path) -> None:
    campaign = _campaign()
    path = tmp_path / "campaign.mcap"
    write_campaign(path, campaign)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = read_campaign(path)
    assert back.joint_names == campaign.joint_names
    assert _same_bits(back.joint_positions, campaign.joint_positions)
    assert _same_bits(back.points, campaign.points)
    assert back.point_std is not None
    assert campaign.point_std is not None
    assert _same_bits(back.point_std, campaign.point_std)
    assert back.stamps_ns is not None
    assert campaign.stamps_ns is not None
    assert _same_bits(back.stamps_ns, campaign.stamps_ns)
    assert (back.frame, back.frame_id) == ("tracker", "laser_tracker")
    assert back.metadata == campaign.metadata


def test_roundtrip_without_stamps_and_std(tmp_path: Path) -> None:
    campaign = _campaign(stamps=False, std=False)
    path = tmp_path / "campaign.mcap"
    write_campaign(path, campaign)
    back = read_campaign(path)
    assert back.stamps_ns is None
    assert back.point_std is None
    assert _same_bits(back.points, campaign.points)
    assert _same_bits(back.joint_positions, campaign.joint_positions)


def test_roundtrip_keeps_pose_order_of_unsorted_stamps(tmp_path: Path) -> None:
    campaign = _campaign(5)
    assert campaign.stamps_ns is not None
    shuffled = Campaign(
        joint_names=campaign.joint_names,
        joint_positions=campaign.joint_positions,
        points=campaign.points,
        frame="base",
        frame_id="base_link",
        stamps_ns=campaign.stamps_ns[[3, 0, 4, 1, 2]],
    )
    path = tmp_path / "campaign.mcap"
    write_campaign(path, shuffled)
    back = read_campaign(path)
    assert back.stamps_ns is not None
    assert back.stamps_ns.tolist() == shuffled.stamps_ns.tolist()  # type: ignore[union-attr]
    assert _same_bits(back.points, shuffled.points)
    assert back.frame == "base"


def test_write_refuses_to_overwrite_unless_asked(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    write_campaign(path, _campaign(3))
    with pytest.raises(CampaignError, match="exists already"):
        write_campaign(path, _campaign(4))
    write_campaign(path, _campaign(4), overwrite=True)
    assert read_campaign(path).n_poses == 4


# ------------------------------------------------------------------ interoperability


def test_plain_mcap_reader_sees_ros2_topics_schemas_and_metadata(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    write_campaign(path, _campaign(4))
    with path.open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {JOINT_STATE, POINT_STAMPED, VECTOR3_STAMPED}
        for name, schema in schemas.items():
            assert schema.encoding == "ros2msg"
            assert schema.data.decode() == message_schema(name).text
        assert b"float64[] position" in schemas[JOINT_STATE].data
        assert b"MSG: builtin_interfaces/Time" in schemas[POINT_STAMPED].data
        topics = {c.topic: (schemas_by_id := summary.schemas)[c.schema_id].name for c in summary.channels.values()}
        assert schemas_by_id
        assert topics == {
            "/joint_states": JOINT_STATE,
            "/tracker/point": POINT_STAMPED,
            "/tracker/point_std": VECTOR3_STAMPED,
        }
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert summary.statistics is not None
        assert summary.statistics.message_count == 12
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    content = json.loads(records["robocal_campaign"]["campaign"])
    assert content["format_version"] == 1
    assert content["units"] == {
        "joint_positions": "rad",
        "points": "m",
        "point_std": "m",
        "stamps": "ns",
    }
    assert (content["frame"], content["frame_id"]) == ("tracker", "laser_tracker")


def test_rosbags_reads_the_file_with_its_embedded_definitions(tmp_path: Path) -> None:
    campaign = _campaign(3)
    path = tmp_path / "campaign.mcap"
    write_campaign(path, campaign)
    with AnyReader([path]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/joint_states"] == JOINT_STATE
        joint_messages = [
            reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/joint_states"
        ]
    assert [list(m.name) for m in joint_messages] == [list(NAMES)] * 3  # type: ignore[attr-defined]
    assert np.array_equal(joint_messages[1].position, campaign.joint_positions[1])  # type: ignore[attr-defined]


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_rosbag2_directory_is_read(tmp_path: Path, storage: StoragePlugin) -> None:
    store = ros_typestore()
    bag = tmp_path / "bag"
    order = (NAMES[2], NAMES[0], NAMES[1])
    with Rosbag2Writer(bag, version=9, storage_plugin=storage) as writer:
        joints = writer.add_connection("/joint_states", JOINT_STATE, typestore=store)
        points = writer.add_connection("/tracker/point", POINT_STAMPED, typestore=store)
        for i in range(20):  # joint states at 100 Hz, names in changing order
            stamp = T0 + i * 10_000_000
            names = NAMES if i % 2 else order
            q = np.array([{n: 0.01 * i + k for k, n in enumerate(NAMES)}[n] for n in names])
            writer.write(joints, stamp, encode_joint_state(stamp, names, q))
        for i in (3, 8, 15):  # three tracker points, stamped like a joint state
            stamp = T0 + i * 10_000_000
            writer.write(points, stamp, encode_point_stamped(stamp, "base_link", np.array([i, 0.5, 1.0])))
    campaign = read_campaign(bag)
    assert campaign.joint_names == order  # order of the first JointState message
    campaign = campaign.reorder_joints(NAMES)
    assert campaign.n_poses == 3
    expected = np.array([[0.01 * i + k for k in range(3)] for i in (3, 8, 15)])
    assert np.array_equal(campaign.joint_positions, expected)
    assert campaign.points[:, 0].tolist() == [3.0, 8.0, 15.0]
    assert (campaign.frame, campaign.frame_id) == ("base", "base_link")
    assert campaign.metadata["source_format"] == "rosbag2"
    assert campaign.stamps_ns is not None
    assert campaign.stamps_ns.tolist() == [T0 + i * 10_000_000 for i in (3, 8, 15)]


def test_foreign_mcap_frame_from_frame_id_and_tolerance_pairing(tmp_path: Path) -> None:
    messages = _pose_messages(4, frame_id="world")
    shifted = [
        (t, ty, s + 300_000, encode_point_stamped(s + 300_000, "world", np.array([1.0, 2.0, 3.0])))
        if t == "/tracker/point"
        else (t, ty, s, d)
        for t, ty, s, d in messages
    ]
    path = tmp_path / "recorded.mcap"
    _write_foreign(path, messages)
    assert read_campaign(path).frame == "tracker"
    assert read_campaign(path, base_frame_id="world").frame == "base"
    late = tmp_path / "late.mcap"
    _write_foreign(late, shifted)
    with pytest.raises(BagError, match="no pose found"):
        read_campaign(late)
    campaign = read_campaign(late, stamp_tolerance_ns=400_000)
    assert campaign.n_poses == 4
    assert campaign.joint_positions[:, 2].tolist() == [0.3, 1.3, 2.3, 3.3]


# ------------------------------------------------------------------------ crashes


def test_file_of_killed_recorder_is_recovered(tmp_path: Path) -> None:
    campaign = _campaign(5)
    path = tmp_path / "live.mcap"
    crashed = tmp_path / "crashed.mcap"
    recorder = CampaignRecorder(path, joint_names=NAMES, frame="tracker", frame_id="laser_tracker", metadata={"run": 1})
    assert campaign.stamps_ns is not None
    assert campaign.point_std is not None
    for i in range(5):
        recorder.append(
            int(campaign.stamps_ns[i]),
            campaign.joint_positions[i],
            campaign.points[i],
            campaign.point_std[i],
        )
    shutil.copyfile(path, crashed)  # what is on disk when the process dies now
    recorder.close()
    with pytest.warns(UserWarning, match="truncated") as caught:
        back = read_campaign(crashed)
    assert back.n_poses == 5
    assert _same_bits(back.points, campaign.points)
    assert back.point_std is not None
    assert _same_bits(back.point_std, campaign.point_std)
    # The recovery is also recorded in the campaign, as the same one-line message.
    note = (
        f"{crashed} is truncated (writer stopped before the footer); recovered 5 poses up to the last complete record"
    )
    assert back.metadata == {"run": 1, "warnings": [note]}
    assert [str(w.message) for w in caught] == [note]
    assert back.subset([0, 1]).metadata["warnings"] == [note]
    assert back.reorder_joints(NAMES[::-1]).metadata["warnings"] == [note]


def test_read_warnings_describe_the_file_read_not_an_earlier_one(tmp_path: Path) -> None:
    campaign = _campaign(4)
    path = tmp_path / "campaign.mcap"
    write_campaign(path, campaign)
    chopped = tmp_path / "chopped.mcap"
    chopped.write_bytes(path.read_bytes()[:-300])
    with pytest.warns(UserWarning, match="is truncated"):
        recovered = read_campaign(chopped)
    assert "is truncated" in recovered.metadata["warnings"][0]
    # Written back, the recovered campaign is a complete file: read without warnings.
    rewritten = tmp_path / "rewritten.mcap"
    write_campaign(rewritten, recovered)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = read_campaign(rewritten)
    assert "warnings" not in again.metadata
    assert again.metadata == campaign.metadata
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert "warnings" not in read_campaign(path).metadata


def test_dropped_points_are_recorded_in_the_metadata(tmp_path: Path) -> None:
    path = tmp_path / "unpaired.mcap"
    messages = _pose_messages(3)
    point = _pose_messages(4)[7]
    late = T0 + 3_000_005
    _write_foreign(path, [*messages, (point[0], point[1], late, encode_point_stamped(late, "world", np.ones(3)))])
    with pytest.warns(UserWarning, match="were dropped"):
        campaign = read_campaign(path)
    assert campaign.n_poses == 3
    assert campaign.metadata["points_dropped"] == 1
    assert campaign.metadata["warnings"] == [
        f"{path}: 1 of 4 points on /tracker/point have no /joint_states message within the pairing tolerance "
        "of 0 ms and were dropped (pose 4 of 4: the /joint_states message nearest to its /tracker/point stamp "
        "is 1 ms away)"
    ]


@pytest.mark.parametrize(
    "chunked",
    [
        pytest.param(
            True,
            marks=pytest.mark.skipif(not hasattr(Writer, "flush"), reason="mcap lacks flush"),
        ),
        False,
    ],
)
def test_chopped_file_reads_up_to_last_complete_pose(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, chunked: bool
) -> None:
    monkeypatch.setattr(campaign_mcap, "_CHUNKED", chunked)
    campaign = _campaign(6)
    path = tmp_path / "campaign.mcap"
    write_campaign(path, campaign)
    data = path.read_bytes()
    assert campaign.point_std is not None
    seen, failures = set(), []
    chopped = tmp_path / "chopped.mcap"
    for cut in range(1, len(data) - 200, 37):
        chopped.write_bytes(data[:-cut])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                back = read_campaign(chopped)
            except BagError as err:
                failures.append(str(err))
                continue
        assert any("is truncated" in str(w.message) for w in caught)
        n = back.n_poses
        seen.add(n)
        assert _same_bits(back.points, campaign.points[:n])
        assert _same_bits(back.joint_positions, campaign.joint_positions[:n])
        assert back.point_std is not None
        assert _same_bits(back.point_std, campaign.point_std[:n])
    assert {1, 5, 6} <= seen
    assert all("truncated before its first complete pose" in f for f in failures)


def _record_one_pose_then_fail(path: Path) -> None:
    with CampaignRecorder(path, joint_names=NAMES, frame="base", frame_id="base_link") as rec:
        rec.append(T0, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0])
        raise RuntimeError("robot stopped")


def test_recorder_finishes_file_when_block_raises(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    with pytest.raises(RuntimeError, match="robot stopped"):
        _record_one_pose_then_fail(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_campaign(path).n_poses == 1


# ------------------------------------------------------------------------- errors


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CampaignError, match="campaign file not found"):
        read_campaign(tmp_path / "nope.mcap")


def test_not_an_mcap_file(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    path.write_text("joint1,x\n1,2\n")
    with pytest.raises(CampaignError, match="not a campaign"):
        read_campaign(path)


def test_directory_without_rosbag2_metadata(tmp_path: Path) -> None:
    with pytest.raises(CampaignError, match="not a campaign"):
        read_campaign(tmp_path)


def test_missing_topic(tmp_path: Path) -> None:
    path = tmp_path / "joints_only.mcap"
    _write_foreign(path, [m for m in _pose_messages(2) if m[0] == "/joint_states"])
    with pytest.raises(BagError, match="topic /tracker/point not found"):
        read_campaign(path)


def test_wrong_message_type(tmp_path: Path) -> None:
    path = tmp_path / "wrong_type.mcap"
    vector = encode_vector3_stamped(T0, "world", np.ones(3))
    messages = [m for m in _pose_messages(1) if m[0] == "/joint_states"]
    _write_foreign(path, [*messages, ("/tracker/point", VECTOR3_STAMPED, T0, vector)])
    with pytest.raises(BagError, match="has type 'geometry_msgs/msg/Vector3Stamped'"):
        read_campaign(path)


def test_wrong_message_encoding(tmp_path: Path) -> None:
    path = tmp_path / "json.mcap"
    _write_foreign(path, _pose_messages(1), message_encoding="json")
    with pytest.raises(BagError, match="encoding 'json', expected 'cdr'"):
        read_campaign(path)


def test_undecodable_message(tmp_path: Path) -> None:
    path = tmp_path / "garbage.mcap"
    messages = _pose_messages(1)
    _write_foreign(path, [messages[0], ("/tracker/point", POINT_STAMPED, T0, b"\x00\x01")])
    with pytest.raises(BagError, match="cannot decode geometry_msgs/msg/PointStamped"):
        read_campaign(path)


def test_nan_in_point(tmp_path: Path) -> None:
    path = tmp_path / "nan.mcap"
    nan = encode_point_stamped(T0, "world", np.array([1.0, np.nan, 0.0]))
    _write_foreign(path, [_pose_messages(1)[0], ("/tracker/point", POINT_STAMPED, T0, nan)])
    with pytest.raises(BagError, match="NaN or inf in /tracker/point message at stamp"):
        read_campaign(path)


def test_nan_in_joint_state(tmp_path: Path) -> None:
    path = tmp_path / "nan.mcap"
    nan = encode_joint_state(T0, NAMES, np.array([0.0, np.nan, 0.0]))
    _write_foreign(path, [("/joint_states", JOINT_STATE, T0, nan), _pose_messages(1)[1]])
    with pytest.raises(BagError, match="NaN or inf in /joint_states"):
        read_campaign(path)


def test_differing_joint_names(tmp_path: Path) -> None:
    path = tmp_path / "names.mcap"
    messages = _pose_messages(1) + _pose_messages(2, names=("a", "b", "c"))[2:]
    _write_foreign(path, messages)
    with pytest.raises(BagError, match="differing joint names"):
        read_campaign(path)


def test_no_pairs(tmp_path: Path) -> None:
    path = tmp_path / "unpaired.mcap"
    joint, point = _pose_messages(1)
    late = T0 + 5
    _write_foreign(
        path,
        [joint, (point[0], point[1], late, encode_point_stamped(late, "world", np.ones(3)))],
    )
    with pytest.raises(BagError, match="no pose found"):
        read_campaign(path)


def test_repeated_stamps(tmp_path: Path) -> None:
    path = tmp_path / "repeat.mcap"
    messages = _pose_messages(1)
    _write_foreign(path, [messages[0], *messages])
    with pytest.raises(BagError, match="share the stamp"):
        read_campaign(path)


def test_empty_frame_id(tmp_path: Path) -> None:
    path = tmp_path / "noframe.mcap"
    _write_foreign(path, _pose_messages(2, frame_id=""))
    with pytest.raises(BagError, match="frame_id is empty"):
        read_campaign(path)


def test_truncated_before_first_pose(tmp_path: Path) -> None:
    path = tmp_path / "early.mcap"
    recorder = CampaignRecorder(path, joint_names=NAMES, frame="base", frame_id="base_link")
    crashed = tmp_path / "crashed.mcap"
    shutil.copyfile(path, crashed)
    recorder.close()
    with pytest.raises(BagError, match="truncated before its first complete pose"):
        read_campaign(crashed)


def test_unsupported_format_version(tmp_path: Path) -> None:
    path = tmp_path / "future.mcap"
    record = {"format_version": "2", "campaign": json.dumps({"format_version": 2})}
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2")
        writer.add_metadata("robocal_campaign", record)
        writer.finish()
    with pytest.raises(BagError, match="format version 2 is not supported"):
        read_campaign(path)


def test_recorder_rejects_bad_poses(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    with CampaignRecorder(path, joint_names=NAMES, frame="base", frame_id="base_link") as rec:
        rec.append(T0, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [1e-5, 1e-5, 1e-5])
        with pytest.raises(InputError, match="joint_positions must have shape"):
            rec.append(T0 + 1, [0.0, 0.1], [1.0, 2.0, 3.0], [1e-5] * 3)
        with pytest.raises(InputError, match="point contains NaN"):
            rec.append(T0 + 1, [0.0, 0.1, 0.2], [1.0, np.nan, 3.0], [1e-5] * 3)
        with pytest.raises(InputError, match="already appended"):
            rec.append(T0, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [1e-5] * 3)
        with pytest.raises(InputError, match="every pose or for none"):
            rec.append(T0 + 1, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0])
        with pytest.raises(InputError, match="non-negative"):
            rec.append(T0 + 1, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [-1e-5, 0.0, 0.0])
        with pytest.raises(InputError, match="outside the ROS time range"):
            rec.append(-1, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [1e-5] * 3)
        with pytest.raises(InputError, match="integer number of ns"):
            rec.append(1.5, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [1e-5] * 3)  # type: ignore[arg-type]
    with pytest.raises(CampaignError, match="is closed"):
        rec.append(T0 + 2, [0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [1e-5] * 3)
    assert read_campaign(path).n_poses == 1


def test_recorder_rejects_bad_setup(tmp_path: Path) -> None:
    path = tmp_path / "campaign.mcap"
    with pytest.raises(InputError, match="joint_names must be unique"):
        CampaignRecorder(path, joint_names=("a", "a"), frame="base", frame_id="base_link")
    with pytest.raises(InputError, match="frame must be"):
        CampaignRecorder(path, joint_names=NAMES, frame="world", frame_id="w")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="cannot be stored as JSON"):
        CampaignRecorder(path, joint_names=NAMES, frame="base", frame_id="b", metadata={"f": open})
    assert not path.exists()


def test_write_rejects_repeated_stamps(tmp_path: Path) -> None:
    campaign = _campaign(3)
    assert campaign.stamps_ns is not None
    repeated = Campaign(
        joint_names=campaign.joint_names,
        joint_positions=campaign.joint_positions,
        points=campaign.points,
        stamps_ns=np.array([T0, T0, T0 + 1]),
    )
    with pytest.raises(InputError, match="must be unique"):
        write_campaign(tmp_path / "campaign.mcap", repeated)
    assert not (tmp_path / "campaign.mcap").exists()
