"""The compensation service: joints that reach Cartesian targets under the calibrated model,
with the stated uncertainty of where the robot then goes.

A controller moving to a Cartesian target computes its joints with its own (factory)
kinematics, so a calibration changes nothing there unless the joints are computed for it:
:func:`compensate` gives, per target, the joints that put the calibrated model's measured
point (and tool frame, when an orientation is given) on the target, as a small correction of
seed joints on the same IK branch (:mod:`robocal_uncertainty.core.inverse_kinematics`), and
refuses per target, one line each, what it cannot state: an unreachable target, a solution
beyond the joint limits, a near-singular target, a correction larger than the limit or one
that changed the branch.

Seeds: the joints the controller would use (``seeds``, e.g. its own IK solution); without
them the nominal model's solution, found by the same iteration from the calibration
campaign's pose nearest to the target (the robot was there, on the branch its program uses).

The uncertainty of the reached position is the validated statement of ``evaluate``: the
same :func:`~robocal_uncertainty.app.evaluation.evaluate` Monte Carlo (the calibration
campaign re-identified per trial, with the model error), with all accepted compensated
joints as its test configurations in one batched run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.calibration_file import apply_calibration
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.inverse_kinematics import (
    UR_JOINT_NAMES,
    IkSettings,
    IkSolution,
    branch_signs,
    model_reach,
    solve_near,
    ur_analytic_ik,
    ur_dh_parameters,
)
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.importers.targets import Targets
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.calibration import CalibrationUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = [
    "COMPENSATION_FORMAT",
    "REPRODUCTION_TOLERANCE_M",
    "Compensation",
    "compensate",
    "service_response",
    "service_targets",
    "targets_frame",
]

Array = NDArray[np.float64]

COMPENSATION_FORMAT = "robocal_uncertainty/compensation/1"
REPRODUCTION_TOLERANCE_M = 1e-6
"""Largest difference [m], at the compensated joints, between the calibration file's model and
the re-identification of its campaign that the uncertainty run makes: above it the campaign is
not the calibration's (or another lambda) and its statement would be about another model."""
PLAUSIBLE_REACH_FACTOR = 3.0
"""A target farther than this many reaches from the robot base is refused as a unit error
(a file of millimetres labelled metres puts targets hundreds of reaches away)."""


