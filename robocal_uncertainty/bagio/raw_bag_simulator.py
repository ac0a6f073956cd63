"""Realistic raw recordings of a calibration run, as ``ros2 bag record`` would store them.

From a :class:`~robocal_uncertainty.core.simulation.SimulatedCampaign` (its true robot and
true joint positions), the arm starts at a home pose, moves along smooth joint
trajectories (quintic or cosine time scaling) to each pose in turn, dwells there and
finally returns home. Meanwhile:

* ``/joint_states`` (``sensor_msgs/msg/JointState``) are published at ``joint_rate_hz``:
  true joints plus the encoder noise of the simulation settings, fresh per reading;
* ``/tracker/point`` (``geometry_msgs/msg/PointStamped``) at ``tracker_rate_hz``: true
  tool point in the campaign frame plus the tracker noise (uniform, per reading), except
  during beam dropouts (a Poisson process of random gaps, in motion and in dwells);
* for a 6-DOF campaign (simulated with ``orientation_std``), ``/tracker/pose``
  (``geometry_msgs/msg/PoseStamped``) in place of the points: the same noisy position and
  the true tool orientation turned by a normal rotation vector of ``orientation_std`` [rad]
  per axis (fixed axes, per reading), with the same timing and dropouts.

Header stamps are the sampling times (with a little jitter), log times add a random
transport latency; messages are written in log-time order to one MCAP file (profile
``ros2``, CDR, ``ros2msg`` schemas, zstd chunks, indexed). The ground truth
(static windows with their true joints and true point) is stored as the JSON metadata
record :data:`RAW_TRUTH_METADATA` and read back with :func:`read_raw_truth`. Everything
is deterministic from the seed.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from mcap.writer import CompressionType, Writer
from numpy.typing import NDArray

from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC, POSE_TOPIC
from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
from robocal_uncertainty.bagio.pose_messages import POSE_STAMPED, encode_pose_stamped
from robocal_uncertainty.bagio.ros_messages import (
    JOINT_STATE,
    POINT_STAMPED,
    encode_joint_state,
    encode_point_stamped,
    message_schema,
)
from robocal_uncertainty.core.kinematics import forward_points, forward_poses
from robocal_uncertainty.core.rotation import quaternion_from_matrix, rotation_exp
from robocal_uncertainty.core.simulation import SimulatedCampaign
from robocal_uncertainty.errors import BagError, ConfigError

__all__ = [
    "RAW_TRUTH_METADATA",
    "RawBagSettings",
    "RawBagTruth",
    "RawRecord",
    "StaticWindow",
    "read_raw_truth",
    "simulate_raw_recording",
    "write_raw_bag",
    "write_raw_records",
]

RAW_TRUTH_METADATA = "robocal_raw_truth"
_NS_PER_S = 1_000_000_000
_LIBRARY = "robocal_uncertainty raw bag simulator"
Array = NDArray[np.float64]


@dataclass(frozen=True)
class RawBagSettings:
    """How the raw recording is timed.

    Parameters
    ----------
    joint_rate_hz : float [Hz]
        Joint state rate (robots publish 100-500 Hz).
    tracker_rate_hz : float [Hz]
        Tracker point rate (up to 1 kHz).
    dwell_s : float [s]
        Time the arm stays still at each pose.
    move_s : float [s]
        Duration of each move between poses (also from and back to home).
    profile : {"quintic", "cosine"}
        Time scaling of the moves: quintic (zero velocity and acceleration at both ends)
        or cosine (zero velocity at both ends).
    start_ns : int [ns]
        Stamp of the first sample (ns since the epoch).
    stamp_jitter_s : float [s]
        Sampling times are uniform within +- this around the nominal grid.
    latency_s : (float, float) [s]
        Log time minus stamp is uniform in this range (kept increasing per topic).
    dropout_rate_hz : float [1/s]
        Mean number of tracker beam dropouts per second.
    dropout_s : (float, float) [s]
        Dropout durations are uniform in this range.
    return_home : bool
        End with a move back home (else the recording ends during the last dwell).
    joint_topic, point_topic : str
        Topic names.
    pose_topic : str
        Topic of the tracker poses of a 6-DOF campaign (written instead of `point_topic`).
    """

    joint_rate_hz: float = 125.0
    tracker_rate_hz: float = 500.0
    dwell_s: float = 2.0
    move_s: float = 3.0
    profile: Literal["quintic", "cosine"] = "quintic"
    start_ns: int = 1_700_000_000_000_000_000
    stamp_jitter_s: float = 1e-4
    latency_s: tuple[float, float] = (2e-4, 2e-3)
    dropout_rate_hz: float = 0.2
    dropout_s: tuple[float, float] = (0.02, 0.3)
    return_home: bool = True
    joint_topic: str = JOINT_TOPIC
    point_topic: str = POINT_TOPIC
    pose_topic: str = POSE_TOPIC

    def __post_init__(self) -> None:
        for name in ("joint_rate_hz", "tracker_rate_hz", "dwell_s", "move_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                msg = f"{name} must be a positive finite number, got {value!r}"
                raise ConfigError(msg)
        if self.profile not in ("quintic", "cosine"):
            msg = f"profile must be 'quintic' or 'cosine', got {self.profile!r}"
            raise ConfigError(msg)
        period = 1.0 / max(self.joint_rate_hz, self.tracker_rate_hz)
        if not 0 <= self.stamp_jitter_s < period / 2:
            msg = (
                f"stamp_jitter_s must be in [0, {period / 2:g}) s (half the shortest period), got {self.stamp_jitter_s}"
            )
            raise ConfigError(msg)
        for name in ("latency_s", "dropout_s"):
            low, high = getattr(self, name)
            if not (0 <= low <= high and math.isfinite(high)):
                msg = f"{name} must be a range 0 <= low <= high, got {getattr(self, name)}"
                raise ConfigError(msg)
        if not (math.isfinite(self.dropout_rate_hz) and self.dropout_rate_hz >= 0):
            msg = f"dropout_rate_hz must be >= 0, got {self.dropout_rate_hz}"
            raise ConfigError(msg)
        if isinstance(self.start_ns, bool) or not isinstance(self.start_ns, int) or self.start_ns < 0:
            msg = f"start_ns must be a non-negative integer, got {self.start_ns!r}"
            raise ConfigError(msg)


@dataclass(frozen=True)
class StaticWindow:
    """One true dwell of the arm.

    Parameters
    ----------
    start_ns, end_ns : int [ns]
        Arrival at and departure from the pose (end of recording for a last dwell).
    joint_positions : ndarray, shape (n_joints,) [rad]
        True joint positions.
    point : ndarray, shape (3,) [m]
        True tool point in the recording's frame.
    orientation : ndarray, shape (4,), optional
        6-DOF recordings: true tool orientation in the recording's frame, unit quaternion
        ``(x, y, z, w)``; None for points.
    """

    start_ns: int
    end_ns: int
    joint_positions: Array
    point: Array
    orientation: Array | None = None


@dataclass(frozen=True)
class RawBagTruth:
    """Ground truth of a raw recording.

    Parameters
    ----------
    frame : {"base", "tracker"}
        Frame of the points (as the campaign's).
    frame_id : str
        ``header.frame_id`` of the tracker points.
    joint_names : tuple of str
    windows : tuple of StaticWindow
        One per pose, in time order.
    seed : int
        Seed of the recording's noise and timing.
    settings : dict
        The :class:`RawBagSettings` as a dict.
    joint_count, point_count : int
        Messages written per topic (`point_count`: tracker points, or poses when 6-DOF).
    orientation_std : float or None [rad]
        6-DOF recordings: standard deviation of each rotation-vector component of the
        orientation noise per reading; None for points.
    tracker_topic : str
        Topic of the tracker messages (points, or poses when 6-DOF).
    """

    frame: Literal["base", "tracker"]
    frame_id: str
    joint_names: tuple[str, ...]
    windows: tuple[StaticWindow, ...]
    seed: int
    settings: dict[str, object]
    joint_count: int
    point_count: int
    orientation_std: float | None = None
    tracker_topic: str = POINT_TOPIC

    def to_json(self) -> str:
        """JSON text of the truth (floats round-trip exactly)."""
        content = {
            "frame": self.frame,
            "frame_id": self.frame_id,
            "joint_names": list(self.joint_names),
            "seed": self.seed,
            "settings": self.settings,
            "joint_count": self.joint_count,
            "point_count": self.point_count,
            "orientation_std": self.orientation_std,
            "tracker_topic": self.tracker_topic,
            "units": {
                "stamps": "ns",
                "joint_positions": "rad",
                "point": "m",
                "orientation": "quaternion x, y, z, w",
                "orientation_std": "rad",
            },
            "windows": [
                {
                    "start_ns": w.start_ns,
                    "end_ns": w.end_ns,
                    "joint_positions": w.joint_positions.tolist(),
                    "point": w.point.tolist(),
                    **({} if w.orientation is None else {"orientation": w.orientation.tolist()}),
                }
                for w in self.windows
            ],
        }
        return json.dumps(content, sort_keys=True)


@dataclass(frozen=True)
class RawRecord:
    """One serialised message to write: topic, type, log time [ns] and CDR payload."""

    topic: str
    typename: str
    log_time_ns: int
    data: bytes


def _scaling(tau: Array, profile: str) -> Array:
    """Time scaling s(tau) in [0, 1] of a move, tau in [0, 1] (shape kept)."""
    if profile == "cosine":
        return np.asarray(0.5 - 0.5 * np.cos(np.pi * tau), dtype=np.float64)
    return np.asarray(tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2), dtype=np.float64)


def _trajectory(waypoints: Array, settings: RawBagSettings) -> tuple[Array, NDArray[np.bool_], float]:
    """Dwell/move schedule: segment start times [s], whether each segment is a move, end [s].

    Segments alternate: (move 0 -> 1), dwell 1, move 1 -> 2, ... with waypoint 0 the home
    pose; the recording starts with the first move.
    """
    starts: list[float] = []
    t = 0.0
    kinds: list[bool] = []
    n = waypoints.shape[0]
    for i in range(1, n):
        starts.append(t)
        kinds.append(True)
        t += settings.move_s
        if i < n - 1 or not settings.return_home:
            starts.append(t)
            kinds.append(False)
            t += settings.dwell_s
    return np.array(starts), np.array(kinds, dtype=np.bool_), t


def _joints_at(times: Array, waypoints: Array, settings: RawBagSettings) -> Array:
    """True joint positions (len(times), n_joints) [rad] at `times` [s]."""
    starts, moves, _ = _trajectory(waypoints, settings)
    segment = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, starts.size - 1)
    # Waypoint index reached at the end of each segment.
    step = moves.astype(np.intp)
    target = np.cumsum(step)
    source = target - step
    tau = np.clip((times - starts[segment]) / settings.move_s, 0.0, 1.0)
    s = np.where(moves[segment], _scaling(tau, settings.profile), 1.0)
    q0 = waypoints[source[segment]]
    q1 = waypoints[target[segment]]
    return np.asarray(q0 + (q1 - q0) * s[:, None], dtype=np.float64)


def _sample_times(rng: np.random.Generator, rate: float, duration: float, jitter: float) -> Array:
    period = 1.0 / rate
    grid = rng.uniform(0.0, period) + np.arange(0.0, duration, period)
    grid = grid[grid < duration]
    return grid + rng.uniform(-jitter, jitter, size=grid.size) if jitter > 0 else grid


def _log_times(rng: np.random.Generator, stamps: NDArray[np.int64], latency: tuple[float, float]) -> NDArray[np.int64]:
    delay = np.round(rng.uniform(latency[0], latency[1], size=stamps.size) * _NS_PER_S).astype(np.int64)
    log = stamps + delay
    # Keep each topic's log times strictly increasing (a transport preserves order).
    return np.maximum.accumulate(log - np.arange(log.size)) + np.arange(log.size)


def _beam_times(
    rng_times: np.random.Generator, rng_dropout: np.random.Generator, settings: RawBagSettings, duration: float
) -> Array:
    """Tracker sample times [s] with the beam interruptions (Poisson count, uniform lengths) removed."""
    pt = _sample_times(rng_times, settings.tracker_rate_hz, duration, settings.stamp_jitter_s)
    n_drop = int(rng_dropout.poisson(settings.dropout_rate_hz * duration))
    drop_start = rng_dropout.uniform(0.0, duration, size=n_drop)
    drop_end = drop_start + rng_dropout.uniform(*settings.dropout_s, size=n_drop)
    beam = np.ones(pt.size, dtype=bool)
    for lo, hi in zip(drop_start, drop_end):
        beam &= ~((pt >= lo) & (pt < hi))
    return pt[beam]


def _static_windows(
    simulated: SimulatedCampaign, settings: RawBagSettings, dwell_starts: Array, duration: float, *, six_dof: bool
) -> tuple[StaticWindow, ...]:
    """The true pose of each dwell and the stamps [ns] between which the arm stands still there."""
    model = simulated.true_model
    q_true = simulated.true_joint_positions
    start_ns = settings.start_ns
    true_points, true_rotations = forward_poses(model, model.parameter_vector(), q_true)
    return tuple(
        StaticWindow(
            start_ns=start_ns + round(float(t0) * _NS_PER_S),
            end_ns=start_ns + round(float(min(t0 + settings.dwell_s, duration)) * _NS_PER_S),
            joint_positions=q_true[i],
            point=true_points[i],
            orientation=quaternion_from_matrix(true_rotations[i]) if six_dof else None,
        )
        for i, t0 in enumerate(dwell_starts)
    )


def _measured_points(simulated: SimulatedCampaign, params: Array, q_point: Array, rng: np.random.Generator) -> Array:
    """True tool points [m] at the tracker's sample joints plus the tracker's noise at their distance."""
    sim = simulated.settings
    points = forward_points(simulated.true_model.layout, params, q_point)
    if sim.frame == "tracker":
        distance = np.linalg.norm(points, axis=-1)
    else:
        distance = np.linalg.norm(points - np.asarray(sim.tracker_xyz), axis=-1)
    return points + sim.tracker_noise.sample(rng, distance)


def _pose_records(
    topic: str, frame_id: str, stamps: NDArray[np.int64], log: NDArray[np.int64], xyz: Array, quaternions: Array
) -> list[RawRecord]:
    """One PoseStamped record per tracker sample."""
    return [
        RawRecord(topic, POSE_STAMPED, int(t_log), encode_pose_stamped(int(t), frame_id, x, r))
        for t, t_log, x, r in zip(stamps, log, xyz, quaternions)
    ]


def simulate_raw_recording(
    simulated: SimulatedCampaign,
    settings: RawBagSettings | None = None,
    *,
    seed: int = 0,
) -> tuple[list[RawRecord], RawBagTruth]:
    """Build the messages of a raw recording and its truth (nothing is written).

    Parameters
    ----------
    simulated : SimulatedCampaign
        Its true model, true joint positions (n_poses, n_joints) [rad], frame and noise
        models define the recording.
    settings : RawBagSettings, optional
    seed : int
        Seed of the timing, noise and dropouts.

    Returns
    -------
    records : list of RawRecord
        In log-time order.
    truth : RawBagTruth
    """
    settings = settings or RawBagSettings()
    # A seventh stream for the orientation noise: the first six (and so a point recording)
    # are those of earlier versions.
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(7)]
    rng_joint_t, rng_point_t, rng_encoder, rng_tracker, rng_dropout, rng_latency, rng_rotation = streams
    model = simulated.true_model
    sim = simulated.settings
    q_true = simulated.true_joint_positions
    home = model.joint_limits.mean(axis=1)
    waypoints = np.vstack([home, q_true] + ([home] if settings.return_home else []))
    starts, moves, duration = _trajectory(waypoints, settings)
    jt = _sample_times(rng_joint_t, settings.joint_rate_hz, duration, settings.stamp_jitter_s)
    pt = _beam_times(rng_point_t, rng_dropout, settings, duration)
    params = model.parameter_vector()
    q_joint = _joints_at(jt, waypoints, settings)
    readings = q_joint + sim.encoder_noise.sample_joints(rng_encoder, q_joint.shape, model.prismatic)
    q_point = _joints_at(pt, waypoints, settings)
    measured = _measured_points(simulated, params, q_point, rng_tracker)
    start_ns = settings.start_ns
    joint_stamps = start_ns + np.round(jt * _NS_PER_S).astype(np.int64)
    point_stamps = start_ns + np.round(pt * _NS_PER_S).astype(np.int64)
    joint_log = _log_times(rng_latency, joint_stamps, settings.latency_s)
    point_log = _log_times(rng_latency, point_stamps, settings.latency_s)
    names = model.joint_names
    frame_id = simulated.campaign.frame_id
    records = [
        RawRecord(settings.joint_topic, JOINT_STATE, int(log), encode_joint_state(int(s), names, q))
        for s, log, q in zip(joint_stamps, joint_log, readings)
    ]
    six_dof = sim.orientation_std is not None
    if six_dof:
        _, rotations = forward_poses(model, params, q_point)
        noise = rng_rotation.normal(0.0, float(sim.orientation_std or 0.0), size=(pt.size, 3))
        quaternions = quaternion_from_matrix(rotation_exp(noise) @ rotations)
        records += _pose_records(settings.pose_topic, frame_id, point_stamps, point_log, measured, quaternions)
    else:
        records += [
            RawRecord(settings.point_topic, POINT_STAMPED, int(log), encode_point_stamped(int(s), frame_id, x))
            for s, log, x in zip(point_stamps, point_log, measured)
        ]
    records.sort(key=lambda r: r.log_time_ns)  # stable: ties keep joints first
    windows = _static_windows(simulated, settings, starts[~moves], duration, six_dof=six_dof)
    truth = RawBagTruth(
        frame=sim.frame,
        frame_id=frame_id,
        joint_names=names,
        windows=windows,
        seed=seed,
        settings=asdict(settings),
        joint_count=int(jt.size),
        point_count=int(pt.size),
        orientation_std=sim.orientation_std,
        tracker_topic=settings.pose_topic if six_dof else settings.point_topic,
    )
    return records, truth


def write_raw_records(
    path: str | Path,
    records: list[RawRecord],
    metadata: dict[str, dict[str, str]] | None = None,
    *,
    overwrite: bool = False,
) -> None:
    """Write records (in the given order) to one MCAP file with ``ros2msg`` schemas.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create.
    records : list of RawRecord
        Messages; their header stamps are also used as publish times.
    metadata : dict, optional
        MCAP metadata records by name.
    overwrite : bool
        Replace an existing file.

    Raises
    ------
    BagError
        If the file exists (without `overwrite`) or cannot be written.
    """
    path = Path(path)
    try:
        stream = path.open("wb" if overwrite else "xb")
    except FileExistsError as err:
        msg = f"raw bag {path} exists already (pass overwrite=True to replace it)"
        raise BagError(msg) from err
    except OSError as err:
        msg = f"cannot create raw bag {path}: {err.strerror or err}"
        raise BagError(msg) from err
    with stream:
        # Message indexes are kept: rosbags (and ros2 bag) read messages through them.
        writer = Writer(stream, compression=CompressionType.ZSTD, chunk_size=4 * 1024 * 1024)
        writer.start(profile="ros2", library=_LIBRARY)
        for name, entries in (metadata or {}).items():
            writer.add_metadata(name, entries)
        channels: dict[tuple[str, str], int] = {}
        sequence: dict[int, int] = {}
        for record in records:
            key = (record.topic, record.typename)
            if key not in channels:
                schema = message_schema(record.typename)
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.text.encode("utf-8"))
                channels[key] = writer.register_channel(
                    record.topic, "cdr", schema_id, {"offered_qos_profiles": "", "topic_type_hash": schema.rihs01}
                )
            channel = channels[key]
            sequence[channel] = sequence.get(channel, 0) + 1
            writer.add_message(channel, record.log_time_ns, record.data, record.log_time_ns, sequence[channel])
        writer.finish()


def write_raw_bag(
    path: str | Path,
    simulated: SimulatedCampaign,
    settings: RawBagSettings | None = None,
    *,
    seed: int = 0,
    overwrite: bool = False,
) -> RawBagTruth:
    """Simulate a raw recording of `simulated` and write it with its truth to `path`.

    See :func:`simulate_raw_recording` for the arguments.

    Returns
    -------
    RawBagTruth
        Also stored in the file (metadata record :data:`RAW_TRUTH_METADATA`).
    """
    records, truth = simulate_raw_recording(simulated, settings, seed=seed)
    write_raw_records(path, records, {RAW_TRUTH_METADATA: {"truth": truth.to_json()}}, overwrite=overwrite)
    return truth


def read_raw_truth(path: str | Path) -> RawBagTruth:
    """Read the ground truth stored by :func:`write_raw_bag`.

    Raises
    ------
    BagError
        Not an MCAP file, or no valid truth record in it.
    """
    path = Path(path)
    record = read_mcap_file(path).metadata.get(RAW_TRUTH_METADATA)
    try:
        if record is None:
            raise KeyError(RAW_TRUTH_METADATA)
        content = json.loads(record["truth"])
        windows = tuple(
            StaticWindow(
                start_ns=int(w["start_ns"]),
                end_ns=int(w["end_ns"]),
                joint_positions=np.array(w["joint_positions"], dtype=np.float64),
                point=np.array(w["point"], dtype=np.float64),
                orientation=np.array(w["orientation"], dtype=np.float64) if "orientation" in w else None,
            )
            for w in content["windows"]
        )
        orientation_std = content.get("orientation_std")
        frame: Literal["base", "tracker"] = "base" if content["frame"] == "base" else "tracker"
        return RawBagTruth(
            frame=frame,
            frame_id=str(content["frame_id"]),
            joint_names=tuple(str(n) for n in content["joint_names"]),
            windows=windows,
            seed=int(content["seed"]),
            settings=dict(content["settings"]),
            joint_count=int(content["joint_count"]),
            point_count=int(content["point_count"]),
            orientation_std=None if orientation_std is None else float(orientation_std),
            tracker_topic=str(content.get("tracker_topic", content["settings"].get("point_topic", POINT_TOPIC))),
        )
    except (KeyError, TypeError, ValueError) as err:
        msg = f"{path} has no valid {RAW_TRUTH_METADATA!r} metadata record ({type(err).__name__}: {err})"
        raise BagError(msg) from err
