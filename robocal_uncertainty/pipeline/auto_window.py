"""One static-pose detector for live streams and recordings: the window learnt from the first dwells.

The default static window (0.5 s) and guards (0.1 s) suit a robot that dwells a second or
more per pose. A recording with shorter dwells finds nothing with them, so ``replay``
shortens them to the dwells it sees (:func:`~robocal_uncertainty.pipeline.replay.auto_collector_settings`).
A live collector cannot see the whole recording, so the rule is causal and the same for both:

* Messages are held (not yet fed to the detector) while the joints' still intervals are
  tracked as they arrive (greedy, in time order, as
  :func:`~robocal_uncertainty.pipeline.replay.still_intervals`).
* Once ``learn_dwells`` closed intervals are dwells (at least a quarter as long as the longest
  so far), the window and guards are decided from those intervals by
  :func:`~robocal_uncertainty.pipeline.replay.auto_collector_settings`, a
  :class:`~robocal_uncertainty.pipeline.collector.StaticPoseCollector` is built with them and
  the held messages are fed to it, in order; every later message goes straight to it.
* The end of the stream (:meth:`AutoWindowCollector.flush`), ``capture_now`` and ``clear``
  decide at once from what has been seen (the open interval included).

The offline ``replay`` and the collector node both feed every message through this class,
so the same messages give the same samples, whether recorded or live. Live, the first
samples come out when the ``learn_dwells``-th dwell ends (a few poses late), and nothing is
lost. With ``auto=False`` the settings are used as given from the first message.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.pipeline.collector import CollectorSettings, LogCallback, StaticPoseCollector

__all__ = ["LEARN_DWELLS", "AutoWindowCollector"]

LEARN_DWELLS = 5
"""Dwells seen before the window is decided."""


class AutoWindowCollector:
    """A :class:`StaticPoseCollector` whose window and guards are learnt from the first dwells.

    Parameters
    ----------
    joint_names : sequence of str
    tracker_frame_id : str
    settings : CollectorSettings
        The settings; with `auto`, their window and guards are upper bounds.
    auto : bool
        Learn the window (see the module docstring); False: use `settings` as given.
    learn_dwells : int
        Dwells seen before deciding.
    log : callable, optional
        As for :class:`StaticPoseCollector`.

    Notes
    -----
    ``add_joint_state``, ``add_tracker_point``, ``add_tracker_pose``, ``capture_now`` and
    ``flush`` return the list of samples they complete (several when held messages are fed
    at the decision). Not thread-safe.
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        tracker_frame_id: str,
        settings: CollectorSettings,
        *,
        auto: bool = True,
        learn_dwells: int = LEARN_DWELLS,
        log: LogCallback | None = None,
    ) -> None:
        self.joint_names = tuple(str(n) for n in joint_names)
        self.tracker_frame_id = tracker_frame_id
        self.requested = settings
        self.learn_dwells = int(learn_dwells)
        self._log = log
        self._held: list[tuple[str, tuple[Any, ...]]] = []
        self._intervals: list[tuple[int, int]] = []
        self._open: tuple[int, int] | None = None  # (first stamp, last stamp) of the open interval
        self._low: np.ndarray | None = None
        self._high: np.ndarray | None = None
        self._last_stamp: int | None = None
        self.collector: StaticPoseCollector | None = None
        # Validates the settings and names at once (a one-line ConfigError).
        probe = StaticPoseCollector.from_settings(self.joint_names, tracker_frame_id, settings)
        if not auto:
            probe._log = log
            self.collector = probe

    # -- state -----------------------------------------------------------------------------

    @property
    def learning(self) -> bool:
        """True while messages are held until the window is decided."""
        return self.collector is None

    @property
    def settings(self) -> CollectorSettings:
        """The settings in use (the requested ones while learning)."""
        return self.requested if self.collector is None else self.collector.settings

    @property
    def held(self) -> int:
        """Messages held while learning."""
        return len(self._held)

    @property
    def dropped(self) -> dict[str, int]:
        """Dropped messages per cause (zeros while learning: held messages are checked at the decision)."""
        if self.collector is None:
            from robocal_uncertainty.pipeline.collector import DROP_CAUSES

            return dict.fromkeys(DROP_CAUSES, 0)
        return self.collector.dropped

    @property
    def rejected_dwells(self) -> int:
        return 0 if self.collector is None else self.collector.rejected_dwells

    @property
    def is_static(self) -> bool:
        return self.collector is not None and self.collector.is_static

    # -- input -----------------------------------------------------------------------------

    def add_joint_state(self, stamp_ns: int, names: Sequence[str], positions: ArrayLike) -> list[CalibrationSample]:
        if self.collector is not None:
            return _listed(self.collector.add_joint_state(stamp_ns, names, positions))
        self._held.append(("add_joint_state", (stamp_ns, names, positions)))
        self._track(int(stamp_ns), names, positions)
        if self._dwells() >= self.learn_dwells:
            return self._decide(include_open=False)
        return []

    def add_tracker_point(self, stamp_ns: int, frame_id: str, xyz: ArrayLike) -> list[CalibrationSample]:
        if self.collector is not None:
            return _listed(self.collector.add_tracker_point(stamp_ns, frame_id, xyz))
        self._held.append(("add_tracker_point", (stamp_ns, frame_id, xyz)))
        return []

    def add_tracker_pose(
        self, stamp_ns: int, frame_id: str, xyz: ArrayLike, quaternion: ArrayLike
    ) -> list[CalibrationSample]:
        if self.collector is not None:
            return _listed(self.collector.add_tracker_pose(stamp_ns, frame_id, xyz, quaternion))
        self._held.append(("add_tracker_pose", (stamp_ns, frame_id, xyz, quaternion)))
        return []

    def capture_now(self) -> list[CalibrationSample]:
        """Decide now if still learning, then capture the current dwell (see the collector's)."""
        out = self._decide(include_open=True) if self.collector is None else []
        assert self.collector is not None
        return out + _listed(self.collector.capture_now())

    def clear(self) -> list[CalibrationSample]:
        """Decide now if still learning (samples of finished dwells are kept), then forget the
        current window and dwell without emitting it."""
        out = self._decide(include_open=True) if self.collector is None else []
        assert self.collector is not None
        self.collector.flush()  # its sample, if any, is the discarded dwell
        return out

    def flush(self) -> list[CalibrationSample]:
        """End of the stream: decide if still learning, then flush the collector."""
        out = self._decide(include_open=True) if self.collector is None else []
        assert self.collector is not None
        return out + _listed(self.collector.flush())

    # -- internals -------------------------------------------------------------------------

    def _track(self, stamp: int, names: Sequence[str], positions: ArrayLike) -> None:
        """Greedy still intervals of the joint states that carry every joint, finite, in time order."""
        index = {str(n): i for i, n in enumerate(names)}
        values = np.asarray(positions, dtype=np.float64).reshape(-1)
        if values.size != len(index) or not all(n in index for n in self.joint_names):
            return
        q = values[[index[n] for n in self.joint_names]]
        if not np.isfinite(q).all() or (self._last_stamp is not None and stamp <= self._last_stamp):
            return
        self._last_stamp = stamp
        if self._open is None or self._low is None or self._high is None:
            self._open, self._low, self._high = (stamp, stamp), q.copy(), q.copy()
            return
        low, high = np.minimum(self._low, q), np.maximum(self._high, q)
        if float((high - low).max()) > self.requested.joint_motion_threshold:
            self._intervals.append(self._open)
            self._open, self._low, self._high = (stamp, stamp), q.copy(), q.copy()
        else:
            self._open, self._low, self._high = (self._open[0], stamp), low, high

    def _dwells(self) -> int:
        """Closed intervals at least a quarter as long as the longest (the dwells so far)."""
        if not self._intervals:
            return 0
        d = np.array([end - start for start, end in self._intervals], dtype=np.int64)
        return int(np.count_nonzero(d >= 0.25 * d.max())) if d.max() > 0 else 0

    def _decide(self, *, include_open: bool) -> list[CalibrationSample]:
        from robocal_uncertainty.pipeline.replay import StillIntervals, auto_collector_settings

        spans = self._intervals + ([self._open] if include_open and self._open is not None else [])
        still = StillIntervals(
            np.array([s for s, _ in spans], dtype=np.int64), np.array([e for _, e in spans], dtype=np.int64)
        )
        settings = auto_collector_settings(self.requested, still)
        collector = StaticPoseCollector.from_settings(self.joint_names, self.tracker_frame_id, settings, log=self._log)
        self.collector = collector
        held, self._held = self._held, []
        out: list[CalibrationSample] = []
        for method, arguments in held:
            out += _listed(getattr(collector, method)(*arguments))
        return out


def _listed(sample: CalibrationSample | None) -> list[CalibrationSample]:
    return [] if sample is None else [sample]
