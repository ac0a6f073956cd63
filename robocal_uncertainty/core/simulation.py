"""Simulated calibration campaigns with known truth, for tests, demos and coverage checks.

The instruments' error models (tracker MPE +-(a + b L), encoder half-widths) are those of
:mod:`robocal_uncertainty.core.instruments`, the ones the calibration sources draw from.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.instruments.encoders import EncoderNoise
from robocal_uncertainty.core.instruments.laser_tracker import TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points, forward_poses
from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values
from robocal_uncertainty.core.robot_model import RobotModel, rpy_from_matrix, rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_exp
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "ParameterErrorRanges",
    "SessionChange",
    "SessionSimulationSettings",
    "SimulatedCampaign",
    "SimulatedSessions",
    "SimulationSettings",
    "UnmodelledErrors",
    "draw_joint_positions",
    "draw_session_change",
    "draw_true_parameters",
    "session_parameters",
    "simulate_campaign",
    "simulate_measurements",
    "simulate_session",
    "simulate_sessions",
]

Array = NDArray[np.float64]


def _real(value: object) -> bool:
    """A real number (not a bool): what the finiteness checks below may compare."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


@dataclass(frozen=True)
class ParameterErrorRanges:
    """Half-widths of the uniform true parameter errors [m] and [rad].

    The defaults (1 mm, 0.1 deg) give nominal absolute errors of 1-3 mm over the workspace,
    typical of an uncalibrated arm of the reference paper's size.
    """

    length: float = 1e-3
    angle: float = float(np.radians(0.1))
    tool: float = 1e-3


@dataclass(frozen=True)
class UnmodelledErrors:
    """Errors the kinematic model cannot represent (a real robot's model inadequacy).

    Parameters
    ----------
    gear_amplitude : float [rad]
        Transmission error of every joint, ``a sin(2 q_j + j)`` (twice per revolution, as a
        strain-wave gear; phase fixed per joint index j).
    compliance : float [rad]
        Gravity sag of joints 2 and 3: ``c cos(q_2)`` and ``c cos(q_2 + q_3)``.
    """

    gear_amplitude: float = 0.0
    compliance: float = 0.0

    def __post_init__(self) -> None:
        for name in ("gear_amplitude", "compliance"):
            value = getattr(self, name)
            if not _real(value) or not np.isfinite(value) or value < 0:
                msg = f"{name} must be finite and >= 0, got {value}"
                raise ConfigError(msg)

    def deflection(self, joint_positions: Array) -> Array:
        """Angle the joints really take beyond their readings, same shape as the input [rad]."""
        q = np.asarray(joint_positions, dtype=np.float64)
        out = self.gear_amplitude * np.sin(2.0 * q + np.arange(q.shape[-1]))
        if self.compliance and q.shape[-1] >= 3:
            out[..., 1] += self.compliance * np.cos(q[..., 1])
            out[..., 2] += self.compliance * np.cos(q[..., 1] + q[..., 2])
        return out


