"""Fixtures of the ROS 2 node tests (skipped cleanly without ROS 2 or without a colcon build).

Run from a source tree (``python3 -m pytest test/nodes`` puts the repository first on
``sys.path``), ``robocal_uncertainty`` is the source package, which has no generated
``msg`` module; the colcon-installed package directory that has it (found on ``sys.path``
once the workspace is sourced) is then added to the package's ``__path__``, so
``robocal_uncertainty.msg`` and its type support load from the install.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest


def _add_installed_msg_module() -> None:
    import robocal_uncertainty

    try:
        import robocal_uncertainty.msg
    except ImportError:
        pass
    else:
        return
    for entry in sys.path:
        candidate = Path(entry or ".") / "robocal_uncertainty"
        if (candidate / "msg" / "__init__.py").is_file() and str(candidate) not in robocal_uncertainty.__path__:
            robocal_uncertainty.__path__.append(str(candidate))
            return


_add_installed_msg_module()


@pytest.fixture
def ros_context() -> Iterator[object]:
    """An rclpy context of its own on a domain of its own (no cross-talk with other tests)."""
    import rclpy

    context = rclpy.Context()
    domain = int(os.environ.get("ROBOCAL_TEST_DOMAIN_ID", str(100 + os.getpid() % 100)))
    rclpy.init(context=context, domain_id=domain)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
