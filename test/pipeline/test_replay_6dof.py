"""A 6-DOF raw recording (joint states + ``geometry_msgs/PoseStamped`` tracker poses): the offline
replay finds every pose with its orientation, and equals, bit for bit, the same messages sent
through the node path (collector -> CalibrationSample CDR -> calibration and uncertainty
logic), samples, calibration and uncertainty (orientation included)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pipeline_data import COLLECTOR, SEED, TEST_JOINTS

from robocal_uncertainty.app import ReplayEvaluation, evaluate, replay
from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.bagio.campaign_format import POSE_TOPIC
from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
from robocal_uncertainty.bagio.messages import (
    CALIBRATION_SAMPLE,
    decode_message,
    encode_message,
    msg_to_sample,
    sample_to_msg,
)
from robocal_uncertainty.bagio.pose_messages import POSE_STAMPED, decode_pose_stamped, encode_pose_stamped
from robocal_uncertainty.bagio.raw_bag_simulator import (
    RAW_TRUTH_METADATA,
    RawBagSettings,
    RawBagTruth,
    RawRecord,
    read_raw_truth,
    simulate_raw_recording,
    write_raw_bag,
    write_raw_records,
)
from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, decode_joint_state, ros_typestore, stamp_parts
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import RobotModel, SimulationSettings, simulate_campaign
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, split_pose_values
from robocal_uncertainty.core.rotation import quaternion_to_matrix, rotation_log
from robocal_uncertainty.core.simulation import SimulatedCampaign
from robocal_uncertainty.errors import BagError
from robocal_uncertainty.pipeline import CalibrationPipeline, SampleStore, StaticPoseCollector
from robocal_uncertainty.pipeline.replay import POSE_WITH_COVARIANCE_STAMPED, replay_bag
from robocal_uncertainty.uncertainty import UncertaintySettings

ORIENTATION_STD = 2e-4  # [rad] per rotation-vector component of one tracker pose reading
SIM = SimulationSettings(n_poses=20, frame="base", orientation_std=ORIENTATION_STD)
RAW = RawBagSettings(
    joint_rate_hz=125.0, tracker_rate_hz=250.0, dwell_s=0.3, move_s=0.15, dropout_rate_hz=0.5, dropout_s=(0.02, 0.1)
)
OPTIONS_KW: dict[str, Any] = {
    "uncertainty": UncertaintySettings(sources=("tracker", "encoder")),
    "test_joints": TEST_JOINTS,
    "trials": 200,
    "seed": SEED,
    "budget": True,
    "budget_trials": 50,
}


def _bits(a: Any) -> bytes:
    return np.ascontiguousarray(a).tobytes()


@pytest.fixture(scope="module")
def simulated(paper_arm: RobotModel) -> SimulatedCampaign:
    return simulate_campaign(paper_arm, SIM, seed=4)


@pytest.fixture(scope="module")
def six_dof_bag(simulated: SimulatedCampaign, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RawBagTruth]:
    path = tmp_path_factory.mktemp("six_dof") / "raw.mcap"
    truth = write_raw_bag(path, simulated, RAW, seed=21)
    return path, truth


@pytest.fixture(scope="module")
def replayed(
    paper_arm: RobotModel, six_dof_bag: tuple[Path, RawBagTruth], tmp_path_factory: pytest.TempPathFactory
) -> tuple[ReplayEvaluation, Path]:
    from robocal_uncertainty.app import EvaluationSettings

    campaign_path = tmp_path_factory.mktemp("six_dof_replay") / "campaign.mcap"
    result = replay(
        six_dof_bag[0],
        paper_arm,
        EvaluationSettings(**OPTIONS_KW),
        tracker_pose_topic=POSE_TOPIC,
        collector=COLLECTOR,
        campaign_path=campaign_path,
    )
    return result, campaign_path


def test_the_raw_bag_holds_poses_and_their_truth(six_dof_bag: tuple[Path, RawBagTruth]) -> None:
    path, truth = six_dof_bag
    back = read_raw_truth(path)
    assert back.to_json() == truth.to_json()
    assert back.windows[3].orientation is not None and truth.windows[3].orientation is not None
    assert _bits(back.windows[3].orientation) == _bits(truth.windows[3].orientation)
    assert truth.tracker_topic == POSE_TOPIC and truth.orientation_std == ORIENTATION_STD
    channels = {c.topic: c.schema_name for c in read_mcap_file(path).channels}
    assert channels == {"/joint_states": JOINT_STATE, POSE_TOPIC: POSE_STAMPED}
    for window in truth.windows:
        assert window.orientation is not None
        assert abs(np.linalg.norm(window.orientation) - 1.0) < 1e-12


def test_replay_finds_every_pose_with_its_orientation(replayed, six_dof_bag) -> None:
    _, truth = six_dof_bag
    result = replayed[0].replay
    assert len(result.samples) == len(truth.windows) == SIM.n_poses
    assert result.message_counts == {"/joint_states": truth.joint_count, POSE_TOPIC: truth.point_count}
    assert sum(result.dropped.values()) == 0
    z = []
    for sample, window in zip(result.samples, truth.windows, strict=True):
        assert window.start_ns < sample.stamp_ns < window.end_ns
        assert sample.orientation is not None and sample.orientation_covariance is not None
        # The reading noise is normal, ORIENTATION_STD per fixed axis: the mean's standard
        # uncertainty is ORIENTATION_STD / sqrt(n), and the sample's (from the scatter) agrees.
        u = ORIENTATION_STD / np.sqrt(sample.tracker_point_count)
        std = np.sqrt(np.diag(sample.orientation_covariance))
        assert np.all((std > 0.6 * u) & (std < 1.5 * u)), (std, u)
        error = rotation_log(quaternion_to_matrix(sample.orientation) @ quaternion_to_matrix(window.orientation).T)
        z.append(error / u)
    z = np.array(z)
    assert np.abs(z).max() < 5.0
    assert 0.6 < z.std() < 1.5  # the scatter of the errors is the stated uncertainty
    campaign = result.campaign
    assert campaign is not None and isinstance(campaign.measurement, PoseMeasurement)
    assert campaign.point_std is not None and campaign.point_std.shape == (SIM.n_poses, 6)


def _node_path(model: RobotModel, path: Path, frame_id: str, recorder_path: Path) -> list[bytes]:
    """What the collector node does with the bag's messages as rclpy would hand them over:
    decoded one by one (decoders independent of the replay's), fed in arrival order, each
    sample recorded to the campaign file, then published as CDR. No flush: a live node
    never sees the end of the stream."""
    collector = StaticPoseCollector.from_settings(model.joint_names, frame_id, COLLECTOR)
    published = []
    with CalibrationPipeline(model, campaign_path=recorder_path, fsync=False) as recorder:
        for message in sorted(read_mcap_file(path).messages, key=lambda m: m.log_time_ns):
            if message.channel.topic == "/joint_states":
                joint = decode_joint_state(message.data)
                sample = collector.add_joint_state(joint.stamp_ns, joint.names, joint.positions)
            else:
                pose = decode_pose_stamped(message.data)
                sample = collector.add_tracker_pose(pose.stamp_ns, pose.frame_id, pose.xyz, pose.quaternion)
            if sample is not None:
                recorder.add_sample(sample)
                published.append(encode_message(sample_to_msg(sample), CALIBRATION_SAMPLE))
    return published


def test_node_path_equals_replay_samples_calibration_and_uncertainty(
    replayed, six_dof_bag, paper_arm: RobotModel, simulated: SimulatedCampaign, tmp_path: Path
) -> None:
    from robocal_uncertainty.app import EvaluationSettings

    path, truth = six_dof_bag
    result, campaign_path = replayed
    node_campaign = tmp_path / "node_campaign.mcap"
    published = _node_path(paper_arm, path, truth.frame_id, node_campaign)
    received = [msg_to_sample(decode_message(data, CALIBRATION_SAMPLE)) for data in published]

    # Samples: every field, the orientation and its covariance bit for bit.
    assert len(received) == len(result.replay.samples) == SIM.n_poses
    for node_sample, replay_sample in zip(received, result.replay.samples, strict=True):
        assert node_sample == replay_sample
        assert _bits(node_sample.orientation) == _bits(replay_sample.orientation)
        assert _bits(node_sample.orientation_covariance) == _bits(replay_sample.orientation_covariance)

    # The collector node's campaign file equals the replay's.
    on_file, replay_file = read_campaign(node_campaign), read_campaign(campaign_path)
    assert on_file.measurement == replay_file.measurement
    assert _bits(on_file.points) == _bits(replay_file.points)
    assert _bits(on_file.point_std) == _bits(replay_file.point_std)

    # Calibration node: the received samples (any arrival order) into its store, identified.
    options = EvaluationSettings(**OPTIONS_KW)
    store = SampleStore(paper_arm)
    for sample in reversed(received):
        assert store.add(sample)
    calibration = store.pipeline(options=options).calibrate()
    ours = result.evaluation
    assert calibration.parameter_names == ours.calibration.parameter_names
    assert {"tool.rx", "tool.ry", "tool.rz"} <= set(calibration.parameter_names)
    assert _bits(calibration.estimate) == _bits(ours.calibration.estimate)

    # Uncertainty node: the pipeline of the first n samples, evaluated with that calibration.
    pipeline = SampleStore.pipeline_of(paper_arm, store.first(len(store)), options=options)
    node = evaluate(paper_arm, pipeline.campaign, options, calibration=pipeline.calibrate())
    assert _bits(node.uncertainty.samples) == _bits(ours.uncertainty.samples)
    assert node.uncertainty.rotation_samples is not None
    assert _bits(node.uncertainty.rotation_samples) == _bits(ours.uncertainty.rotation_samples)
    for a, b in zip(node.uncertainty.poses, ours.uncertainty.poses, strict=True):
        assert a.orientation is not None and b.orientation is not None
        assert _bits(a.orientation.mean_quaternion) == _bits(b.orientation.mean_quaternion)
        assert _bits(a.orientation.covariance) == _bits(b.orientation.covariance)
    for source in ("tracker", "encoder"):
        assert _bits(node.budget[source].samples) == _bits(ours.budget[source].samples)

    # Against the truth: the calibrated model's tool orientation at the true poses is the true
    # one to well within the nominal model's error (0.1 deg angle errors, a drawn tool rotation).
    true_q = simulated.true_joint_positions
    _, true_rot = forward_poses(simulated.true_model, simulated.true_model.parameter_vector(), true_q)
    _, calibrated = forward_poses(calibration.model, calibration.estimate, true_q)
    nominal_model = paper_arm.with_tool_rotation()
    _, nominal = forward_poses(nominal_model, nominal_model.parameter_vector(), true_q)
    error = np.linalg.norm(rotation_log(calibrated @ np.swapaxes(true_rot, -1, -2)), axis=-1)
    nominal_error = np.linalg.norm(rotation_log(nominal @ np.swapaxes(true_rot, -1, -2)), axis=-1)
    # Means of about 60 readings of 0.2 mrad: 0.025 mrad per axis; the nominal model is mrad off.
    assert error.max() < 1e-4
    assert nominal_error.max() > 2e-3


def test_evaluate_of_the_recorded_6dof_campaign_equals_replay(replayed, paper_arm: RobotModel) -> None:
    """The command line's ``evaluate`` of the campaign file the replay wrote: the same numbers."""
    from robocal_uncertainty.app import EvaluationSettings

    result, campaign_path = replayed
    again = evaluate(paper_arm, read_campaign(campaign_path), EvaluationSettings(**OPTIONS_KW))
    ours = result.evaluation
    assert _bits(again.calibration.estimate) == _bits(ours.calibration.estimate)
    assert _bits(again.uncertainty.samples) == _bits(ours.uncertainty.samples)
    assert _bits(again.uncertainty.rotation_samples) == _bits(ours.uncertainty.rotation_samples)
    assert again.warnings == ours.warnings


def test_bad_quaternions_on_the_pose_topic_are_dropped_and_counted(
    paper_arm: RobotModel, simulated: SimulatedCampaign, tmp_path: Path
) -> None:
    records, truth = simulate_raw_recording(simulated, RAW, seed=21)
    poses = [i for i, r in enumerate(records) if r.topic == POSE_TOPIC]
    # Every 50th pose reading scaled to norm 1.01, every 50th (offset 25) with a NaN component.
    for k, i in enumerate(poses[::25]):
        reading = decode_pose_stamped(records[i].data)
        q = reading.quaternion * 1.01 if k % 2 == 0 else np.array([np.nan, 0.0, 0.0, 1.0])
        data = encode_pose_stamped(reading.stamp_ns, reading.frame_id, reading.xyz, q)
        records[i] = RawRecord(POSE_TOPIC, POSE_STAMPED, records[i].log_time_ns, data)
    path = tmp_path / "bad.mcap"
    write_raw_records(path, records, {RAW_TRUTH_METADATA: {"truth": truth.to_json()}})
    logged: list[tuple[str, str]] = []
    result = replay_bag(
        path,
        paper_arm,
        tracker_pose_topic=POSE_TOPIC,
        collector=COLLECTOR,
        calibrate=False,
        log=lambda cause, message: logged.append((cause, message)),
    )
    n_bad = len(poses[::25])
    assert result.dropped["bad_quaternion"] == (n_bad + 1) // 2
    assert result.dropped["nan"] == n_bad // 2
    assert sum(result.dropped.values()) == n_bad
    assert len(result.samples) == len(truth.windows)  # the dwells still average enough poses
    assert any(cause == "bad_quaternion" and "norm 1.01" in message for cause, message in logged)
    assert all("\n" not in message for _, message in logged)


def _with_covariance(records: list[RawRecord]) -> list[RawRecord]:
    """The pose records as PoseWithCovarianceStamped, with an arbitrary reported covariance."""
    store = ros_typestore()
    out = []
    for record in records:
        if record.topic != POSE_TOPIC:
            out.append(record)
            continue
        reading = decode_pose_stamped(record.data)
        sec, nanosec = stamp_parts(reading.stamp_ns)
        header = store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=reading.frame_id
        )
        x, q = reading.xyz, reading.quaternion
        pose = store.types["geometry_msgs/msg/Pose"](
            position=store.types["geometry_msgs/msg/Point"](x=x[0], y=x[1], z=x[2]),
            orientation=store.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        covariance = np.diag([1e-10, 1e-10, 1e-10, 4e-8, 4e-8, 4e-8]).reshape(-1)
        message = store.types[POSE_WITH_COVARIANCE_STAMPED](
            header=header, pose=store.types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=covariance)
        )
        data = bytes(store.serialize_cdr(message, POSE_WITH_COVARIANCE_STAMPED))
        out.append(RawRecord(POSE_TOPIC, POSE_WITH_COVARIANCE_STAMPED, record.log_time_ns, data))
    return out