@dataclass(frozen=True)
class SimulationSettings:
    """Everything that defines a simulated campaign.

    Parameters
    ----------
    n_poses : int
        Number of measured poses.
    frame : {"base", "tracker"}
        Points in the robot base frame, or in a tracker frame with an unknown base.
    tracker_xyz : ndarray, shape (3,) [m]
        Tracker position in the robot base frame (for the MPE distance and the frame).
    tracker_rpy : ndarray, shape (3,) [rad]
        Tracker frame orientation in the robot base frame (used in tracker mode).
    tracker_noise, encoder_noise, errors : see their classes.
    joint_margin : float [rad]
        Poses are drawn uniformly inside the joint limits shrunk by this margin.
    unmodelled : UnmodelledErrors
        Model inadequacy (none by default).
    orientation_std : float [rad], optional
        When given, the campaign is 6-DOF (:class:`PoseMeasurement`): the true model gets a
        tool rotation (uniform within the angle error range about the nominal), and each
        measured orientation is the true one turned by a normal rotation vector of this
        standard deviation per axis (drawn after everything else, so the positions equal
        those of the point-only campaign of the same seed). None (default): points only.
    """

    n_poses: int = 53
    frame: Literal["base", "tracker"] = "base"
    tracker_xyz: tuple[float, float, float] = (2.0, 0.5, 0.3)
    tracker_rpy: tuple[float, float, float] = (0.0, 0.0, float(np.radians(160.0)))
    tracker_noise: TrackerNoise = field(default_factory=TrackerNoise)
    encoder_noise: EncoderNoise = field(default_factory=EncoderNoise)
    errors: ParameterErrorRanges = field(default_factory=ParameterErrorRanges)
    joint_margin: float = float(np.radians(5.0))
    unmodelled: UnmodelledErrors = field(default_factory=UnmodelledErrors)
    orientation_std: float | None = None

    def __post_init__(self) -> None:
        ostd = self.orientation_std
        if ostd is not None and not (_real(ostd) and np.isfinite(ostd) and ostd > 0):
            msg = f"orientation_std must be a positive finite number [rad], got {self.orientation_std!r}"
            raise ConfigError(msg)
        if isinstance(self.n_poses, bool) or not isinstance(self.n_poses, int) or self.n_poses < 1:
            msg = f"n_poses must be a positive integer, got {self.n_poses!r}"
            raise ConfigError(msg)
        if self.frame not in ("base", "tracker"):
            msg = f"frame must be 'base' or 'tracker', got {self.frame!r}"
            raise ConfigError(msg)


@dataclass(frozen=True)
class SimulatedCampaign:
    """A simulated campaign together with the truth that produced it.

    Attributes
    ----------
    campaign : Campaign
        What the instruments reported.
    true_model : RobotModel
        The robot as it really is (nominal + drawn errors, true base).
    true_joint_positions : ndarray, shape (n_poses, n_joints) [rad]
    true_points : ndarray, shape (n_poses, 3) [m]
        Noise-free points in the campaign's frame.
    settings : SimulationSettings
    seed : int or None
    """

    campaign: Campaign
    true_model: RobotModel
    true_joint_positions: Array
    true_points: Array
    settings: SimulationSettings
    seed: int | None


def draw_true_parameters(model: RobotModel, errors: ParameterErrorRanges, *, rng: np.random.Generator) -> Array:
    """Nominal parameter vector plus uniform errors on every joint and tool parameter.

    Returns
    -------
    ndarray, shape (n_params,) [m, rad]
        The base part is left at the model's value.
    """
    layout = model.layout
    p = model.parameter_vector()
    kinds = layout.kinds
    for k, name in enumerate(layout.names):
        if name.startswith("base."):
            continue
        is_tool_point = name.startswith("tool.") and kinds[k] == "length"
        half = errors.tool if is_tool_point else (errors.length if kinds[k] == "length" else errors.angle)
        p[k] += rng.uniform(-half, half)
    return p


def draw_joint_positions(model: RobotModel, n_poses: int, *, rng: np.random.Generator, margin: float = 0.0) -> Array:
    """Joint configurations uniform inside the limits shrunk by `margin`, shape (n, n_joints) [rad]."""
    lo = model.joint_limits[:, 0] + margin
    hi = model.joint_limits[:, 1] - margin
    if (lo >= hi).any():
        msg = f"joint margin {margin} rad leaves no room inside the joint limits"
        raise ConfigError(msg)
    return rng.uniform(lo, hi, size=(n_poses, model.n_joints))


def _tracker_base(settings: SimulationSettings) -> tuple[Array, Array]:
    """world_T_base (xyz, rpy) when world is the tracker frame placed per settings."""
    r_bt = rpy_to_matrix(np.asarray(settings.tracker_rpy))
    t_bt = np.asarray(settings.tracker_xyz, dtype=np.float64)
    r_tb = r_bt.T
    return -r_tb @ t_bt, rpy_from_matrix(r_tb)


def _metadata(model: RobotModel, settings: SimulationSettings, seed: int | None) -> dict[str, object]:
    """What a simulated campaign records of how it was made (noise in SI units)."""
    return {
        "source": "simulation",
        "robot": model.name,
        "seed": seed,
        "n_poses": settings.n_poses,
        "tracker_noise_a_m": settings.tracker_noise.a,
        "tracker_noise_b_m_per_m": settings.tracker_noise.b,
        "encoder_noise_half_width_rad": settings.encoder_noise.half_width,
    }


