"""Helpers of the live tests: processes in their own group, stopped for sure; rclpy waiting."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
BASE_BAG = REPO / "test" / "data" / "paper_arm_base_raw.mcap"
PAPER_TEST_JOINTS_DEG = "-7.5005 -234.4840 -106.7448 -92.3875 -61.5425 20.7451"


def add_installed_msg_module() -> None:
    """Let ``robocal_uncertainty.msg`` load from the colcon install when the source tree is first
    on sys.path (pytest run from the repository root)."""
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


def installed_share() -> Path:
    """The package's share directory in the colcon install (config, msg files as installed)."""
    for prefix in os.environ["AMENT_PREFIX_PATH"].split(os.pathsep):
        share = Path(prefix) / "share" / "robocal_uncertainty"
        if (share / "package.xml").is_file():
            return share
    raise AssertionError("robocal_uncertainty is not in AMENT_PREFIX_PATH")


class Proc:
    """A command in a process group of its own, output to a log file; stop() ends the group."""

    def __init__(self, command: list[str], env: dict[str, str], log: Path, cwd: Path | None = None) -> None:
        self.command = command
        self.log = log
        self._file = open(log, "wb")  # noqa: SIM115 (closed in stop)
        self.popen = subprocess.Popen(
            command, env=env, cwd=cwd, stdout=self._file, stderr=subprocess.STDOUT, start_new_session=True
        )

    def text(self) -> str:
        return self.log.read_text(encoding="utf-8", errors="replace")

    def alive(self) -> bool:
        return self.popen.poll() is None

    def kill(self) -> None:
        """SIGKILL the whole group at once (a crash)."""
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait(timeout=10)

    def stop(self, timeout_s: float = 15.0) -> int | None:
        """SIGINT the group (Ctrl-C), SIGKILL it after `timeout_s`; the exit status."""
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGINT)
            try:
                self.popen.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.kill()
        # Children that outlived their parent (the group id stays the leader's pid).
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self._file.close()
        return self.popen.returncode


@contextlib.contextmanager
def started(command: list[str], env: dict[str, str], log: Path, cwd: Path | None = None) -> Iterator[Proc]:
    proc = Proc(command, env, log, cwd)
    try:
        yield proc
    finally:
        proc.stop()


def run(command: list[str], env: dict[str, str], timeout_s: float = 120.0, cwd: Path | None = None) -> str:
    """Run to completion (in its own group, killed at the timeout); stdout + stderr; asserts status 0."""
    proc = subprocess.Popen(
        command, env=env, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        raise AssertionError(f"{' '.join(command)} timed out:\n{out.decode(errors='replace')[-3000:]}") from None
    text = out.decode(errors="replace")
    assert proc.returncode == 0, f"{' '.join(command)} exited {proc.returncode}:\n{text[-3000:]}"
    return text


def play_every_message(bag: Path, topics: tuple[str, ...], env: dict[str, str], folder: Path) -> None:
    """``ros2 bag play`` of ``bag`` after 3 s, ``topics`` kept all and reliable (no sample lost to the QoS)."""
    overrides = folder / "play_qos.yaml"
    keep_all = {"history": "keep_all", "reliability": "reliable", "durability": "volatile"}
    overrides.write_text(json.dumps(dict.fromkeys(topics, keep_all)))
    run(["ros2", "bag", "play", "-d", "3", str(bag), "--qos-profile-overrides-path", str(overrides)], env, 180)


def spin_until(executor: Any, condition: Callable[[], bool], timeout_s: float, what: str = "") -> None:
    """Spin until `condition()` holds; AssertionError naming `what` at the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        executor.spin_once(timeout_sec=0.05)
    assert condition(), f"timed out after {timeout_s:g} s waiting for {what}"


def call(executor: Any, client: Any, request: Any, timeout_s: float = 30.0) -> Any:
    """Call a service and spin until its answer."""
    assert client.wait_for_service(timeout_sec=timeout_s), f"service {client.srv_name} not available"
    future = client.call_async(request)
    spin_until(executor, future.done, timeout_s, f"the answer of {client.srv_name}")
    return future.result()
