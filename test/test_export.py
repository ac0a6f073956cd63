"""export: corrected URDF (pinocchio FK of the written file equals the calibrated model's), UR
kinematics (FK built the way ur_description builds its URDF equals the calibrated model on the
shipped UR10 series), the uncertainty sidecar, the robot_description string, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from robocal_uncertainty.app.export import calibrated_robot_description, export_calibration
from robocal_uncertainty.cli import main
from robocal_uncertainty.core.calibration_file import CALIBRATION_FORMAT, apply_calibration, read_calibration
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_formats import load_robot_source
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix

pin = pytest.importorskip("pinocchio")

ROOT = Path(__file__).resolve().parents[1]
URDF_DIR = ROOT / "test" / "data" / "urdf"
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


def perturbed_calibration(model: RobotModel, seed: int) -> dict[str, object]:
    """A calibration file's content with every parameter moved by about 1 mm / 1 mrad."""
    p0 = model.parameter_vector()
    est = p0 + np.random.default_rng(seed).normal(0.0, 1e-3, p0.size)
    kinds = model.layout.kinds
    return {
        "format": CALIBRATION_FORMAT,
        "robot": "test",
        "model_name": model.name,
        "joint_names": list(model.joint_names),
        "parameters": [
            {
                "name": name,
                "unit": "m" if kinds[i] == "length" else "rad",
                "nominal": float(p0[i]),
                "estimate": float(est[i]),
                "estimated": i % 3 != 0,
                "linearized_std": 1e-5,
            }
            for i, name in enumerate(model.layout.names)
        ],
        "not_identifiable": ["joint1.theta = 1 * base.yaw"],
        "n_poses": 50,
        "residual_rms_before_m": 1.2e-3,
        "residual_rms_after_m": 1.1e-4,
    }


def pinocchio_points(urdf_text: str, base: str, tip: str, names: tuple[str, ...], q: np.ndarray, point: np.ndarray):
    model = pin.buildModelFromXML(urdf_text)
    data = model.createData()
    base_id, tip_id = model.getFrameId(base), model.getFrameId(tip)
    out = []
    for row in q:
        config = pin.neutral(model)
        for value, name in zip(row, names):
            joint = model.joints[model.getJointId(name)]
            if joint.nq == 2:
                config[joint.idx_q : joint.idx_q + 2] = np.cos(value), np.sin(value)
            else:
                config[joint.idx_q] = value
        pin.framesForwardKinematics(model, data, config)
        m = data.oMf[base_id].inverse() * data.oMf[tip_id]
        out.append(m.rotation @ point + m.translation)
    return np.array(out)


