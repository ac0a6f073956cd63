"""Static-pose detection: turn joint-state and tracker-point streams into calibration samples.

The arm is *static* at time ``t`` when, over the window ``[t - window_s, t]``,

* at least two joint states arrived, a joint state at or before the window start exists
  (the window is covered), and the peak-to-peak range of every joint is at most
  ``joint_motion_threshold`` [rad], and
* the peak-to-peak range of every coordinate of the tracker points is at most
  ``tracker_scatter_threshold`` [m] (a window with fewer than two points, e.g. during a
  beam dropout, does not veto: the joints alone decide).

A *dwell* starts at the window start of the first static window and ends at the first
message whose window is not static. Each dwell gives at most ONE
:class:`~robocal_uncertainty.pipeline.sample.CalibrationSample`:

* **complete dwell**: as soon as the arm has stayed static until
  ``start + guard_s + average_s + guard_s`` (the settle guard, the averaged span and a
  guard after it, all inside static windows), the sample averaging
  ``[start + guard_s, start + guard_s + average_s]`` is emitted, by the message that
  completes it. Whatever happens afterwards (the arm stays, the stream ends, the arm moves
  on) does not change it: a live collector, which never sees an end of stream, emits the
  last pose of a campaign exactly as a replay does.
* **short dwell** (motion resumes before it is complete): the sample averages
  ``[start + guard_s, end - guard_s]``, emitted by the message that ends the dwell.
* :meth:`flush` (end of the stream) and :meth:`capture_now` emit a dwell that is not
  complete yet at once, over ``[start + guard_s, latest message]``.

6-DOF trackers (:meth:`StaticPoseCollector.add_tracker_pose`, a
``geometry_msgs/PoseStamped`` stream in place of the points): the window is static only if,
besides, every entry of the measured rotation matrices spans at most
``orientation_scatter_threshold`` [rad] (an entry moves by at most the rotation angle, so
this bounds the orientation scatter in rad), and the sample carries the chordal L2 mean of
the orientations (the SVD projection of the mean matrix, not an average of angles or
quaternion components) with the covariance of the mean rotation deviation.

The guards drop the tail of the arrival and the start of the departure, where the arm
moves by less than the thresholds. Too few data in the averaged span (fewer than two
joint states or `min_points` tracker points, e.g. the beam was blocked) rejects the dwell.

The window statistics are incremental (:class:`_StillTracker`): a message costs O(1)
amortised work whatever the window length (plain Python on its few values; numpy only when a
window is reduced, about once per window length), and the decisions are exactly those of
recomputing the peak-to-peak ranges over every window.

Time is message time (header stamps, int ns), never the wall clock, so a replay behaves
exactly like the live run. Bad messages are dropped and counted per cause (see
:data:`DROP_CAUSES`); the collector keeps running.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.campaign import Campaign, PointFrame
from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values
from robocal_uncertainty.core.rotation import (
    chordal_mean,
    quaternion_from_matrix,
    quaternion_to_matrix,
    rotation_log,
)
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import ConfigError, InputError

__all__ = [
    "DROP_CAUSES",
    "CollectorSettings",
    "LogCallback",
    "StaticPoseCollector",
    "samples_to_campaign",
]

LogCallback = Callable[[str, str], None]
"""``log(cause, message)``: one-line report of a dropped message or rejected dwell."""

DROP_CAUSES: tuple[str, ...] = (
    "nan",
    "unknown_joint",
    "missing_joint",
    "duplicate_joint",
    "length_mismatch",
    "wrong_frame",
    "backwards_time",
    "bad_quaternion",
)
"""Why a message is dropped: NaN/inf values; a joint name the collector does not know; a
configured joint absent; a joint name given twice; names and positions (or a point) of
the wrong length; a point in another frame than the tracker frame; a stamp not after the
previous accepted one of the same stream; a tracker orientation that is not a unit
quaternion (tolerance 1e-6)."""

_NS_PER_S = 1_000_000_000


def _floats(values: ArrayLike) -> list[float]:
    """`values` flattened to Python floats, as ``np.asarray(values, float64).reshape(-1)`` gives them."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        floats: list[float] = values.reshape(-1).tolist()
        return floats
    if isinstance(values, (tuple, list)) and all(type(v) is float for v in values):
        return list(values)
    converted: list[float] = np.asarray(values, dtype=np.float64).reshape(-1).tolist()
    return converted


