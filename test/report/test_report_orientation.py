"""report.json: the orientation block of every test configuration (SI units, undetermined axes
without numbers, the ROS 6x6 with huge variance only along the undetermined direction)."""

from __future__ import annotations

import json

import numpy as np

from robocal_uncertainty.report import write_report_json


def test_orientation_block_states_units_and_undetermined_axes(setup, tmp_path) -> None:
    path = tmp_path / "report.json"
    write_report_json(path, setup.result, robot_name="paper_arm", campaign_source="simulated, seed 1")
    data = json.loads(path.read_text())
    assert "orientation" in data["units"]
    assert data["units"]["_rad2"].startswith("square radian")
    pose = setup.result.poses[0]
    block = data["test_configurations"][0]["orientation"]
    np.testing.assert_allclose(block["mean_quaternion_xyzw"], pose.orientation.mean_quaternion)
    assert abs(np.linalg.norm(block["mean_quaternion_xyzw"]) - 1.0) < 1e-12
    # Points only, tool point on joint 6's axis: the rotation about the tool axis is undetermined.
    assert block["determined"] == [False, False, False]
    assert block["undetermined_reason"]
    assert all(a == {"axis": n, "determined": False} for a, n in zip(block["axes"], ("rx", "ry", "rz")))
    assert block["standard_uncertainty_rad"] == [None, None, None]
    ros = np.array(block["ros_pose_covariance"])
    u = np.array(block["undetermined_directions"][0])
    assert ros.shape == (6, 6)
    assert u @ ros[3:, 3:] @ u > 1e5
    assert np.array(block["pose_covariance_m_rad"]).shape == (6, 6)
    assert len(block["gum"]["standard_uncertainty_rad"]) == 3


def test_markdown_report_has_orientation_rows_in_mrad(setup, tmp_path) -> None:
    from robocal_uncertainty.report import write_report

    out = write_report(tmp_path, setup.result, robot_name="paper_arm", embed_images=False)
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "Tool orientation: mean (chordal L2) quaternion" in md
    assert "| u / mrad | undetermined | undetermined | undetermined |" in md
    assert "cannot determine the rotation about" in md