def base_frame_points(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """The calibrated model's measured points in its robot base frame (tracker placement left out)."""
    p = model.parameter_vector()
    b0 = model.layout.base_index
    p[b0 : b0 + 6] = 0.0
    return forward_points(model, p, q)


@pytest.mark.parametrize(
    ("robot", "base_link", "tip_link", "base_frame"),
    [
        (str(URDF_DIR / "rail_arm.urdf"), None, None, "floor"),
        (str(URDF_DIR / "panda_arm.urdf"), None, None, "panda_link0"),
        (str(URDF_DIR / "ur10.urdf"), "base_link", "tool0", "base_link"),
        (str(URDF_DIR / "ur10.urdf"), "base", "tool0", "base"),  # a base fixed beside the arm (UR's DH frame)
        ("ur10", None, None, "base"),  # DH model on the shipped ur10.urdf
        ("paper_arm", None, None, "base_link"),  # DH model, URDF generated
    ],
)
def test_exported_urdf_fk_equals_calibrated_model(
    robot: str, base_link: str | None, tip_link: str | None, base_frame: str
) -> None:
    source = load_robot_source(robot, base_link=base_link, tip_link=tip_link)
    data = perturbed_calibration(source.model, seed=5)
    export = export_calibration(data, source, "urdf", where="calibration cal.json")
    calibrated = apply_calibration(source.model, data)
    rng = np.random.default_rng(9)
    q = rng.uniform(calibrated.joint_limits[:, 0], calibrated.joint_limits[:, 1], size=(100, calibrated.n_joints))
    got = pinocchio_points(export.text, base_frame, export.tip_link, calibrated.joint_names, q, export.point_in_tip)
    # Measured: at most 8.2e-14 m (rail_arm), 1.3e-15 m elsewhere.
    assert np.abs(got - base_frame_points(calibrated, q)).max() < 1e-9
    assert "written by robocal-uncertainty export from calibration cal.json" in export.text
    assert "residual RMS 1.2 mm before, 0.11 mm after calibration" in export.text


def test_exported_urdf_keeps_everything_but_movable_origins() -> None:
    source = load_robot_source(str(URDF_DIR / "rail_arm.urdf"))
    export = export_calibration(perturbed_calibration(source.model, seed=2), source, "urdf")
    before = {j.name: j for j in source.urdf.joints}  # type: ignore[union-attr]
    from robocal_uncertainty.core.urdf_model import parse_urdf

    after = {j.name: j for j in parse_urdf(export.text).joints}
    assert before.keys() == after.keys()
    for name, joint in before.items():
        if joint.type == "fixed":
            assert after[name] == joint
        else:
            assert after[name].axis == joint.axis and after[name].lower == joint.lower
            assert after[name].xyz != joint.xyz


def ur_description_fk(kinematics: dict[str, dict[str, float]], q: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Measured point in base_link_inertia the way ur_description builds the UR URDF: each joint
    ``<origin xyz="x y z" rpy="roll pitch yaw"/>`` from the YAML, then a turn about its z axis."""
    out = np.empty((q.shape[0], 3))
    for k, row in enumerate(q):
        t = np.eye(4)
        for key, angle in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"), row):
            v = kinematics[key]
            origin = np.eye(4)
            origin[:3, :3] = rpy_to_matrix(np.array([v["roll"], v["pitch"], v["yaw"]]))
            origin[:3, 3] = v["x"], v["y"], v["z"]
            turn = np.eye(4)
            turn[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
            t = t @ origin @ turn
        out[k] = t[:3, :3] @ point + t[:3, 3]
    return out


def test_ur_kinematics_of_the_shipped_series(
    real_ur10_calibration: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = real_ur10_calibration.calibration
    out = tmp_path / "ur10_kinematics.yaml"
    assert main(["export", str(cal), "--format", "ur-kinematics", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "measured point in wrist_3_link" in printed
    doc = yaml.safe_load(out.read_text())["kinematics"]
    # The header names the calibration in a few short lines: the session record's covariances
    # belong to the sidecar, not to a comment.
    header = [line for line in out.read_text().splitlines() if line.startswith("#")]
    assert any(line.startswith("# session: campaign") for line in header)
    assert max(len(line) for line in header) < 200 and not any("covariance" in line for line in header)
    assert list(doc) == ["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3", "hash"]
    assert all(set(doc[k]) == {"x", "y", "z", "roll", "pitch", "yaw"} for k in list(doc)[:6])
    assert isinstance(doc["hash"], str) and doc["hash"].startswith("calib_")
    sidecar = json.loads((tmp_path / "ur10_kinematics.yaml.uncertainty.json").read_text())
    point = np.array(sidecar["measured_point_in_tip"]["xyz"])
    data = read_calibration(cal)
    calibrated = apply_calibration(load_robot_source("ur10").model, data)
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

    q = read_tracker_csv(UR10_CSV).reorder_joints(calibrated.joint_names).joint_positions
    got = ur_description_fk(doc, q, point)
    want = base_frame_points(calibrated, q)
    # The calibration moved the tool point by millimetres; the export reproduces it exactly
    # (measured 1.1e-15 m over the 632 poses).
    assert np.abs(got - want).max() < 1e-9
    # The same series through the published default kinematics misses by millimetres.
    half_pi = np.pi / 2
    default = {  # the UR10 defaults from the published DH values, as ur_description lays them out
        "shoulder": {"x": 0, "y": 0, "z": 0.1273, "roll": 0, "pitch": 0, "yaw": 0},
        "upper_arm": {"x": 0, "y": 0, "z": 0, "roll": half_pi, "pitch": 0, "yaw": 0},
        "forearm": {"x": -0.612, "y": 0, "z": 0, "roll": 0, "pitch": 0, "yaw": 0},
        "wrist_1": {"x": -0.5723, "y": 0, "z": 0.163941, "roll": 0, "pitch": 0, "yaw": 0},
        "wrist_2": {"x": 0, "y": -0.1157, "z": 0, "roll": half_pi, "pitch": 0, "yaw": 0},
        "wrist_3": {"x": 0, "y": 0.0922, "z": 0, "roll": half_pi, "pitch": np.pi, "yaw": np.pi},
    }
    assert np.abs(ur_description_fk(default, q, point) - want).max() > 5e-4
    # The sidecar: every parameter with its uncertainty and whether the data determine it.
    names = {p["name"] for p in sidecar["parameters"]}
    assert {"joint2.a", "tool.z", "base.yaw"} <= names
    assert any(not p["determined_by_data"] for p in sidecar["parameters"])
    # The covariance travels too (format 2 calibration files): over the estimated parameters,
    # symmetric positive semi-definite, its order named.
    cov = np.array(sidecar["covariance"])
    order = sidecar["covariance_parameters"]
    assert cov.shape == (len(order), len(order)) and set(order) <= names
    assert set(order) == {p["name"] for p in sidecar["parameters"] if p["determined_by_data"]}
    assert np.allclose(cov, cov.T, rtol=0, atol=1e-12 * np.abs(cov).max())
    assert np.linalg.eigvalsh(cov).min() > -1e-9 * np.abs(cov).max()


def test_robot_description_string_from_a_description_parameter() -> None:
    """What the calibration node publishes: the parameter's URDF text with corrected origins."""
    from robocal_uncertainty.core.robot_formats import robot_source_from_description

    text = (URDF_DIR / "panda_arm.urdf").read_text()
    source = robot_source_from_description(text)
    data = perturbed_calibration(source.model, seed=4)
    published = calibrated_robot_description(data, source, urdf_text=text)
    from_file = export_calibration(data, load_robot_source(str(URDF_DIR / "panda_arm.urdf")), "urdf").text
    assert published.split("-->", 1)[1] == from_file.split("-->", 1)[1]


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--format", "ur-kinematics", "--robot", str(URDF_DIR / "panda_arm.urdf")], "needs a Universal Robots chain"),
        (["--format", "yaml", "--robot", str(URDF_DIR / "rail_arm.urdf")], "use --format urdf"),
        (["--format", "urdf", "--robot", "paper_arm"], "cannot be applied to robot 'paper_arm'"),
    ],
)
def test_export_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], match: str
) -> None:
    source = load_robot_source(argv[-1])
    model = source.model if argv[-1] != "paper_arm" else load_robot_source(str(URDF_DIR / "panda_arm.urdf")).model
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(perturbed_calibration(model, seed=1)))
    assert main(["export", str(cal), *argv, "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("robocal-uncertainty export: error: ") and match in err
    assert err.count("\n") == 1


def test_a_calibration_without_covariance_says_so_in_the_sidecar() -> None:
    """Format 1 files state standard uncertainties only: the sidecar says there is no covariance."""
    from robocal_uncertainty.app.export import _covariance

    assert _covariance({"parameters": []}, ["a", "b"])[0] is None
    assert "standard uncertainties only" in _covariance({}, ["a"])[1]
    wrong = {"parameter_covariance": {"names": ["a", "b"], "matrix": [[1.0]]}}
    assert _covariance(wrong, ["a", "b"])[0] is None and "shape (1, 1)" in _covariance(wrong, ["a", "b"])[1]
