"""Simulated calibration campaigns with known truth, for tests, demos and coverage checks.

Noise models follow the seeds: tracker noise uniform within +-a per coordinate (the robot
seed's +-5 um) or within the manufacturer's MPE +-(a + b L) with L the tracker-to-target
distance (the blade seed's form); encoder noise uniform within +-0.005 deg.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.kinematics import forward_points, forward_poses
from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values
from robocal_uncertainty.core.robot_model import RobotModel, rpy_from_matrix, rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_exp
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "EncoderNoise",
    "ParameterErrorRanges",
    "SimulatedCampaign",
    "SimulationSettings",
    "TrackerNoise",
    "UnmodelledErrors",
    "draw_joint_positions",
    "draw_true_parameters",
    "simulate_campaign",
    "simulate_measurements",
]

Array = NDArray[np.float64]


def _real(value: object) -> bool:
    """A real number (not a bool): what the finiteness checks below may compare."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


@dataclass(frozen=True)
class TrackerNoise:
    """Tracker error per coordinate, uniform within +-(a + b * L).

    Parameters
    ----------
    a : float [m]
        Constant part of the half-width (the seed's 5 um).
    b : float [m/m]
        Distance-proportional part; 0 for the plain +-a model.
    """

    a: float = 5e-6
    b: float = 0.0

    def __post_init__(self) -> None:
        if (
            not (_real(self.a) and _real(self.b))
            or not (np.isfinite(self.a) and np.isfinite(self.b))
            or min(self.a, self.b) < 0
        ):
            msg = f"tracker noise a and b must be finite and >= 0, got a={self.a}, b={self.b}"
            raise ConfigError(msg)

    @property
    def kind(self) -> Literal["uniform", "mpe"]:
        """``uniform`` for +-a, ``mpe`` when the half-width grows with distance."""
        return "mpe" if self.b > 0 else "uniform"

    def half_width(self, distance: Array) -> Array:
        """Half-width [m] of the uniform error for targets at `distance` [m]."""
        return self.a + self.b * np.asarray(distance, dtype=np.float64)

    def std(self, distance: Array) -> Array:
        """Standard deviation [m] per coordinate: half-width / sqrt(3)."""
        return np.asarray(self.half_width(distance) / np.sqrt(3.0), dtype=np.float64)

    def sample(self, rng: np.random.Generator, distance: Array) -> Array:
        """Errors of shape (*distance.shape, 3) [m]."""
        half = self.half_width(distance)[..., None]
        return rng.uniform(-1.0, 1.0, size=(*np.shape(distance), 3)) * half


@dataclass(frozen=True)
class EncoderNoise:
    """Joint reading error, uniform within +-half_width [rad] (seed: 0.005 deg)."""

    half_width: float = float(np.radians(0.005))

    def __post_init__(self) -> None:
        if not _real(self.half_width) or not np.isfinite(self.half_width) or self.half_width < 0:
            msg = f"encoder noise half-width must be finite and >= 0, got {self.half_width}"
            raise ConfigError(msg)

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> Array:
        """Errors of the given shape [rad]."""
        return rng.uniform(-self.half_width, self.half_width, size=shape)


@dataclass(frozen=True)
class ParameterErrorRanges:
    """Half-widths of the uniform true parameter errors [m] and [rad].

    The defaults (1 mm, 0.1 deg) give nominal absolute errors of 1-3 mm over the workspace,
    typical of an uncalibrated arm of the seed's size.
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
    readings = true_joint_positions + settings.encoder_noise.sample(rng, true_joint_positions.shape)
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
        metadata={
            "source": "simulation",
            "robot": model.name,
            "seed": seed,
            "n_poses": settings.n_poses,
            "tracker_noise_a_m": settings.tracker_noise.a,
            "tracker_noise_b_m_per_m": settings.tracker_noise.b,
            "encoder_noise_half_width_rad": settings.encoder_noise.half_width,
        },
    )
    return SimulatedCampaign(
        campaign=campaign,
        true_model=true_model,
        true_joint_positions=q_true,
        true_points=forward_points(model.layout, true_params, q_true + settings.unmodelled.deflection(q_true)),
        settings=settings,
        seed=seed,
    )
