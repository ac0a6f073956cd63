"""Joint values outside the robot config's limits end in one line naming joint, value, limits, row."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, check_joint_limits, load_robot_model, simulate_campaign
from robocal_uncertainty.core.joint_limits import DEGREES_HINT
from robocal_uncertainty.errors import InputError

REPO = Path(__file__).resolve().parents[2]
# The robot paper's test configuration (Table 2), degrees; joint2 must lie in [-265, -95] deg.
PAPER_TEST_JOINTS_DEG = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)


@pytest.fixture(scope="module")
def paper_arm():
    return load_robot_model(REPO / "robocal_uncertainty" / "data" / "paper_arm.yaml")


@pytest.fixture(scope="module")
def ur10():
    return load_robot_model(REPO / "robocal_uncertainty" / "data" / "ur10.yaml")


def _message(model, q, **kwargs) -> str:
    with pytest.raises(InputError) as excinfo:
        check_joint_limits(model, q, **kwargs)
    msg = str(excinfo.value)
    assert msg and "\n" not in msg
    return msg


def test_limits_come_from_the_yaml_in_degrees(paper_arm) -> None:
    np.testing.assert_allclose(np.degrees(paper_arm.joint_limits[1]), [-265.0, -95.0])


def test_values_inside_the_limits_pass(paper_arm, ur10) -> None:
    check_joint_limits(paper_arm, np.radians(PAPER_TEST_JOINTS_DEG))
    check_joint_limits(ur10, [0.0, -1.0, 1.0, 0.0, 1.0, 0.0])
    # Exactly on a limit is inside.
    check_joint_limits(ur10, ur10.joint_limits[:, 1])
    check_joint_limits(ur10, ur10.joint_limits[:, 0][None, :])


@pytest.mark.parametrize("robot", ["paper_arm", "ur10"])
@pytest.mark.parametrize("frame", ["base", "tracker"])
def test_simulated_campaigns_pass(robot: str, frame: str, request: pytest.FixtureRequest) -> None:
    model = request.getfixturevalue(robot)
    campaign = simulate_campaign(model, SimulationSettings(frame=frame), seed=3).campaign
    check_joint_limits(model, campaign.joint_positions, what="campaign pose")


def test_message_names_row_joint_value_and_limits(paper_arm) -> None:
    q = np.radians(np.tile(PAPER_TEST_JOINTS_DEG, (3, 1)))
    q[2, 1] = -1.0  # joint2 at -57.3 deg, its limits are [-265, -95] deg
    msg = _message(paper_arm, q, what="campaign pose")
    assert msg.startswith("campaign pose 3 of 3: joint joint2 = -1 rad (-57.2958 deg)")
    assert "outside its limits [-265, -95] deg" in msg
    assert "more value" not in msg
    # -1 deg is outside as well: no degrees hint.
    assert DEGREES_HINT not in msg


def test_first_offender_reported_with_the_count_of_the_others(ur10) -> None:
    q = np.zeros((2, 6))
    q[0, 2] = 3.5  # elbow_joint limits are [-180, 180] deg
    q[1, 0] = 7.0
    q[1, 5] = -7.0
    msg = _message(ur10, q)
    assert msg.startswith("configuration 1 of 2: joint elbow_joint = 3.5 rad (200.535 deg)")
    assert "[-180, 180] deg" in msg
    assert "(2 more values outside the limits)" in msg


def test_degrees_typed_as_radians_get_the_hint(paper_arm, ur10) -> None:
    msg = _message(
        paper_arm, PAPER_TEST_JOINTS_DEG, what="--joints configuration", degrees_hint="did you mean --degrees?"
    )
    assert msg.startswith("--joints configuration 1 of 1: joint joint1 = -7.5005 rad (-429.747 deg)")
    assert "[-175, 175] deg" in msg
    assert msg.endswith("; did you mean --degrees?")
    assert DEGREES_HINT in _message(ur10, [0.0, -90.0, 90.0, 0.0, 90.0, 0.0])


def test_no_hint_when_the_values_do_not_fit_as_degrees_either(paper_arm) -> None:
    q = np.array(PAPER_TEST_JOINTS_DEG)
    q[1] = -300.0  # outside [-265, -95] in degrees too
    assert "did you mean" not in _message(paper_arm, q, degrees_hint="did you mean --degrees?")


def test_no_hint_when_disabled(paper_arm) -> None:
    # Degrees already converted: the values read as degrees again would be tiny and "fit".
    q = np.radians([0.0, -400.0, 0.0, 0.0, 0.0, 0.0])
    msg = _message(paper_arm, q, degrees_hint=None)
    assert re.search(r"joint joint2 = -6\.98132 rad \(-400 deg\) is outside its limits \[-265, -95\] deg$", msg)


def test_wrong_width_and_nan(ur10) -> None:
    assert "expected 6 joint values" in _message(ur10, np.zeros((2, 5)))
    q = np.zeros(6)
    q[4] = np.nan
    assert "joint wrist_2_joint = nan rad" in _message(ur10, q)
