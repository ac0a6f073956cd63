"""Every input error surfaces as a one-line CalibError subclass whose message names the problem."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.robot_formats.robot_yaml import (
    load_robot_model,
    robot_model_from_dict,
)
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import (
    CalibError,
    ConfigError,
    IdentifiabilityError,
    InputError,
)

REPO = Path(__file__).resolve().parents[2]
PAPER_YAML = REPO / "config" / "paper_arm.yaml"
JOINTS = ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")


def one_line(excinfo: pytest.ExceptionInfo) -> str:
    """The message, asserted to be a single non-empty line and a CalibError."""
    assert isinstance(excinfo.value, CalibError)
    msg = str(excinfo.value)
    assert msg and "\n" not in msg and "\r" not in msg, repr(msg)
    return msg


@pytest.fixture(scope="module")
def model():
    return load_robot_model(PAPER_YAML)


@pytest.fixture(scope="module")
def campaign(model):
    return simulate_campaign(model, SimulationSettings(), seed=1).campaign


@pytest.fixture()
def paper_dict() -> dict:
    return yaml.safe_load(PAPER_YAML.read_text(encoding="utf-8"))


# --- campaign construction ----------------------------------------------------------------


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_joints(bad: float) -> None:
    q = np.zeros((5, 6))
    q[2, 3] = bad
    with pytest.raises(
        InputError,
        match=r"^joint_positions contains NaN or inf \(first at pose index 2\)$",
    ) as exc:
        Campaign(JOINTS, q, np.zeros((5, 3)))
    one_line(exc)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_points(bad: float) -> None:
    p = np.zeros((5, 3))
    p[4, 1] = bad
    with pytest.raises(InputError, match=r"^points contains NaN or inf \(first at pose index 4\)$") as exc:
        Campaign(JOINTS, np.zeros((5, 6)), p)
    one_line(exc)


def test_wrong_joint_count_in_campaign() -> None:
    with pytest.raises(InputError, match=r"joint_positions must have shape \(n, 6\), got \(5, 5\)") as exc:
        Campaign(JOINTS, np.zeros((5, 5)), np.zeros((5, 3)))
    one_line(exc)


def test_points_count_mismatch() -> None:
    with pytest.raises(InputError, match=r"points must have shape \(5, 3\), got \(4, 3\)") as exc:
        Campaign(JOINTS, np.zeros((5, 6)), np.zeros((4, 3)))
    one_line(exc)


def test_duplicate_joint_names() -> None:
    with pytest.raises(InputError, match=r"joint_names must be unique and non-empty") as exc:
        Campaign(("a", "a"), np.zeros((1, 2)), np.zeros((1, 3)))
    one_line(exc)


# --- identification ------------------------------------------------------------------------


def test_wrong_joint_names(model, campaign: Campaign) -> None:
    renamed = Campaign(tuple(f"j{i}" for i in range(6)), campaign.joint_positions, campaign.points)
    with pytest.raises(
        InputError,
        match=r"campaign joints \['j0'.*do not match the robot's \['joint1'.*missing",
    ) as exc:
        identify(model, renamed)
    one_line(exc)


def test_wrong_joint_count_in_identify(model, campaign: Campaign) -> None:
    five = Campaign(JOINTS[:5], campaign.joint_positions[:, :5], campaign.points)
    with pytest.raises(InputError, match=r"do not match the robot's .*missing \['joint6'\]") as exc:
        identify(model, five)
    one_line(exc)


def test_permuted_joint_names_are_accepted(model, campaign: Campaign) -> None:
    """Not an error: columns are matched by name (guards the mismatch test above)."""
    order = [5, 3, 1, 0, 2, 4]
    shuffled = Campaign(
        tuple(JOINTS[i] for i in order),
        campaign.joint_positions[:, order],
        campaign.points,
    )
    a = identify(model, shuffled, lambda_=0.0)
    b = identify(model, campaign, lambda_=0.0)
    np.testing.assert_allclose(a.estimate, b.estimate, rtol=0, atol=1e-12)


def test_too_few_poses(model, campaign: Campaign) -> None:
    with pytest.raises(
        IdentifiabilityError,
        match=r"^too few poses: 5 poses give 15 equations for 23 identifiable parameters \(need at least 8 poses\)$",
    ) as exc:
        identify(model, campaign.subset(slice(0, 5)))
    one_line(exc)


def test_degenerate_pose_set(model, campaign: Campaign) -> None:
    same = Campaign(
        JOINTS,
        np.repeat(campaign.joint_positions[:1], 53, axis=0),
        np.repeat(campaign.points[:1], 53, axis=0),
    )
    with pytest.raises(
        IdentifiabilityError,
        match=r"^degenerate pose set: the 53 poses identify only 3 of 23",
    ) as exc:
        identify(model, same)
    one_line(exc)


@pytest.mark.parametrize(
    ("lam", "pattern"),
    [
        (
            "banana",
            r"lambda must be 'auto', 'gcv' or a non-negative number, got 'banana'",
        ),
        (-1, r"lambda must be a finite non-negative number, got -1\.0"),
        ("-1", r"lambda must be a finite non-negative number, got -1\.0"),
        (float("nan"), r"lambda must be a finite non-negative number, got nan"),
        (None, r"lambda must be 'auto', 'gcv' or a non-negative number, got None"),
        (True, r"lambda must be 'auto', 'gcv' or a non-negative number, got True"),
    ],
)
def test_invalid_lambda(model, campaign: Campaign, lam: object, pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern) as exc:
        identify(model, campaign, lambda_=lam)
    one_line(exc)


# --- robot configuration ----------------------------------------------------------------


def write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_unknown_length_unit(tmp_path: Path, paper_dict: dict) -> None:
    paper_dict["units"] = {"length": "inch", "angle": "deg"}
    with pytest.raises(ConfigError, match=r"unknown length unit 'inch' \(known: m, mm, um, µm\)") as exc:
        load_robot_model(write(tmp_path, paper_dict))
    one_line(exc)


def test_unknown_angle_unit_and_missing_unit(paper_dict: dict) -> None:
    bad = copy.deepcopy(paper_dict)
    bad["units"] = {"length": "mm", "angle": "grad"}
    with pytest.raises(ConfigError, match=r"unknown angle unit 'grad' \(known: rad, deg\)") as exc:
        robot_model_from_dict(bad)
    one_line(exc)
    bad["units"] = {"length": "mm"}
    with pytest.raises(ConfigError, match=r"'units' must state 'angle'") as exc:
        robot_model_from_dict(bad)
    one_line(exc)


def test_missing_joints(tmp_path: Path, paper_dict: dict) -> None:
    del paper_dict["joints"]
    path = write(tmp_path, paper_dict)
    with pytest.raises(ConfigError, match=r"robot\.yaml: missing required field 'joints'$") as exc:
        load_robot_model(path)
    one_line(exc)


def test_joint_without_d(tmp_path: Path, paper_dict: dict) -> None:
    del paper_dict["joints"][1]["d"]
    with pytest.raises(ConfigError, match=r"joint 2 is missing 'd'$") as exc:
        load_robot_model(write(tmp_path, paper_dict))
    one_line(exc)


def test_unknown_joint_field_and_convention(paper_dict: dict) -> None:
    bad = copy.deepcopy(paper_dict)
    bad["joints"][0]["offset"] = 1.0
    known = r"\(known: a, alpha, d, limits, name, theta\)$"
    with pytest.raises(ConfigError, match=r"joint 1 has unknown field 'offset' " + known) as exc:
        robot_model_from_dict(bad)
    one_line(exc)
    bad = copy.deepcopy(paper_dict)
    bad["convention"] = "dh"
    with pytest.raises(
        ConfigError,
        match=r"convention must be 'modified_dh' or 'standard_dh', got 'dh'",
    ) as exc:
        robot_model_from_dict(bad)
    one_line(exc)


@pytest.mark.parametrize(
    ("typo", "meant"),
    [("tool_piont", "tool_point"), ("hayati_beta_joint", "hayati_beta_joints"), ("Base", "base")],
)
def test_top_level_typo_is_refused_naming_the_close_match(
    tmp_path: Path, paper_dict: dict, typo: str, meant: str
) -> None:
    """A misspelt optional field used to be ignored: another model, exit 0 (issue 18)."""
    bad = copy.deepcopy(paper_dict)
    bad[typo] = bad.pop(meant) if meant in bad else [0.0, 0.0, 0.1]
    with pytest.raises(ConfigError, match=rf"unknown top-level field '{typo}' \(did you mean '{meant}'\?\)") as exc:
        load_robot_model(write(tmp_path, bad))
    one_line(exc)


def test_unknown_field_without_a_close_match_lists_the_known_ones(paper_dict: dict) -> None:
    bad = copy.deepcopy(paper_dict)
    bad["payload_kg"] = 3.0
    with pytest.raises(ConfigError, match=r"unknown top-level field 'payload_kg' \(known: base, convention, ") as exc:
        robot_model_from_dict(bad)
    one_line(exc)
    bad = copy.deepcopy(paper_dict)
    bad["base"]["xzy"] = [0.0, 0.0, 0.0]
    with pytest.raises(ConfigError, match=r"base has unknown field 'xzy' \(did you mean 'xyz'\?\)"):
        robot_model_from_dict(bad)


def test_malformed_yaml(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("name: x\nconvention: modified_dh\nunits: {length: mm, angle: deg\njoints: []\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml is not valid YAML at line \d+, column \d+: ") as exc:
        load_robot_model(path)
    one_line(exc)


def test_yaml_that_is_not_a_mapping(tmp_path: Path) -> None:
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match=r"expected a mapping at top level, got list") as exc:
        load_robot_model(path)
    one_line(exc)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError,
        match=r"cannot read robot config .*nope\.yaml: No such file or directory",
    ) as exc:
        load_robot_model(tmp_path / "nope.yaml")
    one_line(exc)


def test_non_utf8_file(tmp_path: Path) -> None:
    path = tmp_path / "binary.yaml"
    path.write_bytes(b"\xff\xfe\x00not yaml at all")
    with pytest.raises(ConfigError, match=r"binary\.yaml") as exc:
        load_robot_model(path)
    one_line(exc)


def test_numpy_integer_lambda_is_accepted(model, campaign: Campaign) -> None:
    a = identify(model, campaign, lambda_=np.int64(0))
    b = identify(model, campaign, lambda_=0.0)
    np.testing.assert_array_equal(a.estimate, b.estimate)


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda r: 1.5 * r, r"pose 2 is not a rotation matrix .*det = 3\.375"),
        (lambda r: -r, r"pose 2 is not a rotation matrix .*det = -1"),
        (lambda r: r + 1e-3, r"pose 2 is not a rotation matrix"),
    ],
    ids=["scaled", "reflected", "skewed"],
)
def test_pose_campaign_rejects_non_rotation(edit, pattern: str) -> None:
    from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values, split_pose_values
    from robocal_uncertainty.core.rotation import rotation_exp

    rng = np.random.default_rng(5)
    rotations = rotation_exp(rng.normal(0.0, 1.0, (4, 3)))
    rotations[2] = edit(rotations[2])
    values = pose_values(rng.normal(0.0, 1.0, (4, 3)), rotations)
    meas = PoseMeasurement((1e-5,) * 3, (1e-4,) * 3)
    with pytest.raises(InputError) as excinfo:
        Campaign(JOINTS, np.zeros((4, 6)), values, frame="base", frame_id="base", measurement=meas)
    assert re.search(pattern, one_line(excinfo))
    # A proper rotation with float round-off passes.
    ok = pose_values(split_pose_values(values)[0], rotation_exp(rng.normal(0.0, 1.0, (4, 3))))
    Campaign(JOINTS, np.zeros((4, 6)), ok, frame="base", frame_id="base", measurement=meas)


@pytest.mark.parametrize("std", ["ab", (None, 1.0, 1.0), (1.0, 1.0), (0.0, 1.0, 1.0), (float("nan"), 1.0, 1.0)])
def test_point_std_must_be_three_positive_numbers(std: object) -> None:
    from robocal_uncertainty.core.measurement import PointMeasurement

    with pytest.raises(ConfigError) as excinfo:
        PointMeasurement(std)  # type: ignore[arg-type]
    assert "point std must be three positive finite values [m]" in one_line(excinfo)


@pytest.mark.parametrize("tol", [float("nan"), -1.0, "1e-10", True])
def test_invalid_step_tolerance(model, campaign: Campaign, tol: object) -> None:
    with pytest.raises(ConfigError) as excinfo:
        identify(model, campaign, step_tolerance=tol)  # type: ignore[arg-type]
    assert "step_tolerance must be a finite non-negative number" in one_line(excinfo)


def test_simulation_settings_reject_non_numbers() -> None:
    from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
    from robocal_uncertainty.core.simulation import UnmodelledErrors

    for make in (
        lambda: SimulationSettings(orientation_std="1e-4"),  # type: ignore[arg-type]
        lambda: SimulationSettings(orientation_std=True),  # type: ignore[arg-type]
        lambda: TrackerNoise(a="5e-6"),  # type: ignore[arg-type]
        lambda: TrackerNoise(b=float("nan")),
        lambda: EncoderNoise(half_width=None),  # type: ignore[arg-type]
        lambda: UnmodelledErrors(compliance="0.1"),  # type: ignore[arg-type]
    ):
        with pytest.raises(ConfigError) as excinfo:
            make()
        one_line(excinfo)


@pytest.mark.parametrize(
    ("field", "value"), [("stamp_ns", "abc"), ("stamp_ns", None), ("stamp_ns", 1.5), ("joint_state_count", True)]
)
def test_calibration_sample_integers(field: str, value: object) -> None:
    from robocal_uncertainty.core.sample import CalibrationSample

    kwargs: dict[str, object] = {
        "stamp_ns": 1_700_000_000_000_000_001,
        "frame_id": "tracker",
        "joint_names": ("a",),
        "joint_positions": [0.0],
        "joint_position_std": [0.0],
        "point": [0.0, 0.0, 0.0],
        "point_covariance": np.eye(3),
        "joint_state_count": 3,
        "tracker_point_count": 2,
    }
    assert CalibrationSample(**kwargs).stamp_ns == 1_700_000_000_000_000_001  # type: ignore[arg-type]
    with pytest.raises(InputError) as excinfo:
        CalibrationSample(**{**kwargs, field: value})  # type: ignore[arg-type]
    assert f"{field} must be an integer" in one_line(excinfo)