def test_pose_with_covariance_stamped_gives_the_same_samples(
    paper_arm: RobotModel, simulated: SimulatedCampaign, replayed, tmp_path: Path
) -> None:
    records, _ = simulate_raw_recording(simulated, RAW, seed=21)
    path = tmp_path / "with_covariance.mcap"
    write_raw_records(path, _with_covariance(records))
    result = replay_bag(path, paper_arm, tracker_pose_topic=POSE_TOPIC, collector=COLLECTOR, calibrate=False)
    expected = replayed[0].replay.samples
    assert len(result.samples) == len(expected)
    assert all(a == b for a, b in zip(result.samples, expected, strict=True))


def test_wrong_tracker_topic_kinds_are_one_line_bag_errors(paper_arm: RobotModel, six_dof_bag) -> None:
    from pipeline_data import BASE_BAG

    with pytest.raises(BagError, match=r"/tracker/point not found; /tracker/pose carries 6-DOF tracker poses"):
        replay_bag(six_dof_bag[0], paper_arm, collector=COLLECTOR, calibrate=False)
    with pytest.raises(BagError, match=r"/tracker/pose carries poses; /tracker/pose carries 6-DOF"):
        replay_bag(six_dof_bag[0], paper_arm, point_topic=POSE_TOPIC, collector=COLLECTOR, calibrate=False)
    with pytest.raises(BagError, match=r"tracker pose topic /tracker/point has type geometry_msgs/msg/PointStamped"):
        replay_bag(BASE_BAG, paper_arm, tracker_pose_topic="/tracker/point", calibrate=False)
    with pytest.raises(BagError, match=r"tracker pose topic /nope not found"):
        replay_bag(BASE_BAG, paper_arm, tracker_pose_topic="/nope", calibrate=False)


