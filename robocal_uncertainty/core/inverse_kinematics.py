"""Inverse kinematics of a (calibrated) model near given joints: damped Gauss-Newton, batched.

Compensation asks for the joints that put the measured point (and, when given, the tool
frame) exactly on a target under the calibrated model, as a *small* correction of joints the
robot would use anyway (the controller's solution, or the nominal model's). So the solver
starts at those seed joints and never searches: every target is solved at once by a damped
least-squares (Levenberg-Marquardt) iteration on the model's forward kinematics, with the
analytic joint Jacobian of :mod:`robocal_uncertainty.core.kinematics`, and a solution is
accepted only when it is the continuation of the seed:

- every joint moved by at most ``max_joint_change_rad`` (m for a prismatic joint), and
- the branch signs did not change (:func:`branch_signs`): the configuration's sign pattern
  (for a UR arm shoulder, elbow and wrist; for any other six-joint arm the sign of the
  Jacobian determinant, which changes only across a singularity, where IK branches meet).

Position-only targets leave a six-joint arm three degrees of freedom: the damped step
``J^T (J J^T + mu I)^-1 e`` is the least-norm joint change, so the wrist stays where the
seed had it. A target whose Jacobian is ill-conditioned (``condition > condition_limit``)
is refused: there a target change as small as the stated uncertainty moves the joints by a
large amount and the solution is no longer a small correction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import forward_poses_and_jacobian
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.rotation import rotation_log

__all__ = [
    "UR_JOINT_NAMES",
    "IkSettings",
    "IkSolution",
    "branch_signs",
    "joint_jacobian",
    "model_reach",
    "solve_near",
    "ur_analytic_ik",
    "ur_dh_parameters",
]

Array = NDArray[np.float64]

UR_JOINT_NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
"""Joint names of a Universal Robots arm (ur_robot_driver)."""


@dataclass(frozen=True)
class IkSettings:
    """Settings of :func:`solve_near`.

    Attributes
    ----------
    tolerance_m : float
        Remaining position error [m] a solution must reach (default 1e-9 m: far below any
        robot's repeatability, so the compensation adds no error of its own).
    tolerance_rad : float
        Remaining rotation error [rad] when an orientation is asked for.
    max_iterations : int
    max_joint_change_rad : float
        Largest change of any joint from its seed [rad; m for prismatic joints]. A
        calibration corrects a robot by millimetres, i.e. milliradians of joint motion; 0.05
        rad (2.9 deg) is tens of times that and still far from any other IK branch.
    condition_limit : float
        Largest condition number of the task Jacobian (rotation rows scaled by the reach) at
        the solution. The joint change per target change is at most ``1 / sigma_min``; at a
        condition number of 1e3 on a 1.3 m arm (sigma_max about 1.3 m/rad) a target moved by
        a stated uncertainty of 0.3 mm moves the joints by up to 0.23 rad: the linearised
        statement no longer holds and the move is not a small correction.
    max_step_rad : float
        Largest joint step per iteration (keeps the iteration on the seed's branch).
    """

    tolerance_m: float = 1e-9
    tolerance_rad: float = 1e-9
    max_iterations: int = 100
    max_joint_change_rad: float = 0.05
    condition_limit: float = 1e3
    max_step_rad: float = 0.1


@dataclass(frozen=True, eq=False)
class IkSolution:
    """Result of :func:`solve_near` for n targets.

    Attributes
    ----------
    joints : ndarray, shape (n, n_joints) [rad; m for prismatic joints]
        The solution (the last iterate where not accepted).
    seeds : ndarray, shape (n, n_joints)
    position_error_m : ndarray, shape (n,)
        ``|target - FK(joints)|`` [m].
    rotation_error_rad : ndarray, shape (n,)
        Angle of ``R_target R(joints)^T`` [rad]; zeros for position-only targets.
    condition : ndarray, shape (n,)
        Condition number of the task Jacobian at `joints`.
    joint_change : ndarray, shape (n,)
        Largest ``|joints - seeds|`` over the joints.
    branch_seed, branch : ndarray of int, shape (n, n_signs)
        :func:`branch_signs` at the seeds and at the solutions.
    branch_names : tuple of str
    iterations : int
    """

    joints: Array
    seeds: Array
    position_error_m: Array
    rotation_error_rad: Array
    condition: Array
    joint_change: Array
    branch_seed: NDArray[np.int64]
    branch: NDArray[np.int64]
    branch_names: tuple[str, ...]
    iterations: int


def model_reach(model: RobotModel) -> float:
    """An upper bound of the distance [m] from the first joint axis's frame to the measured point:
    the sum of every link length, offset and mount/tool translation (prismatic joints at their
    upper limit)."""
    reach = float(np.sum(np.abs(model.a)) + np.sum(np.abs(model.d)))
    reach += float(np.linalg.norm(model.tool_point) + np.linalg.norm(model.mount_xyz))
    for j, prismatic in enumerate(model.prismatic):
        if prismatic:
            reach += float(np.max(np.abs(model.joint_limits[j])))
    return reach


def joint_jacobian(model: RobotModel, params: Array, joints: Array) -> tuple[Array, Array, Array]:
    """Tool point, tool rotation and their Jacobian with respect to the joints.

    Parameters
    ----------
    model : RobotModel
        Gives the layout.
    params : ndarray, shape (n_params,) [m, rad]
    joints : ndarray, shape (n, n_joints) [rad; m]

    Returns
    -------
    points : ndarray, shape (n, 3) [m]
    rotations : ndarray, shape (n, 3, 3)
    jacobian : ndarray, shape (n, 6, n_joints)
        Rows 0-2: d point / d joint [m/rad]; rows 3-5: angular velocity in the output frame
        per unit joint motion [rad/rad]. A joint reading adds to its ``theta`` (``d`` for a
        prismatic joint), so these are the parameter Jacobian's columns of those fields.
    """
    layout = model.layout
    points, rotations, jac = forward_poses_and_jacobian(layout, params, joints)
    columns = [idx["d"] if layout.is_prismatic(j) else idx["theta"] for j, idx in enumerate(layout.joint_slices())]
    return points, rotations, np.asarray(jac[..., columns], dtype=np.float64)


def _is_ur(model: RobotModel) -> bool:
    return tuple(model.joint_names) == UR_JOINT_NAMES


def branch_signs(model: RobotModel, params: Array, joints: Array) -> tuple[NDArray[np.int64], tuple[str, ...]]:
    """The IK branch of each configuration as signs (+1, -1; 0 exactly on a singularity).

    - A UR arm (joints ``shoulder_pan_joint`` ... ``wrist_3_joint``): ``elbow`` = sign of
      ``sin(elbow_joint)`` (elbow up/down), ``wrist`` = sign of ``sin(wrist_2_joint)`` (wrist
      flipped or not), ``shoulder`` = sign of ``det J / (sin q3 sin q5)`` (shoulder left/right:
      the UR Jacobian determinant factors into these three, so the three signs together name
      the eight analytic IK solutions apart from the wrist-3 and pan turns by 2 pi).
    - Another six-joint arm: ``det_J``, the sign of the 6x6 Jacobian determinant of the tool
      frame (zero on the singular set, which separates the IK branches of a non-cuspidal arm).
    - Any other chain (redundant, fewer joints): no sign; the branch is kept by the joint
      change limit alone.

    Returns
    -------
    signs : ndarray of int, shape (n, n_signs)
    names : tuple of str
    """
    q = np.atleast_2d(np.asarray(joints, dtype=np.float64))
    if model.n_joints != 6:
        return np.zeros((q.shape[0], 0), dtype=np.int64), ()
    _, _, jac = joint_jacobian(model, params, q)
    det = np.linalg.det(jac)
    if _is_ur(model):
        s3, s5 = np.sin(q[:, 2]), np.sin(q[:, 4])
        shoulder = np.sign(det) * np.sign(s3) * np.sign(s5)
        signs = np.stack((np.sign(shoulder), np.sign(s3), np.sign(s5)), axis=1)
        return signs.astype(np.int64), ("shoulder", "elbow", "wrist")
    return np.sign(det)[:, None].astype(np.int64), ("det_J",)


def _errors(
    model: RobotModel, params: Array, q: Array, target_points: Array, target_rotations: Array | None, scale: float
) -> tuple[Array, Array]:
    """Scaled task error (n, m) and the task Jacobian (n, m, n_joints); rotation rows times `scale` [m]."""
    points, rotations, jac = joint_jacobian(model, params, q)
    error = target_points - points
    if target_rotations is None:
        return error, jac[:, :3]
    # R_target = exp([e]x) R: e in the output frame, as the Jacobian's angular rows.
    rot_error = rotation_log(target_rotations @ np.swapaxes(rotations, -1, -2))
    task = np.concatenate((error, scale * rot_error), axis=1)
    scaled = np.concatenate((jac[:, :3], scale * jac[:, 3:]), axis=1)
    return task, scaled


def _final_errors(
    model: RobotModel, params: Array, q: Array, targets: Array, target_rotations: Array | None
) -> tuple[Array, Array]:
    """Distance [m] and rotation angle [rad] of each reached tool frame from its target (0 without rotations)."""
    points, rotations, _ = joint_jacobian(model, params, q)
    position_error = np.linalg.norm(targets - points, axis=1)
    if target_rotations is None:
        return position_error, np.zeros(q.shape[0])
    return position_error, np.linalg.norm(rotation_log(target_rotations @ np.swapaxes(rotations, -1, -2)), axis=1)


def solve_near(
    model: RobotModel,
    params: Array,
    seeds: Array,
    target_points: Array,
    target_rotations: Array | None = None,
    settings: IkSettings | None = None,
) -> IkSolution:
    """Joints near `seeds` that put the model's tool point (and frame) on the targets.

    Parameters
    ----------
    model : RobotModel
        Layout and joint kinds.
    params : ndarray, shape (n_params,) [m, rad]
        The model's parameters (nominal or calibrated; the base placement decides the frame
        of the targets).
    seeds : ndarray, shape (n, n_joints) [rad; m]
    target_points : ndarray, shape (n, 3) [m]
    target_rotations : ndarray, shape (n, 3, 3), optional
        Tool frame orientations in the same frame; None: position-only targets.
    settings : IkSettings, optional

    Returns
    -------
    IkSolution
        Every target's last iterate and its diagnostics; acceptance (tolerance, joint change,
        branch, condition, limits) is the caller's decision, see :func:`robocal_uncertainty.app.compensation`.
    """
    settings = settings or IkSettings()
    q = np.array(seeds, dtype=np.float64, copy=True)
    targets = np.asarray(target_points, dtype=np.float64)
    n = q.shape[0]
    scale = max(model_reach(model), 1e-3)
    task, jac = _errors(model, params, q, targets, target_rotations, scale)
    cost = np.sum(task * task, axis=1)
    damping = np.full(n, 1e-6 * scale * scale)
    eye = np.eye(task.shape[1])
    iterations = 0
    goal = min(settings.tolerance_m, settings.tolerance_rad * scale) * 1e-3
    for iterations in range(1, settings.max_iterations + 1):
        active = cost > goal * goal
        if not active.any():
            break
        # Least-norm damped step J^T (J J^T + mu I)^-1 e: keeps redundant joints at the seed.
        jjt = jac @ np.swapaxes(jac, -1, -2) + damping[:, None, None] * eye
        step = np.einsum("nmj,nm->nj", jac, np.linalg.solve(jjt, task[..., None])[..., 0])
        biggest = np.max(np.abs(step), axis=1)
        step *= np.minimum(1.0, settings.max_step_rad / np.maximum(biggest, 1e-300))[:, None]
        step[~active] = 0.0
        trial = q + step
        trial_task, trial_jac = _errors(model, params, trial, targets, target_rotations, scale)
        trial_cost = np.sum(trial_task * trial_task, axis=1)
        better = active & (trial_cost < cost)
        q[better] = trial[better]
        task[better], jac[better], cost[better] = trial_task[better], trial_jac[better], trial_cost[better]
        # Levenberg-Marquardt: less damping after a good step, much more after a bad one.
        damping = np.where(better, np.maximum(damping * 0.1, 1e-30), damping * 10.0)
        stalled = active & ~better & (damping > 1e6 * scale * scale)
        if np.all(~active | stalled):
            break
    position_error, rotation_error = _final_errors(model, params, q, targets, target_rotations)
    singular = np.linalg.svd(jac, compute_uv=False)
    condition = singular[:, 0] / np.maximum(singular[:, -1], 1e-300)
    branch_seed, names = branch_signs(model, params, seeds)
    branch, _ = branch_signs(model, params, q)
    return IkSolution(
        joints=q,
        seeds=np.asarray(seeds, dtype=np.float64),
        position_error_m=position_error,
        rotation_error_rad=rotation_error,
        condition=condition,
        joint_change=np.max(np.abs(q - seeds), axis=1),
        branch_seed=branch_seed,
        branch=branch,
        branch_names=names,
        iterations=iterations,
    )


def ur_dh_parameters(model: RobotModel) -> tuple[float, float, float, float, float, float] | None:
    """Standard-DH ``d1, a2, a3, d4, d5, d6`` of a nominal model with the UR structure, else None.

    The UR structure in the modified-DH form the package uses: twists ``0, pi/2, 0, 0, pi/2,
    -pi/2``, lengths only in rows 3 and 4, offsets only in rows 1, 4, 5, 6, no joint offset,
    Hayati angle or mount. A calibrated model breaks this; the analytic solution is for the
    nominal model, the seed of the calibrated solve.
    """
    if model.n_joints != 6 or any(model.prismatic) or model.mounted:
        return None
    alpha = np.array([0.0, np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2])
    a_zero = np.abs(model.a[[0, 1, 4, 5]]).max()
    d_zero = np.abs(model.d[[1, 2]]).max()
    if (
        np.abs(model.alpha - alpha).max() > 1e-12
        or a_zero > 0
        or d_zero > 0
        or np.abs(model.theta).max() > 0
        or np.abs(model.beta).max() > 0
    ):
        return None
    return (
        float(model.d[0]),
        float(model.a[2]),
        float(model.a[3]),
        float(model.d[3]),
        float(model.d[4]),
        float(model.d[5]),
    )


def _dh(theta: Array, d: float, a: float, alpha: float) -> Array:
    """Standard DH transforms ``RotZ(theta) TransZ(d) TransX(a) RotX(alpha)``, shape (n, 4, 4)."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    out = np.zeros((theta.shape[0], 4, 4))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2], out[:, 0, 3] = ct, -st * ca, st * sa, a * ct
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2], out[:, 1, 3] = st, ct * ca, -ct * sa, a * st
    out[:, 2, 1], out[:, 2, 2], out[:, 2, 3] = sa, ca, d
    out[:, 3, 3] = 1.0
    return out


