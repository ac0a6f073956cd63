"""Measurement types: what one measured pose gives, and how it enters the identification.

The identification, the observability analysis, the batched re-identification and the model
adequacy test see a campaign as a stack of equations, ``dimension`` per pose. A measurement
type is everything those loops need to know about one pose's measurement:

``value_size``
    How many numbers store one measured (or predicted) value: 3 for a point; a 6-DOF pose
    may store a position and a rotation matrix (12).
``dimension``
    How many independent equations one pose gives: 3 for a point, 6 for a pose.
``predict`` / ``predict_and_jacobian``
    The value the kinematic chain gives at parameters and joint readings, batched over
    parameter sets and poses, and its Jacobian with respect to the parameters.
``residual`` / ``perturb``
    Measured minus predicted in ``dimension`` coordinates, and its inverse (a value moved by an
    error given in those coordinates). For a point both are plain differences and sums; for a
    rotation the residual is the rotation vector of ``R_measured R_predicted^T`` and
    ``perturb`` applies ``exp``, which is why the loops never subtract values themselves.
``joint_jacobian``
    Jacobian with respect to the joint readings (encoder-noise propagation).
``weights``
    Per component, ``1 / u`` with ``u`` the standard uncertainty in the component's unit:
    rows of the residual and the Jacobian are whitened by it before they are stacked, so a
    6-DOF pose can mix metres and radians. ``None`` leaves the equations unweighted, which is
    today's point identification exactly.

The Jacobian convention makes a Gauss-Newton step independent of the type: for a parameter
step ``dp``, ``residual(m, predict(p + dp)) ~ residual(m, predict(p)) - J dp``, with ``J`` the
Jacobian of the prediction expressed in the residual's coordinates (for a rotation: the
tangent space at the prediction, world frame).

:class:`PointMeasurement` is the first implementation: the tool point in the measurement
frame, computed by :func:`~robocal_uncertainty.core.kinematics.forward_points`. Loops built on
this module give bit-identical numbers to the point-only code they replace.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import NearbyPoints, forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "POINT",
    "POSITION_AXES",
    "MeasurementType",
    "PointMeasurement",
    "joint_columns",
    "row_weights",
    "stack_equations",
    "stack_jacobian",
    "stack_residual",
]

Array = NDArray[np.float64]
POSITION_AXES: tuple[str, str, str] = ("x", "y", "z")
"""Components of a position in the measurement frame."""


def positive_triple(name: str, value: object, unit: str) -> tuple[float, float, float]:
    """Three positive finite floats from `value`, or a one-line ConfigError naming `name` and `unit`."""
    msg = f"{name} must be three positive finite values [{unit}], got {value!r}"
    try:
        out = tuple(float(s) for s in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as err:
        raise ConfigError(msg) from err
    if len(out) != 3 or not all(np.isfinite(s) and s > 0 for s in out):
        raise ConfigError(msg)
    return (out[0], out[1], out[2])


def joint_columns(layout: ParameterLayout) -> list[int]:
    """Indices of the joint offsets (``theta_j``, ``d_j`` for a prismatic joint), in joint order.

    In the modified DH chain a joint reading ``q_j`` enters only as ``q_j + theta_j`` (a
    prismatic one as ``q_j + d_j``), so the Jacobian of any measurement with respect to ``q_j``
    is its column for that offset.
    """
    return [idx["d" if layout.is_prismatic(j) else "theta"] for j, idx in enumerate(layout.joint_slices())]


class MeasurementType(ABC):
    """What one pose of a campaign measures; see the module docstring for the contract.

    Implementations are immutable and picklable (frozen dataclasses): they travel with the
    trial blocks of a Monte Carlo to other processes.
    """

    @property
    @abstractmethod
    def name(self) -> str:
        """Short identifier, e.g. ``"point"``."""

    @property
    @abstractmethod
    def quantity(self) -> str:
        """What is measured, for messages, e.g. ``"measured point"``."""

    @property
    @abstractmethod
    def dimension(self) -> int:
        """Equations per pose: the length of a residual."""

    @property
    @abstractmethod
    def value_size(self) -> int:
        """Numbers per stored measured or predicted value."""

    @property
    @abstractmethod
    def component_names(self) -> tuple[str, ...]:
        """Name of each residual component, length `dimension`."""

    @property
    @abstractmethod
    def component_units(self) -> tuple[str, ...]:
        """SI unit of each residual component, length `dimension` (``"m"`` or ``"rad"``)."""

    @property
    def weights(self) -> Array | None:
        """Whitening factor ``1 / u`` per residual component, shape (dimension,) [1/unit].

        None (the default): every equation has weight 1, in its own unit.
        """
        return None

    @property
    def measures_orientation(self) -> bool:
        """Whether the values hold an orientation (then the tool rotation is identifiable).

        False by default; the identification adds ``tool.rx, tool.ry, tool.rz`` to the model's
        parameters when it is true.
        """
        return False

    @abstractmethod
    def predict(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        """Predicted values for every (parameter set, pose) pair.

        Parameters
        ----------
        layout : ParameterLayout
        params : ndarray, shape (..., n_params) [m, rad]
            Leading dimensions broadcast against those of `joint_positions`.
        joint_positions : ndarray, shape (..., n_poses, n_joints) [rad]

        Returns
        -------
        ndarray, shape (..., n_poses, value_size)
        """

    @abstractmethod
    def predict_and_jacobian(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> tuple[Array, Array]:
        """Predicted values and their Jacobian with respect to the parameters.

        Returns
        -------
        values : ndarray, shape (..., n_poses, value_size)
        jacobian : ndarray, shape (..., n_poses, dimension, n_params) [unit/m, unit/rad]
            In the residual's coordinates: ``residual(m, predict(p + dp)) ~
            residual(m, predict(p)) - jacobian @ dp``.
        """

    def nearby_predictor(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Callable[[Array, Array], Array] | None:
        """A faster :meth:`predict` for parameters and readings close to a reference, or None.

        Re-identification in a Monte Carlo evaluates the chain at micro-perturbations of the
        calibration (`params`, shape (n_params,)) and its readings (`joint_positions`, shape
        (n_poses, n_joints)); a type may return a callable ``f(params, joint_positions)`` with
        the shapes and values of :meth:`predict` (to a few ulps) that exploits this. None (the
        default): use :meth:`predict`.
        """
        _ = layout, params, joint_positions
        return None

    def residual(self, measured: Array, predicted: Array) -> Array:
        """Measured minus predicted, shape (..., n_poses, dimension).

        Parameters
        ----------
        measured, predicted : ndarray, shape (..., n_poses, value_size)
            Broadcast against each other.
        """
        return measured - predicted

    def perturb(self, values: Array, errors: Array) -> Array:
        """Values moved by errors in residual coordinates, so ``residual(perturb(v, e), v) = e``.

        Parameters
        ----------
        values : ndarray, shape (..., n_poses, value_size)
        errors : ndarray, shape (..., n_poses, dimension)

        Returns
        -------
        ndarray, shape of the broadcast of both, last axis value_size
        """
        return values + errors

    def joint_jacobian(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        """Jacobian of the prediction with respect to the joint readings.

        Returns
        -------
        ndarray, shape (..., n_poses, dimension, n_joints) [unit/rad]
        """
        _, jac = self.predict_and_jacobian(layout, params, joint_positions)
        return jac[..., joint_columns(layout)]

    def instrument_covariance(self, position_std: Array) -> Array:
        """Covariance of each pose's measured components from the instrument's position noise.

        Parameters
        ----------
        position_std : ndarray, shape (n_poses,) [m]
            Standard deviation of each measured coordinate of a position.

        Returns
        -------
        ndarray, shape (n_poses, dimension, dimension) [unit^2]
            The default assumes every component is one position coordinate.
        """
        return np.eye(self.dimension) * (np.asarray(position_std, dtype=np.float64) ** 2)[:, None, None]

    def check_values(self, values: Array) -> None:
        """Raise :class:`~robocal_uncertainty.errors.InputError` when finite `values` are not valid.

        Called by :class:`~robocal_uncertainty.core.campaign.Campaign` on its measured values
        (shape (n_poses, value_size), already finite). Nothing to check by default.
        """
        _ = values

    def positions(self, values: Array) -> Array | None:
        """3-D positions in the measurement frame held by `values`, or None if they hold none.

        Used where a 3-D position is needed beside the equations: the rigid-fit start of an
        unknown base, the distance from the tracker.

        Parameters
        ----------
        values : ndarray, shape (..., n_poses, value_size)

        Returns
        -------
        ndarray, shape (..., n_poses, 3) [m], or None
        """
        return None


def row_weights(measurement: MeasurementType, n_poses: int) -> Array | None:
    """Whitening factor of every stacked equation, shape (n_poses * dimension,), or None."""
    w = measurement.weights
    return None if w is None else np.tile(w, n_poses)


def stack_residual(measurement: MeasurementType, residual: Array) -> Array:
    """Per-pose residuals as whitened equations.

    Parameters
    ----------
    measurement : MeasurementType
    residual : ndarray, shape (..., n_poses, dimension)

    Returns
    -------
    ndarray, shape (..., n_poses * dimension)
        Multiplied component-wise by ``measurement.weights`` when it is not None; a plain
        reshape otherwise.
    """
    n_poses = residual.shape[-2]
    r = residual.reshape(*residual.shape[:-2], n_poses * residual.shape[-1])
    w = row_weights(measurement, n_poses)
    return r if w is None else r * w


def stack_jacobian(measurement: MeasurementType, jacobian: Array, columns: NDArray[np.intp] | None = None) -> Array:
    """Per-pose Jacobians as the rows of whitened equations.

    Parameters
    ----------
    measurement : MeasurementType
    jacobian : ndarray, shape (..., n_poses, dimension, m)
    columns : ndarray of int, shape (k,), optional
        Columns to keep (e.g. the estimated parameters); all when None. They are selected
        after stacking, which keeps the memory layout (and so the LAPACK rounding) of the
        point-only code this replaces.

    Returns
    -------
    ndarray, shape (..., n_poses * dimension, k)
        Rows multiplied by ``measurement.weights`` when it is not None.
    """
    n_poses = jacobian.shape[-3]
    a = jacobian.reshape(*jacobian.shape[:-3], n_poses * jacobian.shape[-2], jacobian.shape[-1])
    if columns is not None:
        a = a[..., columns]
    w = row_weights(measurement, n_poses)
    return a if w is None else a * w[:, None]


def stack_equations(
    measurement: MeasurementType, residual: Array, jacobian: Array, columns: NDArray[np.intp] | None = None
) -> tuple[Array, Array]:
    """:func:`stack_residual` and :func:`stack_jacobian` of one linearisation."""
    return stack_residual(measurement, residual), stack_jacobian(measurement, jacobian, columns)


@dataclass(frozen=True)
class PointMeasurement(MeasurementType):
    """The tool point measured in the measurement (tracker) frame: 3 equations per pose.

    Parameters
    ----------
    std : tuple of 3 float [m], optional
        Standard uncertainty of each coordinate. When given, the equations are whitened by it;
        None (the default) weighs every coordinate 1 in metres, as the identification always
        has (the result then does not depend on an absolute noise level).
    """

    std: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.std is not None:
            object.__setattr__(self, "std", positive_triple("point std", self.std, "m"))

    @property
    def name(self) -> str:
        """``"point"``."""
        return "point"

    @property
    def quantity(self) -> str:
        """``"measured point"``."""
        return "measured point"

    @property
    def dimension(self) -> int:
        """3 (x, y, z)."""
        return len(POSITION_AXES)

    @property
    def value_size(self) -> int:
        """3 (x, y, z) [m]."""
        return len(POSITION_AXES)

    @property
    def component_names(self) -> tuple[str, ...]:
        """``("x", "y", "z")``."""
        return POSITION_AXES

    @property
    def component_units(self) -> tuple[str, ...]:
        """``("m", "m", "m")``."""
        return ("m",) * len(POSITION_AXES)

    @property
    def weights(self) -> Array | None:
        """``1 / std`` per coordinate [1/m], or None when no std is given."""
        return None if self.std is None else 1.0 / np.asarray(self.std, dtype=np.float64)

    def predict(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        """Tool points [m], shape (..., n_poses, 3); see :func:`forward_points`."""
        return forward_points(layout, params, joint_positions)

    def predict_and_jacobian(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> tuple[Array, Array]:
        """Tool points [m] and d point / d parameter in the measurement frame.

        See :func:`forward_points_and_jacobian`; shapes (..., n_poses, 3) and
        (..., n_poses, 3, n_params).
        """
        return forward_points_and_jacobian(layout, params, joint_positions)

    def nearby_predictor(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> NearbyPoints | None:
        """Tool points near the reference by :class:`~robocal_uncertainty.core.kinematics.NearbyPoints`
        (None for a layout it does not cover: prismatic joints or a mount)."""
        if not NearbyPoints.supports(layout):
            return None
        return NearbyPoints.at(layout, params, joint_positions)

    def positions(self, values: Array) -> Array:
        """The points themselves [m]."""
        return values


POINT = PointMeasurement()
"""The default measurement type: unweighted tool points."""
