"""The install as a ROS user meets it: ``ros2 interface show`` of every message and service
(the .msg/.srv files installed in share/, not links), the command line through ``ros2 run``."""

from __future__ import annotations

import subprocess

import pytest

pytest.importorskip("rclpy", reason="live ROS tests: rclpy is not importable (ROS 2 not sourced)")

from live_support import REPO, installed_share, run

INTERFACES = [
    "msg/CalibrationSample",
    "msg/CalibrationResult",
    "msg/PoseUncertainty",
    "srv/SuggestPoses",
    "srv/CompensateTargets",
]


@pytest.mark.parametrize("name", INTERFACES)
def test_interface_show_prints_the_definition_file(ros_env, name) -> None:
    source = (REPO / f"{name}.{name.split('/')[0]}").read_text(encoding="utf-8")
    installed = installed_share() / f"{name}.{name.split('/')[0]}"
    assert installed.is_file() and not installed.is_symlink(), f"{installed} is missing or a link"
    assert installed.read_text(encoding="utf-8") == source
    shown = run(["ros2", "interface", "show", f"robocal_uncertainty/{name}"], ros_env, timeout_s=60)
    for line in source.splitlines():  # every comment and field, in order (nested types expanded)
        assert line.rstrip() in shown, line
    if name == "srv/SuggestPoses":
        assert "\n---\n" in shown and "cumulative" in shown


def test_command_line_after_colcon_is_the_pip_one(ros_env, tmp_path) -> None:
    installed = run(["ros2", "run", "robocal_uncertainty", "robocal-uncertainty", "--help"], ros_env, timeout_s=60)
    for verb in ("evaluate", "replay", "validate", "suggest", "compensate"):
        assert verb in installed
    # A bad input: the one-line error of the CLI, status 1, no traceback.
    proc = subprocess.run(
        [
            "ros2",
            "run",
            "robocal_uncertainty",
            "robocal-uncertainty",
            "evaluate",
            str(tmp_path / "none.mcap"),
            "--robot",
            "paper_arm",
        ],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 1
    assert "robocal-uncertainty evaluate: error:" in proc.stderr and "Traceback" not in proc.stderr
