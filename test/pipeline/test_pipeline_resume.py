"""Calibration pipeline: crash-safe campaign recording, resume after a crash, errors."""

from __future__ import annotations

import gc
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from pipeline_data import BASE_BAG, COLLECTOR, SEED, TEST_JOINTS

from robocal_uncertainty.app import evaluate
from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.core import RobotModel
from robocal_uncertainty.errors import CampaignError, ConfigError, IdentifiabilityError, InputError
from robocal_uncertainty.pipeline import CalibrationPipeline, CalibrationSample, replay_bag
from robocal_uncertainty.uncertainty import EvaluationSettings, evaluate_uncertainty


@pytest.fixture(scope="module")
def samples(paper_arm: RobotModel) -> tuple[CalibrationSample, ...]:
    return replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False).samples


def _same_campaign(a, b) -> None:
    for name in ("joint_positions", "points", "point_std", "stamps_ns"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert (a.frame, a.frame_id, a.joint_names) == (b.frame, b.frame_id, b.joint_names)


def test_crash_mid_campaign_resumes_with_every_written_sample(
    tmp_path: Path, paper_arm: RobotModel, samples: tuple[CalibrationSample, ...]
) -> None:
    live = tmp_path / "live.mcap"
    pipeline = CalibrationPipeline(paper_arm, campaign_path=live)
    for sample in samples[:12]:
        pipeline.add_sample(sample)
    # The disk as a crash leaves it: the file as flushed so far, plus half a record.
    crashed = tmp_path / "crashed.mcap"
    shutil.copyfile(live, crashed)
    with crashed.open("ab") as stream:
        stream.write(b"\x05\x40\x00\x00\x00\x00\x00\x00\x00partial")
    before = pipeline.campaign

    resumed = CalibrationPipeline(paper_arm, campaign_path=crashed)
    assert resumed.n_samples == 12
    assert any("truncated" in w for w in resumed.resume_warnings)
    assert "warnings" not in resumed.campaign.metadata  # the rewritten file is complete
    _same_campaign(resumed.campaign, before)
    for sample in samples[12:]:
        resumed.add_sample(sample)
    resumed.close()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # rewritten and closed: a complete file
        stored = read_campaign(crashed)
    assert stored.n_poses == len(samples)
    assert not crashed.with_name(crashed.name + ".resume").exists()

    # Same campaign, same calibration as if nothing had happened.
    reference = CalibrationPipeline(paper_arm)
    for sample in samples:
        reference.add_sample(sample)
    _same_campaign(stored, reference.campaign)
    assert resumed.calibrate().estimate.tobytes() == reference.calibrate().estimate.tobytes()


def test_abandoned_pipeline_resumes_on_the_same_path(
    tmp_path: Path, paper_arm: RobotModel, samples: tuple[CalibrationSample, ...]
) -> None:
    path = tmp_path / "campaign.mcap"
    pipeline = CalibrationPipeline(paper_arm, campaign_path=path, fsync=False)
    for sample in samples[:5]:
        pipeline.add_sample(sample)
    expected = pipeline.campaign
    del pipeline  # never closed: no summary, no footer
    gc.collect()
    resumed = CalibrationPipeline(paper_arm, campaign_path=path)
    _same_campaign(resumed.campaign, expected)
    resumed.add_sample(samples[5])
    del resumed
    gc.collect()
    again = CalibrationPipeline(paper_arm, campaign_path=path)
    assert again.n_samples == 6
    again.close()


def test_evaluate_matches_evaluate_uncertainty(paper_arm: RobotModel, samples) -> None:
    options = EvaluationSettings(test_joints=TEST_JOINTS, trials=200, seed=SEED)
    pipeline = CalibrationPipeline(paper_arm, options=options)
    for sample in samples:
        pipeline.add_sample(sample)
    result = evaluate(paper_arm, pipeline.campaign, options, calibration=pipeline.calibrate()).uncertainty
    direct = evaluate_uncertainty(paper_arm, pipeline.campaign, TEST_JOINTS, trials=200, seed=SEED, coverage=0.95)
    assert result.samples.tobytes() == direct.samples.tobytes()
    assert pipeline.calibrate() is pipeline.calibrate()  # cached until the next sample


def test_too_few_samples_and_missing_test_joints(paper_arm: RobotModel, samples) -> None:
    pipeline = CalibrationPipeline(paper_arm, min_samples=10)
    assert pipeline.campaign is None and not pipeline.ready
    with pytest.raises(IdentifiabilityError, match="only 0 calibration samples, need at least 10"):
        pipeline.calibrate()
    for sample in samples[:10]:
        pipeline.add_sample(sample)
    assert pipeline.ready
    with pytest.raises(ConfigError, match="no test joint"):
        evaluate(paper_arm, pipeline.campaign, pipeline.options, calibration=pipeline.calibrate())


def test_bad_samples_are_refused(tmp_path: Path, paper_arm: RobotModel, samples) -> None:
    pipeline = CalibrationPipeline(paper_arm, campaign_path=tmp_path / "c.mcap")
    pipeline.add_sample(samples[0])
    with pytest.raises(InputError, match="already in the campaign"):
        pipeline.add_sample(samples[0])
    other = CalibrationSample(
        samples[1].stamp_ns,
        "laser_tracker",
        samples[1].joint_names,
        samples[1].joint_positions,
        samples[1].joint_position_std,
        samples[1].point,
        samples[1].point_covariance,
        1,
        2,
    )
    with pytest.raises(InputError, match="frame"):
        pipeline.add_sample(other)
    renamed = CalibrationSample(
        samples[1].stamp_ns,
        samples[1].frame_id,
        tuple(f"j{k}" for k in range(6)),
        samples[1].joint_positions,
        samples[1].joint_position_std,
        samples[1].point,
        samples[1].point_covariance,
        1,
        2,
    )
    with pytest.raises(InputError, match="differ from the model"):
        pipeline.add_sample(renamed)
    assert pipeline.n_samples == 1
    pipeline.close()
    with pytest.raises(CampaignError, match="closed"):
        pipeline.add_sample(samples[1])
    assert read_campaign(tmp_path / "c.mcap").n_poses == 1


def test_samples_in_another_joint_order_are_reordered(paper_arm: RobotModel, samples) -> None:
    sample = samples[0]
    order = [5, 4, 3, 2, 1, 0]
    shuffled = CalibrationSample(
        sample.stamp_ns,
        sample.frame_id,
        tuple(sample.joint_names[k] for k in order),
        sample.joint_positions[order],
        sample.joint_position_std[order],
        sample.point,
        sample.point_covariance,
        sample.joint_state_count,
        sample.tracker_point_count,
    )
    pipeline = CalibrationPipeline(paper_arm)
    pipeline.add_sample(shuffled)
    np.testing.assert_array_equal(pipeline.campaign.joint_positions[0], sample.joint_positions)


def test_resume_refuses_a_campaign_of_another_robot(tmp_path: Path, paper_arm: RobotModel, samples) -> None:
    import dataclasses

    path = tmp_path / "c.mcap"
    with CalibrationPipeline(paper_arm, campaign_path=path) as pipeline:
        pipeline.add_sample(samples[0])
    other = dataclasses.replace(paper_arm, joint_names=tuple(f"j{k}" for k in range(6)))
    with pytest.raises(InputError, match="do not match"):
        CalibrationPipeline(other, campaign_path=path)
    assert read_campaign(path).n_poses == 1
