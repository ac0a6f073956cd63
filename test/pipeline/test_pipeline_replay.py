"""Replaying the raw test bags: every static pose found, sample means within the noise of the
truth, and an uncertainty bit-identical to ``evaluate_uncertainty`` on the same campaign."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from pipeline_data import BASE_BAG, COLLECTOR, SEED, TEST_JOINTS, TRACKER_BAG, TRIALS

from robocal_uncertainty.app import ReplayEvaluation, evaluate, replay
from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagTruth
from robocal_uncertainty.core import RobotModel, SimulationSettings
from robocal_uncertainty.errors import BagError, CampaignError
from robocal_uncertainty.pipeline import replay_bag
from robocal_uncertainty.uncertainty import (
    CalibrationUncertainty,
    EvaluationSettings,
    UncertaintySettings,
    evaluate_uncertainty,
)

OPTIONS = EvaluationSettings(test_joints=TEST_JOINTS, trials=TRIALS, seed=SEED)
ENCODER = SimulationSettings().encoder_noise
TRACKER = SimulationSettings().tracker_noise


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def base_replay(paper_arm: RobotModel, tmp_path_factory: pytest.TempPathFactory) -> tuple[ReplayEvaluation, Path]:
    campaign_path = tmp_path_factory.mktemp("replay") / "campaign.mcap"
    replayed = replay(BASE_BAG, paper_arm, OPTIONS, collector=COLLECTOR, campaign_path=campaign_path)
    return replayed, campaign_path


def _check_windows(samples: tuple, truth: RawBagTruth) -> None:
    """One sample per true dwell, each stamped inside its dwell: none missed, none invented."""
    assert len(samples) == len(truth.windows)
    for sample, window in zip(samples, truth.windows):
        assert window.start_ns < sample.stamp_ns < window.end_ns


def _check_means(samples: tuple, truth: RawBagTruth) -> None:
    """Sample means agree with the truth within 5 standard deviations of a mean."""
    z_q, z_x = [], []
    for sample, window in zip(samples, truth.windows):
        u_q = ENCODER.half_width / np.sqrt(3.0) / np.sqrt(sample.joint_state_count)
        u_x = TRACKER.a / np.sqrt(3.0) / np.sqrt(sample.tracker_point_count)
        z_q.append((sample.joint_positions - window.joint_positions) / u_q)
        z_x.append((sample.point - window.point) / u_x)
    z_q, z_x = np.array(z_q), np.array(z_x)
    assert np.abs(z_q).max() < 5.0
    assert np.abs(z_x).max() < 5.0
    # No bias from the arrival or departure leaking into the averages.
    assert abs(z_q.mean()) < 4.0 / np.sqrt(z_q.size)
    assert abs(z_x.mean()) < 4.0 / np.sqrt(z_x.size)


def test_base_bag_finds_every_static_pose(base_replay, base_truth: RawBagTruth) -> None:
    result = base_replay[0].replay
    _check_windows(result.samples, base_truth)
    assert result.rejected_dwells == 0
    assert sum(result.dropped.values()) == 0
    assert result.message_counts == {"/joint_states": base_truth.joint_count, "/tracker/point": base_truth.point_count}
    assert result.tracker_frame_id == base_truth.frame_id == "base_link"
    assert not result.truncated


def test_base_bag_sample_means_within_noise(base_replay, base_truth: RawBagTruth) -> None:
    result = base_replay[0].replay
    _check_means(result.samples, base_truth)
    for sample in result.samples:
        assert sample.joint_state_count >= 20
        assert sample.tracker_point_count >= COLLECTOR.min_points


def test_base_bag_calibrates(base_replay) -> None:
    result = base_replay[0]
    assert result.replay.campaign is not None
    assert result.replay.campaign.frame == "base"
    assert result.replay.calibration is None  # the service calibrates (once)
    assert result.evaluation.calibration.rms_after < 2e-5 < result.evaluation.calibration.rms_before


def test_replay_uncertainty_is_bit_identical_to_evaluate(base_replay, paper_arm: RobotModel) -> None:
    result = base_replay[0]
    assert isinstance(result.evaluation.uncertainty, CalibrationUncertainty)
    direct = evaluate_uncertainty(
        paper_arm,
        result.replay.campaign,
        TEST_JOINTS,
        uncertainty=UncertaintySettings(),
        trials=TRIALS,
        seed=SEED,
        coverage=0.95,
    )
    _assert_same_uncertainty(result.evaluation.uncertainty, direct)


def test_recorded_campaign_file_gives_the_same_uncertainty(base_replay, paper_arm: RobotModel) -> None:
    replayed, campaign_path = base_replay
    result = replayed.replay
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a closed, complete file
        stored = read_campaign(campaign_path)
    for name in ("joint_positions", "points", "point_std", "stamps_ns"):
        assert _same_bits(getattr(stored, name), getattr(result.campaign, name)), name
    assert (stored.frame, stored.frame_id, stored.joint_names) == (
        result.campaign.frame,
        result.campaign.frame_id,
        result.campaign.joint_names,
    )
    _assert_same_uncertainty(replayed.evaluation.uncertainty, evaluate(paper_arm, stored, OPTIONS).uncertainty)


def _assert_same_uncertainty(a: CalibrationUncertainty, b: CalibrationUncertainty) -> None:
    assert _same_bits(a.samples, b.samples)
    assert _same_bits(a.calibration.estimate, b.calibration.estimate)
    assert a.n_trials == b.n_trials == TRIALS
    for pa, pb in zip(a.poses, b.poses, strict=True):
        assert _same_bits(pa.mean, pb.mean)
        assert _same_bits(pa.covariance, pb.covariance)
        assert [x.expanded_uncertainty for x in pa.axes] == [x.expanded_uncertainty for x in pb.axes]


def test_tracker_bag_ends_in_a_dwell_and_identifies_the_base(
    paper_arm_unknown_base: RobotModel, tracker_truth: RawBagTruth
) -> None:
    result = replay_bag(TRACKER_BAG, paper_arm_unknown_base, collector=COLLECTOR)
    _check_windows(result.samples, tracker_truth)
    _check_means(result.samples, tracker_truth)
    assert result.tracker_frame_id == "laser_tracker"
    assert result.campaign is not None and result.campaign.frame == "tracker"
    assert result.calibration is not None and result.calibration.rms_after < 2e-5
    # The recording stops during the last dwell: flush() emitted it.
    assert tracker_truth.windows[-1].end_ns >= result.samples[-1].stamp_ns


def test_replay_without_calibration_only_collects(paper_arm: RobotModel, base_truth: RawBagTruth) -> None:
    result = replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False)
    assert result.calibration is None
    assert len(result.samples) == len(base_truth.windows)


@pytest.mark.parametrize(
    "content",
    [
        b"",
        b"not a bag at all\n",
        b"\x89MCAP0\r\n" + b"\xff" * 64,
        b"\x89MCAP0\r\n\x01\x05\x00\x00\x00\x00\x00\x00\x00abc",
    ],
    ids=["empty", "text", "garbage-after-magic", "bad-header-record"],
)
def test_corrupt_or_non_bag_files_give_one_line_bag_error(
    tmp_path: Path, paper_arm: RobotModel, content: bytes
) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(BagError) as info:
        replay_bag(path, paper_arm, collector=COLLECTOR)
    assert "\n" not in str(info.value)


def test_missing_file_and_plain_directory_give_bag_error(tmp_path: Path, paper_arm: RobotModel) -> None:
    for path in (tmp_path / "missing.mcap", tmp_path):
        with pytest.raises(BagError, match="bag"):
            replay_bag(path, paper_arm)


def test_missing_topic_gives_bag_error(paper_arm: RobotModel) -> None:
    with pytest.raises(BagError, match="topic /robot/joints not found"):
        replay_bag(BASE_BAG, paper_arm, joint_topic="/robot/joints")


def test_wrongly_typed_topic_gives_bag_error(paper_arm: RobotModel) -> None:
    with pytest.raises(BagError, match="expected sensor_msgs/msg/JointState"):
        replay_bag(BASE_BAG, paper_arm, joint_topic="/tracker/point")


def test_replay_refuses_an_existing_campaign_file(tmp_path: Path, paper_arm: RobotModel) -> None:
    existing = tmp_path / "campaign.mcap"
    existing.write_bytes(b"x")
    with pytest.raises(CampaignError, match="exists already"):
        replay_bag(BASE_BAG, paper_arm, campaign_path=existing)