@dataclass(frozen=True, eq=False)
class Compensation:
    """Compensated joint targets.

    Attributes
    ----------
    robot : str
    joint_names : tuple of str
    frame : {"measurement", "base"}
    frame_id : str
        Frame of the targets and of the stated positions.
    targets : Targets
    seed_source : str
        ``"given"`` or ``"nominal IK from the nearest campaign pose"``.
    nominal_joints : ndarray, shape (n, n_joints)
        The joints the correction starts from (the seeds, or the nominal model's solution).
    joints : ndarray, shape (n, n_joints) [rad; m]
        The compensated joints (the last iterate for refused targets).
    accepted : ndarray of bool, shape (n,)
    status : tuple of str
        ``"ok"`` or why the target is refused (one line).
    solution : IkSolution
        Diagnostics of the calibrated solve.
    settings : IkSettings
    uncertainty : CalibrationUncertainty or None
        The Monte Carlo statement at the accepted joints (their order); None when not asked.
    reproduction_m : float or None
        Largest difference between the calibration file's model and the re-identification
        (see :data:`REPRODUCTION_TOLERANCE_M`).
    prismatic : tuple of bool
        The robot's prismatic joints (their values in m).
    tool_frame : str
        What an orientation target orients: the calibrated tool frame, or the flange frame
        when the calibration carries no tool rotation (point data).
    """

    robot: str
    joint_names: tuple[str, ...]
    frame: str
    frame_id: str
    targets: Targets
    seed_source: str
    nominal_joints: Array
    joints: Array
    accepted: NDArray[np.bool_]
    status: tuple[str, ...]
    solution: IkSolution
    settings: IkSettings
    uncertainty: CalibrationUncertainty | None = None
    reproduction_m: float | None = None
    prismatic: tuple[bool, ...] = ()
    tool_frame: str = "tool"

    def csv_text(self) -> str:
        """Joint targets, one row per accepted target (index 1-based), units in the header."""
        prismatic = self.prismatic or (False,) * len(self.joint_names)
        units = ["m" if p else "rad" for p in prismatic]
        head = ["target"] + [f"{n}_{u}" for n, u in zip(self.joint_names, units)]
        lines = [",".join(head)]
        for i in np.flatnonzero(self.accepted):
            lines.append(",".join([str(i + 1)] + [repr(float(v)) for v in self.joints[i]]))
        return "\n".join(lines) + "\n"

    def urscript_text(self, *, acceleration: float = 1.4, velocity: float = 1.05) -> str:
        """A URScript program moving through the accepted targets (``movej``, rad, rad/s^2, rad/s).

        Raises
        ------
        ConfigError
            The robot is not a UR arm (joints ``shoulder_pan_joint`` ... ``wrist_3_joint``).
        """
        if tuple(self.joint_names) != UR_JOINT_NAMES:
            msg = f"--urscript is for Universal Robots arms; robot {self.robot!r} has joints {list(self.joint_names)}"
            raise ConfigError(msg)
        lines = [
            "def compensated_targets():",
            f"  # {int(self.accepted.sum())} of {self.targets.n} targets of {self.targets.source}, compensated by "
            f"robocal-uncertainty under the calibrated {self.robot} model (frame {self.frame_id});",
            "  # refused targets are left out (see the JSON). Joints in rad, a in rad/s^2, v in rad/s.",
        ]
        for i in np.flatnonzero(self.accepted):
            q = ", ".join(f"{float(v):.9f}" for v in self.joints[i])
            lines.append(f"  movej([{q}], a={acceleration:g}, v={velocity:g})  # target {i + 1}")
        lines.append("end")
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: settings, per target the joints, errors, status and uncertainty (SI)."""
        sol = self.solution
        result: dict[str, Any] = {
            "format": COMPENSATION_FORMAT,
            "units": {"length": "m", "angle": "rad"},
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "frame": self.frame,
            "frame_id": self.frame_id,
            "targets_file": self.targets.source,
            "targets_units": {"length": self.targets.length_unit, "angle": self.targets.angle_unit or None},
            "orientation": self.targets.orientation,
            "oriented_frame": self.tool_frame if self.targets.rotations is not None else None,
            "seed_source": self.seed_source,
            "settings": {
                "tolerance_m": self.settings.tolerance_m,
                "tolerance_rad": self.settings.tolerance_rad,
                "max_joint_change_rad": self.settings.max_joint_change_rad,
                "condition_limit": self.settings.condition_limit,
                "max_iterations": self.settings.max_iterations,
            },
            "branch_signs": list(sol.branch_names),
            "n_targets": self.targets.n,
            "n_accepted": int(self.accepted.sum()),
            "reproduction_m": self.reproduction_m,
        }
        unc = self.uncertainty
        if unc is not None:
            result["uncertainty"] = {
                "method": "Monte Carlo (JCGM 101) of evaluate: the calibration campaign re-identified per trial",
                "sources": list(unc.settings.sources),
                "trials": unc.n_trials,
                "seed": unc.seed,
                "coverage_probability": unc.coverage_probability,
                "frame_id": unc.frame_id,
                "trustworthy": bool(unc.model_adequacy.trustworthy),
                "warnings": list(unc.warnings),
            }
        rows = []
        k = 0
        for i in range(self.targets.n):
            row: dict[str, Any] = {
                "target": i + 1,
                "status": self.status[i],
                "position_m": self.targets.points[i].tolist(),
                "nominal_joints": self.nominal_joints[i].tolist(),
                "joints": self.joints[i].tolist(),
                "position_error_m": float(sol.position_error_m[i]),
                "rotation_error_rad": float(sol.rotation_error_rad[i]) if self.targets.rotations is not None else None,
                "joint_change": float(sol.joint_change[i]),
                "condition": float(sol.condition[i]),
                "branch_seed": sol.branch_seed[i].tolist(),
                "branch": sol.branch[i].tolist(),
            }
            if self.accepted[i] and unc is not None:
                pose = unc.poses[k]
                k += 1
                row["reached"] = {
                    "mean_m": pose.mean.tolist(),
                    "mean_minus_target_m": (pose.mean - self.targets.points[i]).tolist(),
                    "standard_uncertainty_m": [a.standard_uncertainty for a in pose.axes],
                    "expanded_uncertainty_m": [a.expanded_uncertainty for a in pose.axes],
                    "interval_m": [[a.interval.low, a.interval.high] for a in pose.axes],
                    "region_coverage_factor": None if pose.region is None else pose.region.coverage_factor,
                    "covariance_m2": pose.covariance.tolist(),
                }
            rows.append(row)
        result["targets"] = rows
        return result


def targets_frame(model: RobotModel, calibrated: RobotModel, frame: str | None) -> tuple[str, str]:
    """The frame the targets are in (``measurement`` or ``base``) and its frame id.

    Default: the measurement frame when the calibration identified the base (or the config
    places it), else the base frame (as ``fk``)."""
    p = calibrated.parameter_vector()
    b0 = calibrated.layout.base_index
    has_world = not np.allclose(p[b0 : b0 + 6], 0.0)
    chosen = frame or ("measurement" if has_world else "base")
    if chosen not in ("measurement", "base"):
        msg = f"--frame must be measurement or base, got {chosen!r}"
        raise ConfigError(msg)
    if chosen == "measurement" and not has_world and not model.base_known:
        msg = (
            f"the {model.name} model's base is unknown in the measurement frame {model.measurement_frame_id} and the "
            "calibration identified none: give the targets in the base frame (--frame base)"
        )
        raise ConfigError(msg)
    return chosen, (calibrated.measurement_frame_id if chosen == "measurement" else calibrated.base_frame_id)


def _frame_params(model: RobotModel, frame: str) -> Array:
    p = model.parameter_vector()
    if frame == "base":
        b0 = model.layout.base_index
        p[b0 : b0 + 6] = 0.0
    return p


def _check_plausible(targets: Targets, calibrated: RobotModel, params: Array) -> None:
    """Refuse a file whose lengths are off by a unit factor, before any solve."""
    b0 = calibrated.layout.base_index
    origin = params[b0 : b0 + 3]
    reach = model_reach(calibrated)
    distance = np.linalg.norm(targets.points - origin, axis=1)
    far = int(np.argmax(distance))
    if distance[far] > PLAUSIBLE_REACH_FACTOR * reach:
        hint = ""
        if targets.length_unit == "m" and distance[far] * 1e-3 <= PLAUSIBLE_REACH_FACTOR * reach:
            hint = ": millimetres labelled as metres?"
        msg = (
            f"targets {targets.source}: target {far + 1} is {distance[far]:.4g} m from the robot base, more than "
            f"{PLAUSIBLE_REACH_FACTOR:g} x the robot's reach ({reach:.3g} m){hint} (header unit {targets.length_unit})"
        )
        raise InputError(msg)
    if targets.n >= 3 and np.all(distance < 1e-2 * reach):
        msg = (
            f"targets {targets.source}: every target lies within {np.max(distance) * 1e3:.3g} mm of the robot base "
            f"(reach {reach:.3g} m): metres labelled as {targets.length_unit}?"
        )
        raise InputError(msg)


def _nearest_campaign_seeds(
    nominal: RobotModel, nominal_params: Array, campaign_joints: Array, targets: Targets
) -> Array:
    points = forward_points(nominal.layout, nominal_params, campaign_joints)
    gaps = np.linalg.norm(targets.points[:, None, :] - points[None, :, :], axis=2)
    return np.asarray(campaign_joints[np.argmin(gaps, axis=1)], dtype=np.float64)


def _nominal_seeds(
    model: RobotModel,
    nominal: RobotModel,
    nom_params: Array,
    targets: Targets,
    campaign: Campaign | None,
    branch: dict[str, int] | None,
    settings: IkSettings,
) -> tuple[Array, str, list[str]]:
    """Seeds without given ones: the nominal model's solution; returns the seeds, their source and,
    per target, why there is none ("" where there is one).

    Pose targets of a UR arm: the analytic solution on `branch` (default: the branch of the
    campaign pose nearest to the target), each joint turned by 2 pi to lie nearest to that pose.
    Otherwise (points, other arms): the damped iteration on the nominal model from that pose.
    """
    n = targets.n
    analytic = targets.rotations is not None and ur_dh_parameters(model) is not None
    if campaign is None and not (analytic and branch is not None):
        msg = (
            "no seed joints: give --seed-joints (e.g. the controller's joints for each target) or the calibration's "
            "campaign" + (" (or --branch for pose targets of a UR arm)" if analytic else "")
        )
        raise ConfigError(msg)
    start = None
    if campaign is not None:
        joints = campaign.reorder_joints(model.joint_names).joint_positions
        start = _nearest_campaign_seeds(nominal, nom_params, joints, targets)
    if not analytic:
        assert start is not None
        found = solve_near(
            nominal, nom_params, start, targets.points, targets.rotations, replace(settings, max_iterations=300)
        )
        return found.joints, "nominal IK from the nearest campaign pose", [""] * n
    assert targets.rotations is not None
    solutions = ur_analytic_ik(model, _flange_targets(nominal.layout, nom_params, targets))
    assert solutions is not None
    b0 = nominal.layout.base_index
    base_only = nom_params.copy()
    base_only[b0 : b0 + 6] = 0.0
    flat = solutions.reshape(-1, 6)
    finite = np.isfinite(flat).all(axis=1)
    flat_signs = np.zeros((flat.shape[0], 3), dtype=np.int64)
    flat_signs[finite], names = branch_signs(nominal, base_only, flat[finite])
    signs = flat_signs.reshape(n, 8, 3)
    if branch is not None:
        unknown = sorted(set(branch) - set(names))
        if unknown:
            msg = f"--branch names {', '.join(unknown)}; a UR branch is {', '.join(names)} (each +1 or -1)"
            raise ConfigError(msg)
        wanted = np.tile([branch.get(k, 0) for k in names], (n, 1))
        source = "nominal analytic UR IK, branch " + ", ".join(f"{k} {branch[k]:+d}" for k in names if k in branch)
    else:
        assert start is not None
        wanted, _ = branch_signs(nominal, base_only, start)
        source = "nominal analytic UR IK, on the branch of the nearest campaign pose"
    match = np.all((signs == wanted[:, None, :]) | (wanted[:, None, :] == 0), axis=2) & np.isfinite(solutions).all(
        axis=2
    )
    reference = start if start is not None else np.zeros((n, 6))
    seeds, missing = _nearest_on_branch(model, solutions, match, reference, names, wanted)
    return seeds, source, missing


def _flange_targets(layout: ParameterLayout, nom_params: Array, targets: Targets) -> Array:
    """Target tool frames -> flange poses (n, 4, 4) in the robot base frame (the nominal chain's frame)."""
    assert targets.rotations is not None
    b0, t0, r0 = layout.base_index, layout.tool_index, layout.tool_rotation_index
    world_t_base = np.eye(4)
    world_t_base[:3, :3] = rpy_to_matrix(nom_params[b0 + 3 : b0 + 6])
    world_t_base[:3, 3] = nom_params[b0 : b0 + 3]
    flange_t_tool = np.eye(4)
    if r0 is not None:
        flange_t_tool[:3, :3] = rpy_to_matrix(nom_params[r0 : r0 + 3])
    flange_t_tool[:3, 3] = nom_params[t0 : t0 + 3]
    tool = np.tile(np.eye(4), (targets.n, 1, 1))
    tool[:, :3, :3] = targets.rotations
    tool[:, :3, 3] = targets.points
    flange: Array = np.linalg.inv(world_t_base) @ tool @ np.linalg.inv(flange_t_tool)
    return flange


def _nearest_on_branch(
    model: RobotModel,
    solutions: Array,
    match: NDArray[np.bool_],
    reference: Array,
    names: Sequence[str],
    wanted: NDArray[np.int64],
) -> tuple[Array, list[str]]:
    """Per target, the analytic solution on the wanted branch nearest to `reference` (whole turns
    within the limits), or `reference` and why there is none."""
    n = reference.shape[0]
    seeds = reference.copy()
    missing = [""] * n
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    for i in range(n):
        options = solutions[i][match[i]]
        if options.shape[0] == 0:
            wish = ", ".join(f"{k} {int(v):+d}" for k, v in zip(names, wanted[i]) if v)
            missing[i] = f"refused: the nominal model has no solution on the branch ({wish})"
            continue
        # Each joint turned by whole turns to lie nearest to the reference, within the limits.
        turns = np.round((reference[i] - options) / (2 * np.pi))
        shifted = options + 2 * np.pi * turns
        shifted = np.where(shifted > hi, shifted - 2 * np.pi, np.where(shifted < lo, shifted + 2 * np.pi, shifted))
        seeds[i] = shifted[np.argmin(np.linalg.norm(shifted - reference[i], axis=1))]
    return seeds, missing


def _status(model: RobotModel, solution: IkSolution, targets: Targets, settings: IkSettings) -> tuple[str, ...]:
    out = []
    lo, hi = model.joint_limits[:, 0] - 1e-9, model.joint_limits[:, 1] + 1e-9
    for i in range(targets.n):
        q = solution.joints[i]
        pos, rot = solution.position_error_m[i], solution.rotation_error_rad[i]
        cond = solution.condition[i]
        if not np.isfinite(q).all():
            out.append("refused: no solution (non-finite joints)")
        elif solution.branch_seed.shape[1] and np.any(solution.branch_seed[i] == 0):
            zero = [n for n, v in zip(solution.branch_names, solution.branch_seed[i]) if v == 0]
            out.append(
                f"refused: the seed lies on a singularity ({', '.join(zero)} sign 0): it has no branch to keep; "
                "give a seed off it"
            )
        elif cond > settings.condition_limit or pos > settings.tolerance_m or rot > settings.tolerance_rad:
            missed = pos > settings.tolerance_m or rot > settings.tolerance_rad
            what = f"{pos * 1e3:.4g} mm" + (f", {rot * 1e3:.4g} mrad" if targets.rotations is not None else "")
            if cond > settings.condition_limit:
                out.append(
                    f"refused: near-singular (condition {cond:.3g} > {settings.condition_limit:g}"
                    + (f", remaining error {what}" if missed else "")
                    + "): a target change of the stated uncertainty would move the joints far"
                )
            else:
                out.append(f"refused: unreachable from the seed (remaining error {what}; condition {cond:.3g} there)")
        elif solution.joint_change[i] > settings.max_joint_change_rad:
            j = int(np.argmax(np.abs(q - solution.seeds[i])))
            out.append(
                f"refused: the correction moves {model.joint_names[j]} by {solution.joint_change[i]:.4g} rad "
                f"(limit {settings.max_joint_change_rad:g})"
            )
        elif solution.branch.shape[1] and np.any(solution.branch[i] != solution.branch_seed[i]):
            changed = [
                f"{n} {int(a):+d} -> {int(b):+d}"
                for n, a, b in zip(solution.branch_names, solution.branch_seed[i], solution.branch[i])
                if a != b
            ]
            near = " (the seed lies next to a singularity)" if solution.joint_change[i] < 0.01 else ""
            out.append(
                f"refused: branch changed ({', '.join(changed)}) by a correction of "
                f"{math.degrees(solution.joint_change[i]):.3g} deg{near}"
            )
        elif np.any((q < lo) | (q > hi)):
            j = int(np.argmax((q < lo) | (q > hi)))
            low, high = np.degrees(model.joint_limits[j])
            out.append(
                f"refused: beyond the joint limits ({model.joint_names[j]} = {math.degrees(q[j]):.6g} deg, "
                f"limits [{low:.6g}, {high:.6g}] deg)"
            )
        else:
            out.append("ok")
    return tuple(out)


@dataclass(frozen=True)
class _Solved:
    """The calibrated inverse kinematics of the targets, before any uncertainty."""

    calibrated: RobotModel
    frame: str
    frame_id: str
    params: Array
    """The calibrated parameters with the base of `frame` [m, rad]."""
    seed_source: str
    nominal_joints: Array
    solution: IkSolution
    status: tuple[str, ...]
    accepted: NDArray[np.bool_]
    tool_frame: str


def _seed_params(nominal: RobotModel, cal_params: Array) -> Array:
    """The nominal kinematics with the calibration's base placement and tool.

    The seed then differs from the calibrated solution by the kinematic correction alone (a probe
    mounted turned by 90 deg is not a correction).
    """
    nom_params = nominal.parameter_vector()
    b0, t0 = nominal.layout.base_index, nominal.layout.tool_index
    nom_params[b0 : b0 + 6] = cal_params[b0 : b0 + 6]
    nom_params[t0 : t0 + 3] = cal_params[t0 : t0 + 3]
    r0 = nominal.layout.tool_rotation_index
    if r0 is not None:
        nom_params[r0 : r0 + 3] = cal_params[r0 : r0 + 3]
    return nom_params


def _given_seeds(model: RobotModel, seeds: Array, n: int) -> Array:
    """The given seed joints, one per target (one given for all is repeated); checked against the limits."""
    from robocal_uncertainty.core.joint_limits import check_joint_limits

    q0 = np.atleast_2d(np.asarray(seeds, dtype=np.float64))
    if q0.shape[1] != model.n_joints or q0.shape[0] not in (1, n):
        msg = (
            f"seed joints: {q0.shape[0]} configurations of {q0.shape[1]} joints for {n} targets of a "
            f"{model.n_joints}-joint robot: give one, or one per target"
        )
        raise InputError(msg)
    check_joint_limits(model, q0, what="seed configuration")
    return np.repeat(q0, n, axis=0) if q0.shape[0] == 1 else q0


def _solve(
    model: RobotModel,
    calibration: dict[str, Any],
    targets: Targets,
    *,
    frame: str | None,
    seeds: Array | None,
    campaign: Campaign | None,
    settings: IkSettings,
    branch: dict[str, int] | None,
    where: str,
) -> _Solved:
    """Seeds (given or the nominal model's) and the calibrated solution near them, with a status each."""
    calibrated = apply_calibration(model, calibration, where=where)
    nominal = model.with_tool_rotation() if calibrated.tool_rotation else model
    chosen, frame_id = targets_frame(model, calibrated, frame)
    cal_params = _frame_params(calibrated, chosen)
    nom_params = _seed_params(nominal, cal_params)
    _check_plausible(targets, calibrated, cal_params)
    # Without a calibrated tool rotation (point data) an orientation is the flange's: said in the output.
    tool_frame = (
        "the calibrated tool frame (tool.rx, tool.ry, tool.rz)"
        if calibrated.tool_rotation
        else "the flange frame (the calibration has no tool rotation)"
    )
    if seeds is not None:
        nominal_q, seed_source = _given_seeds(model, seeds, targets.n), "given"
    else:
        nominal_q, seed_source, no_seed = _nominal_seeds(
            model, nominal, nom_params, targets, campaign, branch, settings
        )
    solution = solve_near(calibrated, cal_params, nominal_q, targets.points, targets.rotations, settings)
    status = _status(calibrated, solution, targets, settings)
    if seeds is None:
        status = tuple(no_seed[i] or s for i, s in enumerate(status))
    return _Solved(
        calibrated=calibrated,
        frame=chosen,
        frame_id=frame_id,
        params=cal_params,
        seed_source=seed_source,
        nominal_joints=nominal_q,
        solution=solution,
        status=status,
        accepted=np.array([s == "ok" for s in status]),
        tool_frame=tool_frame,
    )


def _reached_uncertainty(
    model: RobotModel,
    calibration: dict[str, Any],
    solved: _Solved,
    campaign: Campaign | None,
    options: EvaluationSettings,
    *,
    where: str,
    workers: int,
) -> tuple[CalibrationUncertainty, float]:
    """Uncertainty of the accepted reached positions, from the campaign re-identified, and how far
    that re-identification places them from the calibration's [m] (refused beyond the tolerance)."""
    from robocal_uncertainty.app.evaluation import evaluate

    if campaign is None:
        msg = (
            "the uncertainty of the reached positions needs the calibration's campaign: give --campaign "
            "(or --no-uncertainty)"
        )
        raise ConfigError(msg)
    lam = calibration.get("lambda")
    if not isinstance(lam, (int, float)) or isinstance(lam, bool):
        msg = f"{where} has no numeric 'lambda': cannot re-identify its campaign for the uncertainty"
        raise ConfigError(msg)
    chosen, calibrated, cal_params = solved.frame, solved.calibrated, solved.params
    q_ok = solved.solution.joints[solved.accepted]
    asked = replace(options, test_joints=q_ok, lambda_=float(lam), frame=chosen)
    evaluation = evaluate(model, campaign, asked, run=RunContext(workers=workers))
    again = model.with_tool_rotation() if evaluation.calibration.model.tool_rotation else model
    reidentified = _frame_params(again.with_parameters(evaluation.calibration.estimate), chosen)
    gap = forward_points(calibrated.layout, reidentified, q_ok) - forward_points(calibrated.layout, cal_params, q_ok)
    reproduction = float(np.max(np.linalg.norm(gap, axis=1)))
    if reproduction > REPRODUCTION_TOLERANCE_M:
        msg = (
            f"the campaign does not reproduce {where}: its re-identification (lambda {lam:g}) places the "
            f"compensated points up to {reproduction * 1e3:.4g} mm away: give the campaign the calibration "
            "was made from"
        )
        raise ConfigError(msg)
    return evaluation.uncertainty, reproduction


def _compensation(
    model: RobotModel,
    targets: Targets,
    solved: _Solved,
    settings: IkSettings,
    uncertainty: CalibrationUncertainty | None,
    reproduction: float | None,
) -> Compensation:
    """The result: the solved joints, their status and, where asked, the uncertainty."""
    return Compensation(
        robot=model.name,
        joint_names=tuple(model.joint_names),
        frame=solved.frame,
        frame_id=solved.frame_id,
        targets=targets,
        seed_source=solved.seed_source,
        nominal_joints=solved.nominal_joints,
        joints=solved.solution.joints,
        accepted=solved.accepted,
        status=solved.status,
        solution=solved.solution,
        settings=settings,
        uncertainty=uncertainty,
        reproduction_m=reproduction,
        prismatic=tuple(model.prismatic),
        tool_frame=solved.tool_frame,
    )


def compensate(
    model: RobotModel,
    calibration: dict[str, Any],
    targets: Targets,
    *,
    frame: str | None = None,
    seeds: Array | None = None,
    campaign: Campaign | None = None,
    options: EvaluationSettings | None = None,
    settings: IkSettings | None = None,
    branch: dict[str, int] | None = None,
    where: str = "calibration",
    workers: int = 1,
) -> Compensation:
    """Joints reaching `targets` under the calibrated model and the uncertainty of the reached position.

    Parameters
    ----------
    model : RobotModel
        The nominal model the calibration was identified on.
    calibration : dict
        A calibration file's content (``read_calibration``).
    targets : Targets
        In the frame `frame`.
    frame : {"measurement", "base"}, optional
        See :func:`targets_frame`.
    seeds : ndarray, shape (n_targets, n_joints) or (1, n_joints), optional
        Joints the correction starts from and whose branch it keeps (e.g. the controller's
        solution for each target). Default: the nominal model's solution from the campaign
        pose nearest to each target (needs `campaign`).
    campaign : Campaign, optional
        The calibration's campaign: the seeds' start, and the Monte Carlo of the statement.
    options : EvaluationSettings, optional
        Monte Carlo settings (sources, trials, seed, coverage); ``test_joints``, ``lambda_``
        and ``frame`` are set here. None: no uncertainty (joints only).
    settings : IkSettings, optional
    branch : dict of str to int, optional
        Without `seeds`, for pose targets of a UR arm: the analytic nominal solution's branch
        (``{"shoulder": 1, "elbow": -1, "wrist": 1}``, see
        :func:`~robocal_uncertainty.core.inverse_kinematics.branch_signs`); default the branch
        of the campaign pose nearest to the target.
    where : str
        Names the calibration in messages.
    workers : int
        Monte Carlo worker processes; never changes the result.

    Raises
    ------
    InputError
        Targets implausible for the robot (unit error), seeds of the wrong shape or outside
        the joint limits.
    ConfigError
        No seeds and no campaign; an uncertainty asked for without a campaign; a campaign that
        does not reproduce the calibration.
    """
    settings = settings or IkSettings()
    solved = _solve(
        model,
        calibration,
        targets,
        frame=frame,
        seeds=seeds,
        campaign=campaign,
        settings=settings,
        branch=branch,
        where=where,
    )
    uncertainty = None
    reproduction = None
    if options is not None and solved.accepted.any():
        uncertainty, reproduction = _reached_uncertainty(
            model, calibration, solved, campaign, options, where=where, workers=workers
        )
    return _compensation(model, targets, solved, settings, uncertainty, reproduction)


def service_targets(
    *,
    positions: Array,
    quaternions: Array,
    use_orientation: bool,
    frame_id: str,
    model: RobotModel,
    calibrated: RobotModel,
    seed_joints: list[float],
) -> tuple[Targets, str, Array | None]:
    """The ``~/compensate_targets`` request (``srv/CompensateTargets``) as :func:`compensate`'s arguments.

    Parameters
    ----------
    positions : ndarray, shape (n, 3) [m]
    quaternions : ndarray, shape (n, 4)
        ``x, y, z, w``; used only with `use_orientation`.
    use_orientation : bool
    frame_id : str
        The PoseArray's ``header.frame_id``: the calibration's measurement or base frame.
    model, calibrated : RobotModel
        The nominal model and the calibrated one (its frame ids and base).
    seed_joints : list of float
        Flattened seeds [rad]; empty: none.

    Returns
    -------
    targets, frame, seeds

    Raises
    ------
    InputError
        No targets, NaN, a frame that is neither of the calibration's, seeds of the wrong size.
    """
    from robocal_uncertainty.core.rotation import quaternion_to_matrix

    points = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if points.shape[0] == 0:
        raise InputError("the PoseArray has no pose")
    if not np.isfinite(points).all():
        raise InputError("a target position is NaN or inf")
    frames = {calibrated.measurement_frame_id: "measurement", calibrated.base_frame_id: "base"}
    if frame_id not in frames:
        msg = (
            f"targets in frame {frame_id!r}: give them in the measurement frame {calibrated.measurement_frame_id!r} "
            f"or the robot base frame {calibrated.base_frame_id!r}"
        )
        raise InputError(msg)
    rotations = None
    if use_orientation:
        rotations = quaternion_to_matrix(
            np.asarray(quaternions, dtype=np.float64).reshape(-1, 4), name="target orientation"
        )
    seeds = None
    if seed_joints:
        values = np.asarray(seed_joints, dtype=np.float64)
        if values.size % model.n_joints or not np.isfinite(values).all():
            msg = f"seed_joints: {values.size} values, not finite multiples of the robot's {model.n_joints} joints"
            raise InputError(msg)
        seeds = values.reshape(-1, model.n_joints)
    targets = Targets(
        points,
        rotations,
        f"PoseArray in {frame_id}",
        "m",
        "rad" if use_orientation else "",
        "quaternion" if use_orientation else "none",
    )
    return targets, frames[frame_id], seeds


def service_response(result: Compensation) -> dict[str, Any]:
    """The ``srv/CompensateTargets`` response fields of a :class:`Compensation` (SI units)."""
    n = result.joints.shape[0]
    joints = np.where(result.accepted[:, None], result.joints, np.nan)
    u = np.full((n, 3), np.nan)
    big_u = np.full((n, 3), np.nan)
    unc = result.uncertainty
    if unc is not None:
        for k, i in enumerate(np.flatnonzero(result.accepted)):
            u[i] = [a.standard_uncertainty for a in unc.poses[k].axes]
            big_u[i] = [a.expanded_uncertainty for a in unc.poses[k].axes]
    refused = n - int(result.accepted.sum())
    return {
        "success": True,
        "message": f"{int(result.accepted.sum())} of {n} targets compensated in {result.frame_id}"
        + (f", {refused} refused (see status)" if refused else "")
        + f"; seeds: {result.seed_source}",
        "joint_names": list(result.joint_names),
        "joint_positions": joints.reshape(-1).tolist(),
        "status": list(result.status),
        "position_error": result.solution.position_error_m.tolist(),
        "standard_uncertainty": u.reshape(-1).tolist(),
        "expanded_uncertainty": big_u.reshape(-1).tolist(),
        "coverage_probability": float("nan") if unc is None else unc.coverage_probability,
        "trials": 0 if unc is None else int(unc.n_trials),
        "frame_id": result.frame_id,
    }
