"""The static-pose collector with a 6-DOF tracker: orientation scatter check in rad, chordal
mean of the orientations, 6-DOF campaign from the samples, bad quaternions dropped."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robocal_uncertainty.bagio.campaign_mcap import read_campaign
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, split_pose_values
from robocal_uncertainty.core.rotation import quaternion_from_matrix, quaternion_to_matrix, rotation_exp, rotation_log
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline
from robocal_uncertainty.pipeline.collector import StaticPoseCollector, samples_to_campaign
from robocal_uncertainty.pipeline.sample_store import SampleStore

NAMES = ("j1", "j2")
MS = 1_000_000


def _run(collector: StaticPoseCollector, dwells: list[tuple[np.ndarray, np.ndarray]], rot_noise: float) -> list:  # type: ignore[type-arg]
    """Each dwell: 2 s static at joint q with orientation R, 100 Hz, then a 0.5 s move."""
    rng = np.random.default_rng(0)
    samples = []
    t = 0
    for q, rotation in dwells:
        for k in range(200):
            t += 10 * MS
            samples.append(collector.add_joint_state(t, NAMES, q))
            noisy = rotation_exp(rng.normal(0.0, rot_noise, 3)) @ rotation
            samples.append(
                collector.add_tracker_pose(t + MS, "tracker", q.sum() * np.ones(3), quaternion_from_matrix(noisy))
            )
        for k in range(50):
            t += 10 * MS
            samples.append(collector.add_joint_state(t, NAMES, q + 0.01 * (k + 1)))
    samples.append(collector.flush())
    return [s for s in samples if s is not None]


def test_orientations_are_averaged_on_the_rotation_group() -> None:
    rotations = [rotation_exp(np.array([0.3, -1.0, 2.9])), rotation_exp(np.array([0.0, 0.2, -0.1]))]
    dwells = [(np.array([0.1, 0.2]), rotations[0]), (np.array([0.5, -0.3]), rotations[1])]
    samples = _run(StaticPoseCollector(NAMES, tracker_frame_id="tracker"), dwells, rot_noise=1e-4)
    assert len(samples) == 2
    for sample, rotation in zip(samples, rotations, strict=True):
        assert sample.orientation is not None
        error = rotation_log(quaternion_to_matrix(sample.orientation) @ rotation.T)
        assert np.linalg.norm(error) < 5e-5  # 100 readings of 0.1 mrad: ~1e-5 rad
        std = np.sqrt(np.diag(sample.orientation_covariance))
        np.testing.assert_allclose(std, 1e-5, rtol=0.3)
    campaign = samples_to_campaign(samples, frame="tracker")
    assert isinstance(campaign.measurement, PoseMeasurement)
    _, rot = split_pose_values(campaign.points)
    np.testing.assert_allclose(rot[0], rotations[0], atol=1e-4)
    assert campaign.point_std is not None
    assert campaign.point_std.shape == (2, 6)


def test_orientation_scatter_vetoes_a_static_window() -> None:
    dwells = [(np.array([0.1, 0.2]), np.eye(3))]
    # 5 mrad scatter with a 0.5 mrad threshold: never static, no sample.
    noisy = StaticPoseCollector(NAMES, tracker_frame_id="tracker", orientation_scatter_threshold=5e-4)
    assert _run(noisy, dwells, rot_noise=5e-3) == []
    # The same scatter passes a 0.1 rad threshold.
    loose = StaticPoseCollector(NAMES, tracker_frame_id="tracker", orientation_scatter_threshold=0.1)
    assert len(_run(loose, dwells, rot_noise=5e-3)) == 1


def test_bad_quaternions_are_dropped_and_counted() -> None:
    collector = StaticPoseCollector(NAMES, tracker_frame_id="tracker")
    assert collector.add_tracker_pose(1, "tracker", [0, 0, 0], [0, 0, 0, 2]) is None
    assert collector.add_tracker_pose(2, "tracker", [0, 0, 0], [np.nan, 0, 0, 1]) is None
    assert collector.dropped["bad_quaternion"] == 1
    assert collector.dropped["nan"] == 1


def test_point_samples_keep_the_point_campaign() -> None:
    collector = StaticPoseCollector(NAMES, tracker_frame_id="tracker")
    samples = []
    for k in range(300):
        samples.append(collector.add_joint_state(k * 10 * MS, NAMES, [0.1, 0.2]))
        samples.append(collector.add_tracker_point(k * 10 * MS + MS, "tracker", [1.0, 2.0, 3.0]))
    samples.append(collector.flush())
    kept = [s for s in samples if s is not None]
    assert kept[0].orientation is None
    assert samples_to_campaign(kept, frame="tracker").measurement.name == "point"


def _pose_samples(joint_names: tuple[str, ...], n: int, seed: int) -> list[CalibrationSample]:
    rng = np.random.default_rng(seed)
    samples = []
    for i in range(n):
        rot_cov = np.diag(rng.uniform(1e-11, 1e-9, 3))
        samples.append(
            CalibrationSample(
                stamp_ns=(i + 1) * 1_000_000_000,
                frame_id="tracker",
                joint_names=joint_names,
                joint_positions=rng.uniform(-1.0, 1.0, len(joint_names)),
                joint_position_std=np.full(len(joint_names), 1e-5),
                point=rng.uniform(-1.0, 1.0, 3),
                point_covariance=np.diag(rng.uniform(1e-12, 1e-10, 3)),
                joint_state_count=100,
                tracker_point_count=100,
                orientation=quaternion_from_matrix(rotation_exp(rng.normal(0.0, 1.0, 3))),
                orientation_covariance=rot_cov,
            )
        )
    return samples


def test_the_calibration_pipeline_records_and_resumes_6dof_samples(tmp_path, paper_arm) -> None:
    """The collector node records 6-DOF samples through CalibrationPipeline: the campaign
    (in memory, on file and resumed) keeps every orientation and its standard uncertainty."""
    samples = _pose_samples(paper_arm.joint_names, 5, seed=3)
    path = tmp_path / "campaign.mcap"
    with CalibrationPipeline(paper_arm, campaign_path=path, fsync=False) as pipeline:
        for sample in samples[:3]:
            pipeline.add_sample(sample)
        live = pipeline.campaign
    assert live is not None and isinstance(live.measurement, PoseMeasurement)
    positions, rotations = split_pose_values(live.points)
    for i, sample in enumerate(samples[:3]):
        np.testing.assert_array_equal(positions[i], sample.point)
        np.testing.assert_allclose(rotations[i], quaternion_to_matrix(sample.orientation), atol=1e-15)
        assert live.point_std is not None
        np.testing.assert_array_equal(live.point_std[i, 3:], np.sqrt(np.diag(sample.orientation_covariance)))
    on_file = read_campaign(path)
    assert on_file.measurement == live.measurement
    np.testing.assert_allclose(on_file.points, live.points, atol=1e-12)
    resumed = CalibrationPipeline(paper_arm, campaign_path=path, fsync=False)
    for sample in samples[3:]:
        resumed.add_sample(sample)
    resumed.close()
    whole = read_campaign(path)
    assert whole.n_poses == 5 and whole.measurement == live.measurement
    np.testing.assert_allclose(whole.points[:3], live.points, atol=1e-12)
    np.testing.assert_allclose(
        split_pose_values(whole.points)[1][4], quaternion_to_matrix(samples[4].orientation), atol=1e-12
    )
    point_sample = dataclasses.replace(samples[0], stamp_ns=99, orientation=None, orientation_covariance=None)
    with pytest.raises(InputError, match="orientation"):
        CalibrationPipeline(paper_arm, campaign_path=path, fsync=False).add_sample(point_sample)


def test_the_sample_store_reads_6dof_campaign_files_with_their_orientations(tmp_path, paper_arm) -> None:
    samples = _pose_samples(paper_arm.joint_names, 4, seed=5)
    path = tmp_path / "campaign.mcap"
    with CalibrationPipeline(paper_arm, campaign_path=path, fsync=False) as pipeline:
        for sample in samples:
            pipeline.add_sample(sample)
        recorded = pipeline.campaign
    store = SampleStore(paper_arm)
    assert store.load_campaign_file(path) == (4, ())
    loaded = store.first()
    for sample, back in zip(samples, loaded, strict=True):
        assert back.orientation is not None and sample.orientation is not None
        np.testing.assert_allclose(
            quaternion_to_matrix(back.orientation), quaternion_to_matrix(sample.orientation), atol=1e-12
        )
        np.testing.assert_allclose(back.point, sample.point, atol=1e-15)
        np.testing.assert_allclose(
            np.sqrt(np.diag(back.orientation_covariance)), np.sqrt(np.diag(sample.orientation_covariance)), rtol=1e-12
        )
    rebuilt = store.pipeline().campaign
    assert rebuilt is not None and recorded is not None
    assert rebuilt.measurement == recorded.measurement
    np.testing.assert_allclose(rebuilt.points, recorded.points, atol=1e-12)