def test_command_line_replays_a_pose_topic(six_dof_bag, paper_arm: RobotModel, tmp_path: Path) -> None:
    """``replay --tracker-pose-topic`` writes the campaign the service replay builds with the
    command line's collector settings, and reports the orientation at the test configuration."""
    path, _ = six_dof_bag
    out, campaign_out = tmp_path / "report", tmp_path / "campaign.mcap"
    joints = [str(v) for v in np.degrees(TEST_JOINTS[1])]
    argv = ["replay", str(path), "--robot", "paper_arm", "--tracker-pose-topic", POSE_TOPIC, "--degrees"]
    argv += ["--test-joints", *joints, "--sources", "tracker,encoder", "--trials", "100", "--seed", "7"]
    argv += ["--no-budget", "--no-sweeps", "--no-progress", "--out", str(out)]
    argv += ["--campaign-out", str(campaign_out)]
    assert main(argv) == 0
    service = replay_bag(path, paper_arm, tracker_pose_topic=POSE_TOPIC, calibrate=False, auto_window=True)
    assert service.campaign is not None
    written = read_campaign(campaign_out)
    assert isinstance(written.measurement, PoseMeasurement)
    positions, rotations = split_pose_values(written.points)
    expected_positions, expected_rotations = split_pose_values(service.campaign.points)
    np.testing.assert_array_equal(positions, expected_positions)
    np.testing.assert_allclose(rotations, expected_rotations, atol=1e-15)
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    orientation = report["test_configurations"][0]["orientation"]
    assert abs(np.linalg.norm(orientation["mean_quaternion_xyzw"]) - 1.0) < 1e-9
    assert report["settings"]["sources"] == ["tracker", "encoder"]
    # Without --sources: the validated default plus, for a pose topic, the tracker's orientation noise.
    default_out = tmp_path / "default_sources"
    argv_default = [a for a in argv if a not in ("--sources", "tracker,encoder", "--campaign-out", str(campaign_out))]
    argv_default[argv_default.index(str(out))] = str(default_out)
    assert main(argv_default) == 0
    report = json.loads((default_out / "report.json").read_text(encoding="utf-8"))
    assert report["settings"]["sources"] == ["tracker", "encoder", "residual", "tracker_orientation"]