def simulate_measurements(
    true_params: Array,
    model: RobotModel,
    true_joint_positions: Array,
    settings: SimulationSettings,
    *,
    rng: np.random.Generator,
) -> tuple[Array, Array, Array]:
    """Noisy joint readings and tracker points for given true joints.

    Returns
    -------
    joint_readings : ndarray, shape (n, n_joints) [rad]
    points : ndarray, shape (n, 3) [m]
        Measured points in the frame of `true_params`' base.
    point_std : ndarray, shape (n, 3) [m]
    """
    deflected = true_joint_positions + settings.unmodelled.deflection(true_joint_positions)
    true_points = forward_points(model.layout, true_params, deflected)
    if settings.frame == "tracker":
        distance = np.linalg.norm(true_points, axis=-1)
    else:
        distance = np.linalg.norm(true_points - np.asarray(settings.tracker_xyz), axis=-1)
    noise = settings.tracker_noise.sample(rng, distance)
    readings = true_joint_positions + settings.encoder_noise.sample_joints(
        rng, true_joint_positions.shape, model.prismatic
    )
    std = np.repeat(settings.tracker_noise.std(distance)[:, None], 3, axis=1)
    return readings, true_points + noise, std


def simulate_campaign(
    model: RobotModel,
    settings: SimulationSettings | None = None,
    *,
    seed: int | None = None,
    rng: np.random.Generator | None = None,
) -> SimulatedCampaign:
    """Draw a true robot, poses and noisy measurements.

    Parameters
    ----------
    model : RobotModel
        Nominal model; the truth is nominal plus uniform errors.
    settings : SimulationSettings, optional
    seed : int, optional
        Seed of the generator (ignored when `rng` is given; recorded in the metadata).
    rng : numpy.random.Generator, optional
    """
    settings = settings or SimulationSettings()
    if rng is None:
        rng = np.random.default_rng(seed)
    true_params = draw_true_parameters(model, settings.errors, rng=rng)
    b0 = model.layout.base_index
    if settings.frame == "tracker":
        xyz, rpy = _tracker_base(settings)
        true_params[b0 : b0 + 3] = xyz
        true_params[b0 + 3 : b0 + 6] = rpy
        frame_id = model.measurement_frame_id
    else:
        true_params[b0 : b0 + 6] = 0.0
        frame_id = model.base_frame_id
    q_true = draw_joint_positions(model, settings.n_poses, rng=rng, margin=settings.joint_margin)
    readings, points, std = simulate_measurements(true_params, model, q_true, settings, rng=rng)
    true_model = model.with_parameters(true_params)
    measurement: MeasurementType = POINT
    values = points
    if settings.orientation_std is not None:
        # Drawn last: the robot, poses and points equal those of the point-only campaign.
        half = settings.errors.angle
        tool_rpy = model.tool_rpy + rng.uniform(-half, half, size=3)
        true_model = replace(true_model.with_tool_rotation(), tool_rpy=tool_rpy)
        deflected = q_true + settings.unmodelled.deflection(q_true)
        _, true_rotations = forward_poses(true_model, true_model.parameter_vector(), deflected)
        rot_noise = rng.normal(0.0, settings.orientation_std, size=(settings.n_poses, 3))
        values = pose_values(points, rotation_exp(rot_noise) @ true_rotations)
        pos_std = float(np.mean(std))
        measurement = PoseMeasurement((pos_std,) * 3, (settings.orientation_std,) * 3)
        std = np.concatenate((std, np.full((settings.n_poses, 3), settings.orientation_std)), axis=1)
    campaign = Campaign(
        measurement=measurement,
        joint_names=model.joint_names,
        joint_positions=readings,
        points=values,
        frame=settings.frame,
        frame_id=frame_id,
        point_std=std,
        stamps_ns=np.arange(settings.n_poses, dtype=np.int64) * 10_000_000_000,
        metadata=_metadata(model, settings, seed),
    )
    return SimulatedCampaign(
        campaign=campaign,
        true_model=true_model,
        true_joint_positions=q_true,
        true_points=forward_points(model.layout, true_params, q_true + settings.unmodelled.deflection(q_true)),
        settings=settings,
        seed=seed,
    )


