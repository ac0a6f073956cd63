"""ROS-free node logic, tested without ROS: the sample store and the stream merger."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from pipeline_data import BASE_BAG, COLLECTOR

from robocal_uncertainty.core import RobotModel
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.pipeline import SampleStore, StreamMerger, replay_bag


@pytest.fixture(scope="module")
def samples(paper_arm: RobotModel):
    return replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False).samples


def test_store_keys_samples_by_stamp_and_orders_them(paper_arm: RobotModel, samples) -> None:
    store = SampleStore(paper_arm)
    for sample in reversed(samples):
        assert store.add(sample)
    assert not store.add(samples[0]) and store.duplicates == 1
    assert len(store) == len(samples) and store.latest_stamp_ns == samples[-1].stamp_ns
    assert store.first(3) == list(samples[:3])
    pipeline = store.pipeline(5)
    assert pipeline.n_samples == 5
    assert np.array_equal(pipeline.campaign.stamps_ns, [s.stamp_ns for s in samples[:5]])


def test_store_refuses_other_joints_and_frames(paper_arm: RobotModel, samples) -> None:
    store = SampleStore(paper_arm)
    store.add(samples[0])
    other = dataclasses.replace(samples[1], frame_id="elsewhere")
    with pytest.raises(InputError, match="frame 'elsewhere'"):
        store.add(other)
    renamed = dataclasses.replace(samples[1], joint_names=tuple(f"j{i}" for i in range(6)))
    with pytest.raises(InputError, match="differ from the model"):
        store.add(renamed)
    assert store.refused == 2


def test_store_merges_the_campaign_file_with_live_samples(tmp_path: Path, paper_arm: RobotModel) -> None:
    path = tmp_path / "campaign.mcap"
    replayed = replay_bag(BASE_BAG, paper_arm, collector=COLLECTOR, calibrate=False, campaign_path=path)
    store = SampleStore(paper_arm)
    store.add(replayed.samples[0])  # seen live before the file is read: counted once
    added, notes = store.load_campaign_file(path)
    assert added == len(replayed.samples) - 1 and notes == ()
    assert len(store) == len(replayed.samples)


def test_merger_releases_in_key_order_and_holds_for_the_other_stream() -> None:
    out: list[tuple[int, str]] = []
    merger = StreamMerger(lambda stream, item: out.append((stream, item)), hold_ns=100)
    merger.push(0, 10, 1000, "a10")
    assert out == []  # waits for stream 1
    merger.push(1, 5, 1010, "b5")
    assert out == [(1, "b5")]
    merger.release(1050)
    assert out == [(1, "b5")]
    merger.release(1100)  # held long enough
    assert out == [(1, "b5"), (0, "a10")]
    merger.push(0, 20, 2000, "a20")
    merger.push(0, 30, 2001, "a30")
    assert len(merger) == 2
    merger.drain()
    assert [item for _, item in out[-2:]] == ["a20", "a30"]
    merger.push(1, 1, 3000, "x")
    merger.clear()
    assert len(merger) == 0


def test_merger_refuses_a_negative_hold() -> None:
    with pytest.raises(ConfigError, match="hold_ns must be >= 0"):
        StreamMerger(lambda stream, item: None, hold_ns=-1)
