"""Live ROS 2 tests: the colcon-built package driven by ``ros2 launch``, ``ros2 bag`` and rclpy.

Skipped, with the reason, when ROS 2 is not sourced (no ``ros2`` command or no rclpy) or
when robocal_uncertainty is not built and sourced (``colcon build`` then ``source
install/setup.bash``): a plain ``python -m pytest -q`` never starts anything here.
``.ci/ros_stage.sh`` builds the package in a temporary workspace and runs them through
``colcon test``.

Every process a test starts runs in a process group of its own and is stopped by the test
(SIGINT, then SIGKILL after a timeout). Discovery is limited to localhost and each test
process uses ``ROBOCAL_LIVE_DOMAIN_ID`` (default 17 + pid % 24, within 17-40).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

import pytest


def _why_not() -> str | None:
    if shutil.which("ros2") is None:
        return "ROS 2 is not sourced (no ros2 command): source /opt/ros/jazzy/setup.bash"
    if importlib.util.find_spec("rclpy") is None:
        return "rclpy is not importable: source /opt/ros/jazzy/setup.bash with the Python it was built for"
    prefixes = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    if not any((Path(p) / "share" / "robocal_uncertainty" / "package.xml").is_file() for p in prefixes if p):
        return "robocal_uncertainty is not built and sourced: colcon build && source install/setup.bash"
    return None


REASON = _why_not()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if REASON is None:
        return
    here = Path(__file__).resolve().parent
    for item in items:
        if here in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.skip(reason=f"live ROS tests: {REASON}"))


@pytest.fixture(scope="session")
def ros_env() -> dict[str, str]:
    """The environment of every process the live tests start (and of the test process)."""
    domain = os.environ.get("ROBOCAL_LIVE_DOMAIN_ID") or str(17 + os.getpid() % 24)
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=domain,
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PYTHONUNBUFFERED="1",
        RCUTILS_COLORIZED_OUTPUT="0",
    )
    env.pop("ROS_LOCALHOST_ONLY", None)
    os.environ["ROS_DOMAIN_ID"] = domain  # for rclpy in this process
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env