def test_point_and_6dof_recordings_of_one_campaign_share_timing_and_positions(
    paper_arm: RobotModel, simulated: SimulatedCampaign
) -> None:
    """The same simulated campaign without orientations records points where the 6-DOF one
    records poses: same stamps, log times and positions (the orientation noise has a stream
    of its own); its truth has no orientation."""
    point_only = simulate_campaign(paper_arm, SimulationSettings(n_poses=20, frame="base"), seed=4)
    point_records, point_truth = simulate_raw_recording(point_only, RAW, seed=21)
    pose_records, pose_truth = simulate_raw_recording(simulated, RAW, seed=21)
    assert [w.start_ns for w in pose_truth.windows] == [w.start_ns for w in point_truth.windows]
    assert all(np.array_equal(a.point, b.point) for a, b in zip(pose_truth.windows, point_truth.windows, strict=True))
    assert point_truth.tracker_topic == "/tracker/point" and point_truth.orientation_std is None
    assert all(w.orientation is None for w in point_truth.windows)
    assert [r.log_time_ns for r in point_records] == [r.log_time_ns for r in pose_records]
    for a, b in zip(point_records, pose_records, strict=True):
        if a.topic == "/joint_states":
            assert a.data == b.data
            continue
        assert (a.topic, b.topic) == ("/tracker/point", POSE_TOPIC)
        point = ros_typestore().deserialize_cdr(a.data, "geometry_msgs/msg/PointStamped")
        pose = decode_pose_stamped(b.data)
        assert [point.point.x, point.point.y, point.point.z] == pose.xyz.tolist()
        assert point.header.stamp.sec * 1_000_000_000 + point.header.stamp.nanosec == pose.stamp_ns
