"""The forward-kinematics service: tool points of a nominal or calibrated model, in a named frame.

A calibration that identified the base transform (a tracker-frame campaign) gives points
in the measurement (tracker) frame as well as in the robot base frame; a nominal model
has measurement-frame points only when its config places the base away from the origin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.field_kriging import KrigingBasis, krige
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError

__all__ = ["FRAMES", "ToolPoints", "tool_points"]

Array = NDArray[np.float64]

FRAMES = ("measurement", "base")
"""Frames :func:`tool_points` can report."""


@dataclass(frozen=True, eq=False)
class ToolPoints:
    """Tool points of a model at some joint configurations.

    Attributes
    ----------
    model : {"nominal", "calibrated"}
    robot : str
    joint_names : tuple of str, length n_joints
    joint_positions : ndarray, shape (n, n_joints) [rad]
    points_base : ndarray, shape (n, 3) [m]
        In the robot base frame ``base_frame_id``.
    base_frame_id : str
    points_measurement : ndarray, shape (n, 3) [m], or None
        In the measurement frame ``measurement_frame_id``; None when the model places the
        base at the measurement frame's origin (the two frames coincide).
    measurement_frame_id : str
    frame : {"measurement", "base"}
        The frame chosen for :attr:`points`.
    frame_id : str
        Its ``frame_id``.
    points : ndarray, shape (n, 3) [m]
        The points in `frame`.
    correction : ndarray, shape (n, 3) [m], or None
        The model-error field's conditional mean added to every point (in `frame`), when asked.
    correction_covariance : ndarray, shape (n, 3, 3) [m^2], or None
        Covariance of the corrected point's error (kriging variance, in `frame`): the field and,
        through the fit, the parameters; a new measurement's own noise is not in it.
    std_ratio : ndarray, shape (n,), or None
        Kriging std over the uncorrected std (1: far from every calibration pose, the correction
        knows nothing there).
    coverage_factor : float or None
        Per-axis 95 % coverage factor (Student-t with the field scale's degrees of freedom).
    """

    model: str
    robot: str
    joint_names: tuple[str, ...]
    joint_positions: Array
    points_base: Array
    base_frame_id: str
    points_measurement: Array | None
    measurement_frame_id: str
    frame: str
    frame_id: str
    points: Array
    correction: Array | None = None
    correction_covariance: Array | None = None
    std_ratio: Array | None = None
    coverage_factor: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (lengths [m], angles [rad]): both frames' points where they differ."""
        out: dict[str, Any] = {
            "units": {"length": "m", "angle": "rad"},
            "model": self.model,
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "joint_positions_rad": self.joint_positions.tolist(),
            "points_base_m": self.points_base.tolist(),
            "base_frame_id": self.base_frame_id,
        }
        if self.points_measurement is not None:
            out["points_measurement_frame_m"] = self.points_measurement.tolist()
            out["measurement_frame_id"] = self.measurement_frame_id
        if self.correction is not None and self.correction_covariance is not None:
            out["field_correction"] = {
                "frame_id": self.frame_id,
                "correction_m": self.correction.tolist(),
                "covariance_m2": self.correction_covariance.tolist(),
                "std_ratio": None if self.std_ratio is None else self.std_ratio.tolist(),
                "coverage_factor_95": self.coverage_factor,
                "note": "points include the correction; a URDF or UR export cannot carry it",
            }
        return out


def tool_points(
    model: RobotModel,
    joints: Array,
    *,
    calibrated: bool,
    frame: str | None = None,
    field_correction: KrigingBasis | None = None,
) -> ToolPoints:
    """Tool points of `model` at `joints`.

    Parameters
    ----------
    model : RobotModel
        Nominal model, or one with a calibration applied.
    joints : ndarray, shape (n, n_joints) [rad]
    calibrated : bool
        Whether `model` carries a calibration (recorded, and a calibration with an
        identified base gives measurement-frame points).
    frame : {"measurement", "base"}, optional
        Frame of :attr:`ToolPoints.points`; default the measurement frame when the model has
        one distinct from the base, else the base frame. ``"measurement"`` of a model whose
        config states the base known at the measurement frame's origin gives those points
        labelled with the measurement frame (the frames coincide).
    field_correction : KrigingBasis, optional
        The calibration's model-error field with its residuals
        (:func:`~robocal_uncertainty.core.field_kriging.kriging_basis`): its conditional
        mean at `joints` is added to the points (both frames) and its kriging covariance kept.

    Raises
    ------
    ConfigError
        Unknown `frame`; ``"measurement"`` for a model whose base is unknown
        (``base.known: false``) and not identified by a calibration.
    """
    if frame is not None and frame not in FRAMES:
        msg = f"frame must be one of {', '.join(FRAMES)}, got {frame!r}"
        raise ConfigError(msg)
    q = np.asarray(joints, dtype=np.float64)
    p = model.parameter_vector()
    b0 = model.layout.base_index
    p_base = p.copy()
    p_base[b0 : b0 + 6] = 0.0
    base_points = forward_points(model.layout, p_base, q)
    world_points = forward_points(model.layout, p, q)
    placed = model.base_known and bool(np.any(model.base_xyz != 0) or np.any(model.base_rpy != 0))
    has_world = (calibrated and not np.allclose(p[b0 : b0 + 6], 0.0)) or placed
    chosen = frame or ("measurement" if has_world else "base")
    if chosen == "measurement" and not has_world and not model.base_known:
        # The base frame's points must not be labelled as the measurement frame's.
        kind = "calibration identified no base" if calibrated else "nominal model cannot place it"
        msg = (
            f"the {model.name} model's base is unknown in the measurement frame {model.measurement_frame_id} "
            f"(base.known: false) and the {kind}: give a calibration of a campaign measured in that frame, "
            "or --frame base"
        )
        raise ConfigError(msg)
    if chosen == "measurement":
        # Without a placed base the config states the base at the measurement frame's origin
        # (base.known: true, xyz and rpy 0): the frames coincide, the points are the same.
        frame_id, points = model.measurement_frame_id, world_points
    else:
        frame_id, points = model.base_frame_id, base_points
    extra: dict[str, Any] = {}
    if field_correction is not None:
        kriged = krige(field_correction, model.layout, p, q)
        r_wb = rpy_to_matrix(p[b0 + 3 : b0 + 6])
        base_mean = kriged.mean @ r_wb  # rows R^T m: the measurement-frame correction in the base frame
        world_points = world_points + kriged.mean
        base_points = base_points + base_mean
        in_measurement = chosen == "measurement"
        rot = np.eye(3) if in_measurement else r_wb.T
        extra = {
            "correction": kriged.mean if in_measurement else base_mean,
            "correction_covariance": np.einsum("ij,njk,lk->nil", rot, kriged.covariance, rot),
            "std_ratio": kriged.std_ratio,
            "coverage_factor": kriged.coverage_factor(),
        }
        points = world_points if in_measurement else base_points
    return ToolPoints(
        model="calibrated" if calibrated else "nominal",
        robot=model.name,
        joint_names=tuple(model.joint_names),
        joint_positions=q,
        points_base=base_points,
        base_frame_id=model.base_frame_id,
        points_measurement=world_points if has_world else None,
        measurement_frame_id=model.measurement_frame_id,
        frame=chosen,
        frame_id=frame_id,
        points=points,
        **extra,
    )