def _seconds_to_ns(name: str, value: float, *, positive: bool) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        msg = f"{name} must be a finite number of seconds, got {value!r}"
        raise ConfigError(msg)
    if value < 0 or (positive and value == 0):
        msg = f"{name} must be {'> 0' if positive else '>= 0'} s, got {value}"
        raise ConfigError(msg)
    return round(value * _NS_PER_S)


@dataclass(frozen=True)
class CollectorSettings:
    """Tuning of :class:`StaticPoseCollector` (everything except names and frame).

    Parameters
    ----------
    window_s : float [s]
        Length of the sliding window that decides whether the arm is static.
    joint_motion_threshold : float [rad]
        Largest peak-to-peak range of any joint over a static window.
    tracker_scatter_threshold : float [m]
        Largest peak-to-peak range of any tracker coordinate over a static window.
    min_points : int
        Fewest tracker points a dwell must average to give a sample (at least 2).
    guard_s : float [s]
        Data dropped at each end of a dwell before averaging (the settle guard).
    average_s : float [s]
        Span averaged per dwell, after the settle guard: a dwell static for
        ``guard_s + average_s + guard_s`` is complete and its sample is emitted at once.
        A shorter dwell is averaged over what it holds when motion resumes.
    log_throttle_s : float [s]
        At most one ``log`` call per cause per this much message time.
    ignore_extra_joints : bool
        Accept joint states carrying joints beyond the configured ones (e.g. a gripper)
        and ignore those; when False such messages are dropped as ``unknown_joint``.
    orientation_scatter_threshold : float [rad]
        6-DOF trackers: largest peak-to-peak range of any rotation-matrix entry over a
        static window (an entry moves by at most the rotation angle).
    """

    window_s: float = 0.5
    joint_motion_threshold: float = 5e-4
    tracker_scatter_threshold: float = 1e-4
    min_points: int = 10
    guard_s: float = 0.1
    average_s: float = 1.0
    log_throttle_s: float = 5.0
    ignore_extra_joints: bool = False
    orientation_scatter_threshold: float = 2e-3

    def __post_init__(self) -> None:
        _seconds_to_ns("window_s", self.window_s, positive=True)
        _seconds_to_ns("guard_s", self.guard_s, positive=False)
        _seconds_to_ns("average_s", self.average_s, positive=True)
        _seconds_to_ns("log_throttle_s", self.log_throttle_s, positive=False)
        for name in ("joint_motion_threshold", "tracker_scatter_threshold", "orientation_scatter_threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                msg = f"{name} must be a positive number, got {value!r}"
                raise ConfigError(msg)
            if not np.isfinite(value):
                msg = f"{name} must be finite, got {value!r}"
                raise ConfigError(msg)
        if isinstance(self.min_points, bool) or not isinstance(self.min_points, int) or self.min_points < 2:
            msg = f"min_points must be an integer >= 2, got {self.min_points!r}"
            raise ConfigError(msg)


Row = list[float]


class _Series:
    """Growing time series: increasing int stamps [ns] and rows of values.

    Kept in Python lists: the collector appends one short row (3, 6 or 9 values) per message
    and asks several positions by bisection, which costs a fraction of the equivalent numpy
    calls on such small pieces; arrays are built only for the rows a window reduction or an
    average needs (:meth:`rows`), with the same values and layout as before.
    """

    def __init__(self, width: int) -> None:
        self.width = width
        self._ts: list[int] = []
        self._rows: list[Row] = []
        self._lo = 0

    def __len__(self) -> int:
        return len(self._ts) - self._lo

    @property
    def stamps(self) -> NDArray[np.int64]:
        """Stamps, shape (n,) [ns] (a copy)."""
        return np.array(self._ts[self._lo :], dtype=np.int64)

    @property
    def values(self) -> NDArray[np.float64]:
        """Values, shape (n, width) (a copy)."""
        return self.rows(0, len(self))

    def rows(self, start: int, stop: int) -> NDArray[np.float64]:
        """Rows start..stop-1 (relative to the current first row) as a C-contiguous array."""
        rows = self._rows[self._lo + start : self._lo + stop]
        return np.array(rows, dtype=np.float64).reshape(len(rows), self.width)

    def append(self, stamp: int, value: Row) -> None:
        if self._lo > 256 and self._lo * 2 > len(self._ts):
            del self._ts[: self._lo]
            del self._rows[: self._lo]
            self._lo = 0
        self._ts.append(stamp)
        self._rows.append(value)

    def index(self, stamp: int, side: Literal["left", "right"] = "left") -> int:
        """Position of `stamp` in the stamps (numpy ``searchsorted`` semantics)."""
        search = bisect_left if side == "left" else bisect_right
        return search(self._ts, stamp, self._lo) - self._lo

    def stamp(self, i: int) -> int:
        """Stamp of row `i` (relative to the current first row) [ns]."""
        return self._ts[self._lo + i]

    def covers(self, stamp: int) -> bool:
        """Whether the first row is stamped at or before `stamp` (False when empty)."""
        return self._lo < len(self._ts) and self._ts[self._lo] <= stamp

    def window(self, stamp: int) -> tuple[int, int]:
        """(position of the first row stamped at or after `stamp`, rows from there on)."""
        i = bisect_left(self._ts, stamp, self._lo)
        return i - self._lo, len(self._ts) - i

    def drop_front(self, count: int) -> None:
        self._lo += count

    def delete(self, start: int, stop: int) -> None:
        """Remove rows start..stop-1 (relative to the current first row)."""
        a, b = self._lo + start, self._lo + stop
        del self._ts[a:b]
        del self._rows[a:b]

    def clear(self) -> None:
        self._lo = 0
        self._ts.clear()
        self._rows.clear()


class _StillTracker:
    """Whether the rows of a sliding time window span at most `threshold` per column.

    Exact and amortised O(1) per row: two facts are remembered between windows.

    * A *run*: every row since `run_start` lies within [run_min, run_max] and
      ``max(run_max - run_min) <= threshold``. While the run holds the whole window (the
      window start only moves forward), the window is still without looking at it.
    * A *block*: rows ``a..b`` of some window span more than `threshold`; every later
      window that still holds row `a` (it ends at or before ``stamp[a] + window``) holds
      ``a..b`` too and cannot be still. `a` is the latest such row.

    Only when neither applies are the window's rows reduced (then the run or the block
    is renewed from them), so a window is reduced about once per window length. The run's
    bounds are Python floats (a row has 3 to 9 values): the same maxima, minima and
    differences as numpy's, without a numpy call per message.
    """

    def __init__(self, threshold: float, window_ns: int) -> None:
        self.threshold = float(threshold)
        self.window_ns = window_ns
        self.reset()

    def reset(self) -> None:
        self._blocked_until: int | None = None
        self._run_start: int | None = None
        self._run_max: Row = []
        self._run_min: Row = []
        self._run_still = False

    def push(self, row: Row) -> None:
        """Extend the run (if any) by a newly appended row."""
        if self._run_start is None:
            return
        high, low = self._run_max, self._run_min
        changed = False
        for i, v in enumerate(row):
            if v > high[i]:
                high[i] = v
                changed = True
            elif v < low[i]:
                low[i] = v
                changed = True
        if changed:
            self._run_still = max([h - lo for h, lo in zip(high, low)]) <= self.threshold

    def still(self, series: _Series, first: int, now: int) -> bool:
        """Whether rows ``first..`` of `series` (the window ending at `now`) are still."""
        if self._blocked_until is not None and now <= self._blocked_until:
            return False
        if self._run_start is not None and self._run_still and self._run_start <= series.stamp(first):
            return True
        values = series.rows(first, len(series))
        high, low = values.max(axis=0), values.min(axis=0)
        if float(np.max(high - low)) <= self.threshold:
            self._run_start, self._run_max, self._run_min = series.stamp(first), high.tolist(), low.tolist()
            self._run_still = True
            return True
        # The latest row `a` such that rows a.. still span more than the threshold.
        backwards = values[::-1]
        spread = np.maximum.accumulate(backwards, axis=0) - np.minimum.accumulate(backwards, axis=0)
        latest = values.shape[0] - 1 - int(np.argmax(spread.max(axis=1) > self.threshold))
        self._blocked_until = series.stamp(first + latest) + self.window_ns
        self._run_start = None
        self._run_max, self._run_min = [], []
        self._run_still = False
        return False


class StaticPoseCollector:
    """Detect static dwells of the arm and emit one averaged sample per dwell.

    Parameters
    ----------
    joint_names : sequence of str, length n_joints
        Joints to average, in the order of the emitted samples.
    tracker_frame_id : str
        ``header.frame_id`` expected on tracker points; others are dropped (``wrong_frame``).
    window_s, joint_motion_threshold, tracker_scatter_threshold, min_points, guard_s,
    average_s, log_throttle_s, ignore_extra_joints
        See :class:`CollectorSettings` (same defaults, same units).
    log : callable, optional
        ``log(cause, message)`` called for dropped messages and rejected dwells, at most
        once per cause per `log_throttle_s` of message time.

    Raises
    ------
    ConfigError
        Bad settings, empty or repeated joint names, empty frame id.

    Notes
    -----
    ``add_joint_state``, ``add_tracker_point``, ``capture_now`` and ``flush`` return the
    sample they complete, or None. Not thread-safe: call from one thread (one ROS
    callback group).
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        *,
        tracker_frame_id: str,
        window_s: float = 0.5,
        joint_motion_threshold: float = 5e-4,
        tracker_scatter_threshold: float = 1e-4,
        min_points: int = 10,
        guard_s: float = 0.1,
        average_s: float = 1.0,
        log_throttle_s: float = 5.0,
        ignore_extra_joints: bool = False,
        log: LogCallback | None = None,
        orientation_scatter_threshold: float = 2e-3,
    ) -> None:
        names = tuple(str(n) for n in joint_names)
        if not names or len(set(names)) != len(names) or not all(names):
            msg = f"joint_names must be unique, non-empty strings, got {list(names)}"
            raise ConfigError(msg)
        if not isinstance(tracker_frame_id, str) or not tracker_frame_id:
            msg = f"tracker_frame_id must be a non-empty string, got {tracker_frame_id!r}"
            raise ConfigError(msg)
        self.settings = CollectorSettings(
            window_s=window_s,
            joint_motion_threshold=joint_motion_threshold,
            tracker_scatter_threshold=tracker_scatter_threshold,
            min_points=min_points,
            guard_s=guard_s,
            average_s=average_s,
            log_throttle_s=log_throttle_s,
            ignore_extra_joints=ignore_extra_joints,
            orientation_scatter_threshold=orientation_scatter_threshold,
        )
        self.joint_names = names
        self.tracker_frame_id = tracker_frame_id
        self._column = {name: j for j, name in enumerate(names)}
        self._window_ns = _seconds_to_ns("window_s", window_s, positive=True)
        self._guard_ns = _seconds_to_ns("guard_s", guard_s, positive=False)
        self._throttle_ns = _seconds_to_ns("log_throttle_s", log_throttle_s, positive=False)
        self._average_ns = _seconds_to_ns("average_s", average_s, positive=True)
        self._log = log
        self._dropped = dict.fromkeys(DROP_CAUSES, 0)
        self._last_logged: dict[str, int] = {}
        self.rejected_dwells = 0
        """Dwells that ended with too few joint states or tracker points to average."""
        self._joints = _Series(len(names))
        self._points = _Series(3)
        self._last_joint: int | None = None
        self._last_point: int | None = None
        self._now: int | None = None
        self._dwell_start: int | None = None
        self._captured = False
        self.emitted = 0
        """Samples emitted (complete, short, captured or flushed dwells)."""
        self._joint_still = _StillTracker(joint_motion_threshold, self._window_ns)
        self._point_still = _StillTracker(tracker_scatter_threshold, self._window_ns)
        # 6-DOF: rotation matrices (row-major, 9 columns) stamped like the points.
        self._rotations = _Series(9)
        self._rotation_still = _StillTracker(orientation_scatter_threshold, self._window_ns)
        # The column order of the last accepted joint-state names (robots repeat them).
        self._last_names: tuple[str, ...] | None = None
        self._last_order: list[int] = []

    @classmethod
    def from_settings(
        cls,
        joint_names: Sequence[str],
        tracker_frame_id: str,
        settings: CollectorSettings,
        *,
        log: LogCallback | None = None,
    ) -> StaticPoseCollector:
        """Build a collector from a :class:`CollectorSettings`."""
        return cls(
            joint_names,
            tracker_frame_id=tracker_frame_id,
            window_s=settings.window_s,
            joint_motion_threshold=settings.joint_motion_threshold,
            tracker_scatter_threshold=settings.tracker_scatter_threshold,
            min_points=settings.min_points,
            guard_s=settings.guard_s,
            average_s=settings.average_s,
            log_throttle_s=settings.log_throttle_s,
            ignore_extra_joints=settings.ignore_extra_joints,
            log=log,
            orientation_scatter_threshold=settings.orientation_scatter_threshold,
        )

    # -- state -----------------------------------------------------------------------------

    @property
    def dropped(self) -> dict[str, int]:
        """Dropped messages per cause (every cause of :data:`DROP_CAUSES`, zeros included)."""
        return dict(self._dropped)

    @property
    def is_static(self) -> bool:
        """True while the arm is in a detected static dwell."""
        return self._dwell_start is not None

    # -- input -----------------------------------------------------------------------------

    def add_joint_state(self, stamp_ns: int, names: Sequence[str], positions: ArrayLike) -> CalibrationSample | None:
        """Take one ``sensor_msgs/JointState``.

        Parameters
        ----------
        stamp_ns : int
            Header stamp [ns since the epoch].
        names : sequence of str
            Joint names of the message.
        positions : array_like, shape (len(names),) [rad]
            Joint positions in the order of `names`.

        Returns
        -------
        CalibrationSample or None
            The sample of a dwell this message ended, if any.
        """
        stamp = int(stamp_ns)
        if self._last_joint is not None and stamp <= self._last_joint:
            return self._drop(
                "backwards_time", stamp, f"joint state stamp {stamp} ns is not after {self._last_joint} ns"
            )
        names = tuple(str(n) for n in names)
        values = _floats(positions)
        if len(values) != len(names):
            return self._drop(
                "length_mismatch", stamp, f"joint state has {len(names)} names but {len(values)} positions"
            )
        if names != self._last_names:
            if len(set(names)) != len(names):
                return self._drop("duplicate_joint", stamp, f"joint state repeats a joint name: {list(names)}")
            unknown = [n for n in names if n not in self._column]
            if unknown and not self.settings.ignore_extra_joints:
                return self._drop("unknown_joint", stamp, f"joint state has unknown joints {unknown}")
            index = {name: i for i, name in enumerate(names)}
            missing = [n for n in self.joint_names if n not in index]
            if missing:
                return self._drop("missing_joint", stamp, f"joint state lacks joints {missing}")
            self._last_names, self._last_order = names, [index[n] for n in self.joint_names]
        q = [values[i] for i in self._last_order]
        if not all(map(math.isfinite, q)):
            return self._drop("nan", stamp, f"joint state has NaN or inf positions {q}")
        self._last_joint = stamp
        self._joints.append(stamp, q)
        self._joint_still.push(q)
        return self._update(stamp)

    def add_tracker_point(self, stamp_ns: int, frame_id: str, xyz: ArrayLike) -> CalibrationSample | None:
        """Take one ``geometry_msgs/PointStamped`` from the tracker.

        Parameters
        ----------
        stamp_ns : int
            Header stamp [ns since the epoch].
        frame_id : str
            Header frame id; must be the configured tracker frame.
        xyz : array_like, shape (3,) [m]
            Measured point.

        Returns
        -------
        CalibrationSample or None
            The sample of a dwell this message ended, if any.
        """
        return self._add_point(int(stamp_ns), frame_id, xyz, None)

    def _add_point(self, stamp: int, frame_id: str, xyz: ArrayLike, rotation: Row | None) -> CalibrationSample | None:
        """Validate and store a tracker position (and, 6-DOF, its rotation matrix, 9 values)."""
        if self._last_point is not None and stamp <= self._last_point:
            return self._drop(
                "backwards_time", stamp, f"tracker point stamp {stamp} ns is not after {self._last_point} ns"
            )
        if frame_id != self.tracker_frame_id:
            return self._drop(
                "wrong_frame", stamp, f"tracker point in frame {frame_id!r}, expected {self.tracker_frame_id!r}"
            )
        point = _floats(xyz)
        if len(point) != 3:
            return self._drop("length_mismatch", stamp, f"tracker point has {len(point)} coordinates, expected 3")
        if not all(map(math.isfinite, point)):
            return self._drop("nan", stamp, f"tracker point has NaN or inf coordinates {point}")
        self._last_point = stamp
        if rotation is not None:
            # Stored with the point, so that its update sees the orientation in the window.
            self._rotations.append(stamp, rotation)
            self._rotation_still.push(rotation)
        self._points.append(stamp, point)
        self._point_still.push(point)
        return self._update(stamp)

    def add_tracker_pose(
        self, stamp_ns: int, frame_id: str, xyz: ArrayLike, quaternion: ArrayLike
    ) -> CalibrationSample | None:
        """Take one ``geometry_msgs/PoseStamped`` from a 6-DOF tracker (instead of points).

        Parameters
        ----------
        stamp_ns : int
            Header stamp [ns since the epoch].
        frame_id : str
            Header frame id; must be the configured tracker frame.
        xyz : array_like, shape (3,) [m]
            Measured position.
        quaternion : array_like, shape (4,)
            Measured orientation ``(x, y, z, w)``; a non-unit one is dropped
            (``bad_quaternion``), NaN as ``nan``.

        Returns
        -------
        CalibrationSample or None
            The sample of a dwell this message ended, if any.
        """
        stamp = int(stamp_ns)
        q = np.array(quaternion, dtype=np.float64).reshape(-1)
        if q.size != 4:
            return self._drop("length_mismatch", stamp, f"tracker orientation has {q.size} components, expected 4")
        if not np.isfinite(q).all():
            return self._drop("nan", stamp, f"tracker orientation has NaN or inf components {q.tolist()}")
        if abs(float(np.linalg.norm(q)) - 1.0) > 1e-6:
            return self._drop(
                "bad_quaternion", stamp, f"tracker orientation is not a unit quaternion (norm {np.linalg.norm(q):.6g})"
            )
        return self._add_point(stamp, frame_id, xyz, quaternion_to_matrix(q).reshape(9).tolist())

    def capture_now(self) -> CalibrationSample | None:
        """Emit the current dwell now (data up to the latest message, no trailing guard).

        Returns
        -------
        CalibrationSample or None
            None when the arm is not static, the dwell was already emitted (it was complete,
            or captured before), or it holds too few data (logged as ``not_static``,
            ``already_captured``, ``rejected_dwell``).
        """
        if self._dwell_start is None or self._now is None:
            self._report("not_static", self._now or 0, "capture requested while the arm is not static")
            return None
        if self._captured:
            self._report("already_captured", self._now, "this dwell was already captured")
            return None
        self._captured = True
        return self._average(self._dwell_start + self._guard_ns, self._now)

    def flush(self) -> CalibrationSample | None:
        """End of the stream: emit the current dwell if not emitted yet, and clear the buffers.

        A complete dwell was emitted when it completed, so this only emits a dwell the
        stream ended in before it was complete (over the data it holds). Stamp
        monotonicity is still checked against the messages before the flush.
        """
        sample = None
        if self._dwell_start is not None and not self._captured and self._now is not None:
            sample = self._average(self._dwell_start + self._guard_ns, self._now)
        self._dwell_start = None
        self._captured = False
        self._joints.clear()
        self._points.clear()
        self._rotations.clear()
        self._joint_still.reset()
        self._point_still.reset()
        self._rotation_still.reset()
        return sample

    # -- internals -------------------------------------------------------------------------

    def _report(self, cause: str, stamp: int, message: str) -> None:
        if self._log is None:
            return
        last = self._last_logged.get(cause)
        if last is not None and stamp - last < self._throttle_ns:
            return
        self._last_logged[cause] = stamp
        self._log(cause, message)

    def _drop(self, cause: str, stamp: int, message: str) -> CalibrationSample | None:
        """Count, report (throttled) and drop a message; always None (no sample)."""
        self._dropped[cause] += 1
        when = stamp if self._now is None else max(stamp, self._now)
        self._report(cause, when, f"dropped: {message} ({self._dropped[cause]} dropped for {cause})")
        return None

    def _window_static(self, now: int) -> bool:
        lo = now - self._window_ns
        joints, points = self._joints, self._points
        if not joints.covers(lo):
            return False  # the window is not covered by joint states yet
        i0, n = joints.window(lo)
        if n < 2 or not self._joint_still.still(joints, i0, now):
            return False
        k0, n = points.window(lo)
        if n >= 2 and not self._point_still.still(points, k0, now):
            return False
        rotations = self._rotations
        r0, n = rotations.window(lo)
        return n < 2 or self._rotation_still.still(rotations, r0, now)

    def _prune(self, now: int) -> None:
        """Drop data no window can need: keep one joint state at or before the window start."""
        lo = now - self._window_ns
        i = self._joints.index(lo, "right") - 1
        if i > 0:
            self._joints.drop_front(i)
        self._points.drop_front(self._points.index(lo))
        self._rotations.drop_front(self._rotations.index(lo))

    def _prune_dwell(self, now: int) -> None:
        """Inside a dwell, drop data between the averaged span and the last window."""
        assert self._dwell_start is not None
        keep_until = self._dwell_start - 1
        if not self._captured:
            keep_until = self._dwell_start + self._guard_ns + self._average_ns
        keep_from = now - self._window_ns - self._guard_ns
        for series in (self._joints, self._points, self._rotations):
            if len(series) < 256:
                continue  # the middle cannot reach 256 rows (the condition below)
            i0, i1 = series.index(keep_until, "right"), series.index(keep_from)
            # Amortised: only compact once the unneeded middle is as large as the rest.
            if i1 - i0 >= max(256, len(series) // 2):
                series.delete(i0, i1)

    def _update(self, stamp: int) -> CalibrationSample | None:
        now = stamp if self._now is None else max(self._now, stamp)
        self._now = now
        static = self._window_static(now)
        if self._dwell_start is None:
            if static:
                self._dwell_start = now - self._window_ns
                self._captured = False
            else:
                self._prune(now)
            return None
        start = self._dwell_start
        span_start = start + self._guard_ns
        span_end = span_start + self._average_ns
        if static:
            sample = None
            if not self._captured and now >= span_end + self._guard_ns:
                # Complete: static through the averaged span and the guard after it.
                self._captured = True
                sample = self._average(span_start, span_end)
            self._prune_dwell(now)
            return sample
        captured = self._captured
        self._dwell_start = None
        self._captured = False
        sample = None if captured else self._average(span_start, now - self._guard_ns)
        self._prune(now)
        return sample

    def _average(self, t0: int, t1: int) -> CalibrationSample | None:
        """Average the data stamped in [t0, min(t1, t0 + average_s)] (None if too few)."""
        t1 = min(t1, t0 + self._average_ns)
        joints, points = self._joints, self._points
        i0, i1 = joints.index(t0), joints.index(t1, "right")
        k0, k1 = points.index(t0), points.index(t1, "right")
        n_joint, n_point = i1 - i0, k1 - k0
        if n_joint < 2 or n_point < self.settings.min_points:
            self.rejected_dwells += 1
            self._report(
                "rejected_dwell",
                t1,
                f"static dwell [{t0}, {t1}] ns has {n_joint} joint states and {n_point} tracker "
                f"points (need 2 and {self.settings.min_points}); no sample",
            )
            return None
        q = joints.rows(i0, i1)
        x = points.rows(k0, k1)
        first = min(joints.stamp(i0), points.stamp(k0))
        last = max(joints.stamp(i1 - 1), points.stamp(k1 - 1))
        orientation = orientation_cov = None
        rotations = self._rotations
        m0, m1 = rotations.index(t0), rotations.index(t1, "right")
        if m1 - m0 >= 2:
            r = rotations.rows(m0, m1).reshape(-1, 3, 3)
            mean = chordal_mean(r)
            deviations = rotation_log(r @ mean.T)
            orientation = quaternion_from_matrix(mean)
            orientation_cov = np.cov(deviations, rowvar=False, ddof=1) / (m1 - m0)
        self.emitted += 1
        return CalibrationSample(
            orientation=orientation,
            orientation_covariance=orientation_cov,
            stamp_ns=first + (last - first) // 2,
            frame_id=self.tracker_frame_id,
            joint_names=self.joint_names,
            joint_positions=q.mean(axis=0),
            joint_position_std=q.std(axis=0, ddof=1),
            point=x.mean(axis=0),
            point_covariance=np.cov(x, rowvar=False, ddof=1) / n_point,
            joint_state_count=n_joint,
            tracker_point_count=n_point,
        )


def samples_to_campaign(
    samples: Sequence[CalibrationSample],
    *,
    frame: PointFrame,
    metadata: dict[str, object] | None = None,
) -> Campaign:
    """Stack samples into a :class:`~robocal_uncertainty.core.campaign.Campaign`.

    Parameters
    ----------
    samples : sequence of CalibrationSample
        All with the same joint names (same order) and frame id.
    frame : {"base", "tracker"}
        Whether the points are in the robot base frame or the tracker frame.
    metadata : dict, optional
        Campaign metadata.

    Returns
    -------
    Campaign
        ``joint_positions`` (n, n_joints) [rad] and ``points`` (n, 3) [m] are the sample
        means; ``point_std`` (n, 3) [m] is the square root of the diagonal of each sample's
        ``point_covariance``, i.e. the standard uncertainty of the MEAN point (not the
        scatter of single tracker readings); ``stamps_ns`` are the sample stamps.

    Raises
    ------
    InputError
        No samples, or samples with differing joint names or frame ids.
    """
    if not samples:
        raise InputError("no calibration samples to build a campaign from")
    first = samples[0]
    for i, sample in enumerate(samples):
        if sample.joint_names != first.joint_names:
            msg = f"sample {i} has joints {list(sample.joint_names)}, sample 0 {list(first.joint_names)}"
            raise InputError(msg)
        if sample.frame_id != first.frame_id:
            msg = f"sample {i} is in frame {sample.frame_id!r}, sample 0 in {first.frame_id!r}"
            raise InputError(msg)
    points = np.array([s.point for s in samples])
    point_std = np.array([s.point_std for s in samples])
    measurement: MeasurementType = POINT
    with_orientation = [s.orientation is not None for s in samples]
    if any(with_orientation):
        if not all(with_orientation):
            missing = with_orientation.index(False)
            msg = f"sample {missing} has no orientation while others have: mixed point and 6-DOF samples"
            raise InputError(msg)
        quaternions = np.array([s.orientation for s in samples], dtype=np.float64)
        rot_std = np.sqrt(np.array([np.diag(np.asarray(s.orientation_covariance)) for s in samples]))
        points = pose_values(points, quaternion_to_matrix(quaternions))
        point_std = np.concatenate((point_std, rot_std), axis=1)
        # Weights: the median standard uncertainty of each axis' mean over the samples
        # (floored at 1e-12 so that noise-free data stay usable).
        median = np.maximum(np.median(point_std, axis=0), 1e-12)
        measurement = PoseMeasurement(
            (float(median[0]), float(median[1]), float(median[2])),
            (float(median[3]), float(median[4]), float(median[5])),
        )
    return Campaign(
        joint_names=first.joint_names,
        joint_positions=np.array([s.joint_positions for s in samples]),
        points=points,
        frame=frame,
        frame_id=first.frame_id,
        point_std=point_std,
        stamps_ns=np.array([s.stamp_ns for s in samples], dtype=np.int64),
        metadata=dict(metadata or {}),
        measurement=measurement,
    )
