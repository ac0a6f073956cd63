"""Shared fixtures of the pipeline tests: the paper arm and the truth of the raw test bags."""

from __future__ import annotations

import dataclasses

import pytest
from pipeline_data import BASE_BAG, REPO, TRACKER_BAG

from robocal_uncertainty.bagio.raw_bag_simulator import RawBagTruth, read_raw_truth
from robocal_uncertainty.core import RobotModel, load_robot_model


@pytest.fixture(scope="session")
def paper_arm() -> RobotModel:
    return load_robot_model(REPO / "robocal_uncertainty" / "data" / "paper_arm.yaml")


@pytest.fixture(scope="session")
def paper_arm_unknown_base(paper_arm: RobotModel) -> RobotModel:
    """The paper arm measured from a tracker whose pose is unknown (as in the tracker bag)."""
    return dataclasses.replace(paper_arm, base_known=False)


@pytest.fixture(scope="session")
def base_truth() -> RawBagTruth:
    return read_raw_truth(BASE_BAG)


@pytest.fixture(scope="session")
def tracker_truth() -> RawBagTruth:
    return read_raw_truth(TRACKER_BAG)