def ur_analytic_ik(model: RobotModel, flange: Array) -> Array | None:
    """The eight analytic inverse kinematics solutions of a nominal UR arm.

    Parameters
    ----------
    model : RobotModel
        A nominal model with the UR structure (see :func:`ur_dh_parameters`); None is returned otherwise.
    flange : ndarray, shape (n, 4, 4)
        Flange poses (the last DH frame) in the robot base frame [m].

    Returns
    -------
    ndarray, shape (n, 8, 6) [rad], or None
        Solutions ordered by (shoulder, wrist, elbow) choice; NaN where a choice has no solution
        (out of reach, or the wrist singular). Angles wrapped to (-pi, pi].
    """
    dh = ur_dh_parameters(model)
    if dh is None:
        return None
    d1, a2, a3, d4, d5, d6 = dh
    t = np.asarray(flange, dtype=np.float64)
    n = t.shape[0]
    out = np.full((n, 8, 6), np.nan)
    p6 = t[:, :3, 3]
    p5 = p6 - d6 * t[:, :3, 2]
    r = np.hypot(p5[:, 0], p5[:, 1])
    inv = np.linalg.inv(t)
    k = 0
    with np.errstate(invalid="ignore", divide="ignore"):
        for s1 in (1.0, -1.0):
            q1 = np.arctan2(p5[:, 1], p5[:, 0]) + s1 * np.arccos(np.clip(d4 / r, -2.0, 2.0)) + np.pi / 2
            q1 = np.where(np.abs(d4 / r) <= 1.0, q1, np.nan)
            c1, s1v = np.cos(q1), np.sin(q1)
            c5 = (p6[:, 0] * s1v - p6[:, 1] * c1 - d4) / d6
            for s5 in (1.0, -1.0):
                q5 = np.where(np.abs(c5) <= 1.0 + 1e-12, s5 * np.arccos(np.clip(c5, -1.0, 1.0)), np.nan)
                sin5 = np.sin(q5)
                x, y = inv[:, :3, 0], inv[:, :3, 1]
                q6 = np.arctan2((-x[:, 1] * s1v + y[:, 1] * c1) / sin5, (x[:, 0] * s1v - y[:, 0] * c1) / sin5)
                t01 = _dh(q1, d1, 0.0, np.pi / 2)
                t45 = _dh(q5, d5, 0.0, -np.pi / 2)
                t56 = _dh(q6, d6, 0.0, 0.0)
                t14 = np.linalg.inv(t01) @ t @ np.linalg.inv(t45 @ t56)
                p13 = t14[:, :3, 3] - d4 * t14[:, :3, 1]
                norm = np.linalg.norm(p13, axis=1)
                c3 = (norm**2 - a2**2 - a3**2) / (2.0 * a2 * a3)
                for s3 in (1.0, -1.0):
                    q3 = np.where(np.abs(c3) <= 1.0 + 1e-12, s3 * np.arccos(np.clip(c3, -1.0, 1.0)), np.nan)
                    q2 = -np.arctan2(p13[:, 1], -p13[:, 0]) + np.arcsin(np.clip(a3 * np.sin(q3) / norm, -1.0, 1.0))
                    t13 = _dh(q2, 0.0, a2, 0.0) @ _dh(q3, 0.0, a3, 0.0)
                    t34 = np.linalg.inv(t13) @ t14
                    q4 = np.arctan2(t34[:, 1, 0], t34[:, 0, 0])
                    q = np.stack((q1, q2, q3, q4, q5, q6), axis=1)
                    out[:, k] = np.angle(np.exp(1j * q))
                    k += 1
    return out