@dataclass(frozen=True)
class SessionChange:
    """What one measurement session changes on a robot (the truth of a simulated session).

    Parameters
    ----------
    tracker_xyz : tuple of 3 float [m]
        Tracker position in the robot base frame.
    tracker_rpy : tuple of 3 float [rad]
        Tracker frame orientation in the robot base frame.
    tool_offset : tuple of 3 float [m]
        Probe (tool point) remount: added to the robot's tool point, flange frame.
    joint_offset_drift : tuple of float [rad], length n_joints
        Added to every joint offset ``theta_j`` (encoder zero drift, re-homing).
    temperature_delta : float [K]
        Temperature difference from the reference session: every joint length parameter
        (``a``, ``d``) is scaled by ``1 + expansion * temperature_delta``.
    """

    tracker_xyz: tuple[float, float, float]
    tracker_rpy: tuple[float, float, float]
    tool_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_offset_drift: tuple[float, ...] = ()
    temperature_delta: float = 0.0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready description, SI units in the names."""
        return {
            "tracker_xyz_m": list(self.tracker_xyz),
            "tracker_rpy_rad": list(self.tracker_rpy),
            "tool_offset_m": list(self.tool_offset),
            "joint_offset_drift_rad": list(self.joint_offset_drift),
            "temperature_delta_K": self.temperature_delta,
        }


@dataclass(frozen=True)
class SessionSimulationSettings:
    """Several measurement sessions of one simulated robot.

    Parameters
    ----------
    n_sessions : int
        Number of sessions (>= 1).
    n_poses : int or tuple of int
        Poses per session (one count for all, or one per session).
    base : SimulationSettings
        Noise models, parameter errors and unmodelled errors shared by all sessions (its
        ``n_poses``, ``frame`` and tracker placement are replaced per session; the frame is
        always ``tracker``).
    tracker_distance : (float, float) [m]
        Range of the horizontal tracker-to-robot distance; the azimuth is uniform over the
        full circle, the tracker looks at the robot (yaw) within ``tracker_yaw_spread``.
    tracker_height : float [m]
        Half-width of the uniform tracker height about the base.
    tracker_level : float [rad]
        Half-width of the uniform roll and pitch (a levelled tripod: small).
    tracker_yaw_spread : float [rad]
        Half-width of the yaw about "looking at the robot".
    tool_remount_std : float [m]
        Standard deviation per axis of the probe remount (0 for the first session).
    joint_offset_std : float [rad]
        Standard deviation of the per-session joint offset drift, every joint (0 for the
        first session: it defines the robot's reference).
    temperature_std : float [K]
        Standard deviation of the temperature difference from the first session.
    expansion : float [1/K]
        Linear expansion coefficient of the links (aluminium 23e-6).
    """

    n_sessions: int = 3
    n_poses: int | tuple[int, ...] = 53
    base: SimulationSettings = field(default_factory=SimulationSettings)
    tracker_distance: tuple[float, float] = (2.0, 3.0)
    tracker_height: float = 0.3
    tracker_level: float = float(np.radians(1.0))
    tracker_yaw_spread: float = float(np.radians(20.0))
    tool_remount_std: float = 50e-6
    joint_offset_std: float = float(np.radians(0.002))
    temperature_std: float = 2.0
    expansion: float = 23e-6

    def __post_init__(self) -> None:
        if isinstance(self.n_sessions, bool) or not isinstance(self.n_sessions, int) or self.n_sessions < 1:
            msg = f"n_sessions must be a positive integer, got {self.n_sessions!r}"
            raise ConfigError(msg)
        counts = self.poses_per_session()
        if len(counts) != self.n_sessions or any(
            isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in counts
        ):
            msg = f"n_poses must be a positive integer or one per session ({self.n_sessions}), got {self.n_poses!r}"
            raise ConfigError(msg)
        for name in (
            "tracker_height",
            "tracker_level",
            "tracker_yaw_spread",
            "tool_remount_std",
            "joint_offset_std",
            "temperature_std",
            "expansion",
        ):
            value = getattr(self, name)
            if not _real(value) or not np.isfinite(value) or value < 0:
                msg = f"{name} must be finite and >= 0, got {value!r}"
                raise ConfigError(msg)
        lo, hi = self.tracker_distance
        if not (_real(lo) and _real(hi) and 0 < lo <= hi and np.isfinite(hi)):
            msg = f"tracker_distance must be (low, high) with 0 < low <= high [m], got {self.tracker_distance!r}"
            raise ConfigError(msg)

    def poses_per_session(self) -> tuple[int, ...]:
        """Pose count of every session."""
        if isinstance(self.n_poses, tuple):
            return self.n_poses
        return (self.n_poses,) * self.n_sessions


@dataclass(frozen=True)
class SimulatedSessions:
    """Sessions of one simulated robot with their truth.

    Attributes
    ----------
    robot_parameters : ndarray, shape (n_params,) [m, rad]
        The robot as it is in the reference (first) session, base part zero (robot base frame).
    changes : tuple of SessionChange
        What each session changed (the first one only places the tracker).
    sessions : tuple of SimulatedCampaign
        Each session's campaign (points in that session's tracker frame) and its true model
        (tracker placement, tool, drift and temperature applied).
    settings : SessionSimulationSettings
    seed : int or None
    """

    robot_parameters: Array
    changes: tuple[SessionChange, ...]
    sessions: tuple[SimulatedCampaign, ...]
    settings: SessionSimulationSettings
    seed: int | None


def draw_session_change(
    model: RobotModel, settings: SessionSimulationSettings, *, rng: np.random.Generator, reference: bool
) -> SessionChange:
    """Draw a tracker placement and (unless `reference`) a remount, drift and temperature."""
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    distance = rng.uniform(*settings.tracker_distance)
    height = rng.uniform(-settings.tracker_height, settings.tracker_height)
    xyz = (distance * np.cos(azimuth), distance * np.sin(azimuth), height)
    level = rng.uniform(-settings.tracker_level, settings.tracker_level, size=2)
    yaw = azimuth + np.pi + rng.uniform(-settings.tracker_yaw_spread, settings.tracker_yaw_spread)
    yaw = float(np.arctan2(np.sin(yaw), np.cos(yaw)))
    tool = rng.normal(0.0, settings.tool_remount_std, size=3)
    drift = rng.normal(0.0, settings.joint_offset_std, size=model.n_joints)
    temperature = float(rng.normal(0.0, settings.temperature_std))
    if reference:
        tool, drift, temperature = np.zeros(3), np.zeros(model.n_joints), 0.0
    return SessionChange(
        tracker_xyz=(float(xyz[0]), float(xyz[1]), float(xyz[2])),
        tracker_rpy=(float(level[0]), float(level[1]), yaw),
        tool_offset=(float(tool[0]), float(tool[1]), float(tool[2])),
        joint_offset_drift=tuple(float(v) for v in drift),
        temperature_delta=temperature,
    )


def session_parameters(model: RobotModel, robot_parameters: Array, change: SessionChange, *, expansion: float) -> Array:
    """True parameter vector of a session: the robot changed by `change`, base = tracker placement.

    Parameters
    ----------
    model : RobotModel
        Nominal model (its layout).
    robot_parameters : ndarray, shape (n_params,) [m, rad]
        The robot in the reference session.
    change : SessionChange
    expansion : float [1/K]

    Returns
    -------
    ndarray, shape (n_params,): base part = world_T_base of the session's tracker frame.
    """
    layout = model.layout
    p = np.array(robot_parameters, dtype=np.float64)
    scale = 1.0 + expansion * change.temperature_delta
    drift = np.zeros(model.n_joints) if not change.joint_offset_drift else np.asarray(change.joint_offset_drift)
    if drift.shape != (model.n_joints,):
        msg = f"joint_offset_drift must have {model.n_joints} values, got {drift.shape[0]}"
        raise ConfigError(msg)
    for j, idx in enumerate(layout.joint_slices()):
        p[idx["theta"]] += drift[j]
        for name in ("a", "d"):
            p[idx[name]] *= scale
    t0 = layout.tool_index
    p[t0 : t0 + 3] += np.asarray(change.tool_offset)
    r_bt = rpy_to_matrix(np.asarray(change.tracker_rpy))
    r_tb = r_bt.T
    b0 = layout.base_index
    p[b0 : b0 + 3] = -r_tb @ np.asarray(change.tracker_xyz)
    p[b0 + 3 : b0 + 6] = rpy_from_matrix(r_tb)
    return p


def simulate_session(
    model: RobotModel,
    robot_parameters: Array,
    change: SessionChange,
    settings: SimulationSettings,
    *,
    expansion: float = 23e-6,
    rng: np.random.Generator,
    seed: int | None = None,
) -> SimulatedCampaign:
    """One session of a known robot: poses and noisy points in the session's tracker frame.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    robot_parameters : ndarray, shape (n_params,) [m, rad]
        The robot in the reference session (see :func:`session_parameters`).
    change : SessionChange
        This session's tracker placement, remount, drift and temperature.
    settings : SimulationSettings
        Noise models, unmodelled errors and ``n_poses`` (its tracker placement and frame are
        taken from `change`, frame ``tracker``).
    rng : numpy.random.Generator
    """
    settings = replace(settings, frame="tracker", tracker_xyz=change.tracker_xyz, tracker_rpy=change.tracker_rpy)
    true_params = session_parameters(model, robot_parameters, change, expansion=expansion)
    q_true = draw_joint_positions(model, settings.n_poses, rng=rng, margin=settings.joint_margin)
    readings, points, std = simulate_measurements(true_params, model, q_true, settings, rng=rng)
    campaign = Campaign(
        joint_names=model.joint_names,
        joint_positions=readings,
        points=points,
        frame="tracker",
        frame_id=model.measurement_frame_id,
        point_std=std,
        stamps_ns=np.arange(settings.n_poses, dtype=np.int64) * 10_000_000_000,
        metadata={**_metadata(model, settings, seed), "session": change.to_dict()},
    )
    deflected = q_true + settings.unmodelled.deflection(q_true)
    return SimulatedCampaign(
        campaign=campaign,
        true_model=model.with_parameters(true_params),
        true_joint_positions=q_true,
        true_points=forward_points(model.layout, true_params, deflected),
        settings=settings,
        seed=seed,
    )


def simulate_sessions(
    model: RobotModel,
    settings: SessionSimulationSettings | None = None,
    *,
    seed: int | None = None,
    rng: np.random.Generator | None = None,
) -> SimulatedSessions:
    """Draw one true robot and several measurement sessions of it.

    The robot (nominal + uniform errors, ``settings.base.errors``) is drawn once. Every
    session places the tracker anew; sessions after the first also remount the probe, drift
    the joint offsets and change the temperature (normal draws with the settings' spreads).

    Parameters
    ----------
    model : RobotModel
    settings : SessionSimulationSettings, optional
    seed : int, optional
        Seed of the generator (ignored when `rng` is given; recorded).
    rng : numpy.random.Generator, optional
    """
    settings = settings or SessionSimulationSettings()
    if rng is None:
        rng = np.random.default_rng(seed)
    robot = draw_true_parameters(model, settings.base.errors, rng=rng)
    b0 = model.layout.base_index
    robot[b0 : b0 + 6] = 0.0
    changes: list[SessionChange] = []
    sessions: list[SimulatedCampaign] = []
    for k, n_poses in enumerate(settings.poses_per_session()):
        change = draw_session_change(model, settings, rng=rng, reference=k == 0)
        base = replace(settings.base, n_poses=n_poses)
        sessions.append(simulate_session(model, robot, change, base, expansion=settings.expansion, rng=rng, seed=seed))
        changes.append(change)
    return SimulatedSessions(
        robot_parameters=robot,
        changes=tuple(changes),
        sessions=tuple(sessions),
        settings=settings,
        seed=seed,
    )
