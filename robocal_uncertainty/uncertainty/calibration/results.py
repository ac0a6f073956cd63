"""What a calibration's Monte Carlo uncertainty evaluation states: frozen result types.

Kept apart from the computation so that the layers which only read a result (reports,
messages, markers) import these types without the trial machinery. Positions are in the
result's output frame [m]; orientations are rotation vectors about the fixed x, y, z axes
of that frame [rad] (the ROS convention of ``geometry_msgs/PoseWithCovariance``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.measurement import POSITION_AXES
from robocal_uncertainty.kernels import BackendInfo
from robocal_uncertainty.montecarlo.engine import AdaptiveReport
from robocal_uncertainty.montecarlo.region import EllipsoidalRegion
from robocal_uncertainty.montecarlo.summary import OutputSummary
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy
from robocal_uncertainty.uncertainty.model_error_draws import FieldEstimate
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = [
    "N_AXES",
    "OUTPUT_FRAMES",
    "ROTATION_AXES",
    "UNDETERMINED_VARIANCE",
    "CalibrationUncertainty",
    "GumPose",
    "OrientationUncertainty",
    "OutputFrame",
    "PoseUncertainty",
]

Array = NDArray[np.float64]
N_AXES = len(POSITION_AXES)
"""Components of an output position: the tool position (x, y, z), whatever is measured."""
OutputFrame = Literal["measurement", "base"]
OUTPUT_FRAMES: tuple[str, ...] = ("measurement", "base")
"""``measurement``: the frame of the campaign's points (the tracker's, or the base when the
campaign is in the base frame); ``base``: the robot base frame."""
ROTATION_AXES: tuple[str, str, str] = ("rx", "ry", "rz")
"""Rotation deviations about the fixed x, y, z axes of the output frame."""
UNDETERMINED_VARIANCE = 1.0e6
"""Variance [rad^2] published for an undetermined rotation direction (ROS "unknown")."""


@dataclass(frozen=True)
class GumPose:
    """First-order GUM propagation for one test configuration (where applicable).

    Attributes
    ----------
    applicable : bool
        False when a non-smooth source (lambda, n_poses, pose_choice) is enabled:
        the law of propagation has no derivative to offer for those.
    estimate : ndarray, shape (3,) [m]
    covariance : ndarray, shape (3, 3) [m^2]
    standard_uncertainty : ndarray, shape (3,) [m]
    coverage_factor : float
        From the normal distribution at the coverage probability.
    expanded_uncertainty : ndarray, shape (3,) [m]
    validated : tuple of bool, length 3
        JCGM 101 §8 check against the Monte Carlo symmetric interval, per axis.
    d_low, d_high : ndarray, shape (3,) [m]
        Endpoint differences of §8.
    delta : ndarray, shape (3,) [m]
        Numerical tolerance used for the check.
    """

    applicable: bool
    estimate: Array
    covariance: Array
    standard_uncertainty: Array
    coverage_factor: float
    expanded_uncertainty: Array
    validated: tuple[bool, ...]
    d_low: Array
    d_high: Array
    delta: Array


@dataclass(frozen=True)
class PoseUncertainty:
    """Uncertainty statement of the tool position at one joint configuration.

    Attributes
    ----------
    joint_positions : ndarray, shape (n_joints,) [rad]
    mean : ndarray, shape (3,) [m]
        Mean of the Monte Carlo tool positions, in the result's output frame
        (:attr:`CalibrationUncertainty.frame_id`).
    covariance : ndarray, shape (3, 3) [m^2]
    axes : tuple of OutputSummary, length 3
        Per-axis x, y, z summaries (standard and expanded uncertainty, coverage factor,
        probabilistically symmetric and shortest intervals, histogram) [m].
    region : EllipsoidalRegion or None
        JCGM 102 hyper-ellipsoidal 3-D coverage region (None if degenerate).
    gum : GumPose
    orientation : OrientationUncertainty or None
        The tool orientation; None when the evaluation was asked for positions only.
    """

    joint_positions: Array
    mean: Array
    covariance: Array
    axes: tuple[OutputSummary, ...]
    region: EllipsoidalRegion | None
    gum: GumPose
    orientation: OrientationUncertainty | None = None

    @property
    def pose_covariance(self) -> Array | None:
        """6x6 covariance of (x, y, z, rx, ry, rz) [m^2, m rad, rad^2], or None without orientation."""
        return None if self.orientation is None else self.orientation.pose_covariance


@dataclass(frozen=True)
class OrientationUncertainty:
    """Uncertainty statement of the tool orientation at one joint configuration.

    Deviations are rotation vectors about the fixed x, y, z axes of the output frame
    (``R_trial = exp([delta]x) R_mean``), the ROS convention of
    ``geometry_msgs/PoseWithCovariance``.

    Attributes
    ----------
    mean_rotation : ndarray, shape (3, 3)
        Chordal L2 mean of the trials' tool rotations, ``output_R_tool``.
    mean_quaternion : ndarray, shape (4,)
        The same as a unit quaternion (x, y, z, w), w >= 0.
    calibrated_rotation : ndarray, shape (3, 3)
        Tool rotation of the calibrated model (the GUM estimate).
    covariance : ndarray, shape (3, 3) [rad^2]
        Monte Carlo covariance of the deviations from the mean (ddof=1).
    axes : tuple of OutputSummary, length 3
        Per-axis (rx, ry, rz) summaries of the deviations from the mean [rad]: standard and
        expanded uncertainty, coverage intervals, histogram.
    pose_covariance : ndarray, shape (6, 6) [m^2, m rad, rad^2]
        Covariance of (x, y, z, rx, ry, rz): position, rotation and their correlation. Its
        position block is :attr:`PoseUncertainty.covariance`.
    determined : tuple of bool, length 3
        Per axis: whether the campaign determines the rotation about it. An undetermined
        axis has no uncertainty statement (its Monte Carlo numbers are not reported).
    undetermined_directions : ndarray, shape (n_undetermined, 3)
        Unit axes (output frame) of the rotations the data cannot determine; empty if none.
    gum : GumPose
        First-order propagation of the smooth sources through the angular Jacobian,
        about :attr:`calibrated_rotation` [rad], validated against the Monte Carlo
        deviations from the same rotation.
    """

    mean_rotation: Array
    mean_quaternion: Array
    calibrated_rotation: Array
    covariance: Array
    axes: tuple[OutputSummary, ...]
    pose_covariance: Array
    determined: tuple[bool, ...]
    undetermined_directions: Array
    gum: GumPose

    @property
    def fully_determined(self) -> bool:
        """True when every rotation axis is determined."""
        return all(self.determined)

    def ros_covariance(
        self, position_covariance: Array, *, undetermined_variance: float = UNDETERMINED_VARIANCE
    ) -> Array:
        """6x6 covariance for ``geometry_msgs/PoseWithCovariance`` (row-major x, y, z, rx, ry, rz).

        The determined part of the Monte Carlo covariance is kept; along each undetermined
        direction ``u`` the rotation gets `undetermined_variance` [rad^2] (``+ s u u^T``) and no
        correlation, so only the components that overlap an undetermined direction are huge.

        Parameters
        ----------
        position_covariance : ndarray, shape (3, 3) [m^2]
        undetermined_variance : float [rad^2]

        Returns
        -------
        ndarray, shape (6, 6) [m^2, m rad, rad^2]
        """
        out = np.array(self.pose_covariance, dtype=np.float64, copy=True)
        out[:3, :3] = position_covariance
        u = np.asarray(self.undetermined_directions, dtype=np.float64).reshape(-1, 3)
        if u.shape[0] == 3:
            # No rotation determined: exactly the stated variance, uncorrelated (u^T u is the
            # identity only to rounding, which left 1e-10 rad^2 cross terms and 1e6 + 2e-10).
            out[3:, :] = 0.0
            out[:, 3:] = 0.0
            out[3:, 3:] = undetermined_variance * np.eye(3)
        elif u.shape[0]:
            proj = np.eye(6)
            proj[3:, 3:] -= u.T @ u
            out = proj @ out @ proj.T
            out[3:, 3:] += undetermined_variance * (u.T @ u)
        return out


@dataclass(frozen=True, eq=False)
class CalibrationUncertainty:
    """Result of :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`.

    Attributes
    ----------
    poses : tuple of PoseUncertainty
        One per test configuration.
    parameter_names : tuple of str
        Names of the estimated parameters.
    parameters : tuple of OutputSummary
        Monte Carlo distribution of each estimated parameter [m or rad].
    calibration : IdentificationResult
        The calibration the uncertainty is about.
    settings : UncertaintySettings
    coverage_probability : float
    n_trials : int
    seed : int
    block_size : int
    adaptive : AdaptiveReport or None
    samples : ndarray, shape (n_trials, 3 n_test + k)
        Positions (output frame) then parameters, per trial.
    rotation_samples : ndarray, shape (n_trials, 3 n_test) [rad], or None
        With orientation: per trial and test configuration, the rotation deviation
        ``log(R_trial R_calibrated^T)`` about the output frame's fixed axes.
    lambda_star : float
        Lambda of the calibration (scaled units).
    lambda_range : (float, float) or None
        Range used by the lambda source.
    frame : {"measurement", "base"}
        Output frame of every position.
    frame_id : str
        Its TF name (the campaign's frame_id, or the model's base frame).
    model_adequacy : ModelAdequacy
        Residuals against the stated noise; the residual source draws what is left over.
    warnings : tuple of str
    not_converged : tuple of str
        Why the run is no statement although it ran (its spread disagrees with its own GUM
        statement: :func:`~robocal_uncertainty.uncertainty.statement_check.gum_disagreements`);
        empty for a statement.
    model_error_field : FieldEstimate or None
        The model-error field estimated for the residual source, drawn when it is
        :attr:`~FieldEstimate.identified` (else the independent model error is drawn); None: no
        model error, or ``model_error="independent"``.
    """

    poses: tuple[PoseUncertainty, ...]
    parameter_names: tuple[str, ...]
    parameters: tuple[OutputSummary, ...]
    calibration: IdentificationResult
    settings: UncertaintySettings
    coverage_probability: float
    n_trials: int
    seed: int
    block_size: int
    adaptive: AdaptiveReport | None
    samples: Array
    lambda_star: float
    lambda_range: tuple[float, float] | None
    frame: OutputFrame
    frame_id: str
    model_adequacy: ModelAdequacy
    warnings: tuple[str, ...] = field(default=())
    rotation_samples: Array | None = None
    not_converged: tuple[str, ...] = field(default=())
    backend: BackendInfo | None = None
    model_error_field: FieldEstimate | None = None

    @property
    def converged(self) -> bool:
        """False when a check failed (:attr:`not_converged`, or the adaptive procedure's); else True.

        A fixed number of trials runs no convergence test: see :attr:`convergence_tested`.
        """
        if self.not_converged:
            return False
        return True if self.adaptive is None else self.adaptive.converged

    @property
    def convergence_tested(self) -> bool:
        """True when a convergence test ran (the adaptive JCGM 101 §7.9 procedure)."""
        return self.adaptive is not None
