"""Which parameters a campaign's measurements can identify, and which pose sets fail.

With position-only measurements (points, the default measurement type) some parameter
combinations move the measured point identically for every pose (joint-1 offset and base yaw,
d1 and base z, joint-6 offset and the tool point, the d of parallel axes). They are
structurally not identifiable: fixing one of each dependent group at its nominal value loses
nothing. They are found once per model on a rich random pose set, by a
greedy rank test in a fixed order of preference (base, tool, joints in order, then the mount of a
URDF model), so the
choice is deterministic and matches common practice (keep the base yaw, drop theta1).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.measurement import POINT, MeasurementType, stack_jacobian
from robocal_uncertainty.core.robot_model import RobotModel

__all__ = ["Observability", "describe_dependency", "structural_observability"]

_STRUCTURAL_TOL = 1e-7
_N_PROBE_POSES = 200


@dataclass(frozen=True)
class Observability:
    """Result of the structural identifiability analysis.

    Attributes
    ----------
    candidates : ndarray of bool, shape (n_params,)
        Parameters one asked to estimate.
    identifiable : ndarray of bool, shape (n_params,)
        Candidates that the measurements can identify (a maximal independent set).
    dependencies : tuple of str
        For each candidate left out, the combination of kept parameters it duplicates,
        e.g. ``"joint1.d = 1 * base.z"``.
    """

    candidates: NDArray[np.bool_]
    identifiable: NDArray[np.bool_]
    dependencies: tuple[str, ...]


def describe_dependency(dependency: str) -> str:
    """Readable form of one `Observability.dependencies` line, for consoles and reports.

    ``"joint3.d = 1 * joint2.d"`` becomes ``"joint3.d and joint2.d act alike (column of
    joint3.d = 1 × column of joint2.d): only their combination is identifiable"``; other
    lines come back unchanged.
    """
    name, sep, rhs = dependency.partition(" = ")
    if not sep:
        return dependency
    terms = re.findall(r"([+-]?\s*[0-9.eE+-]+) \* (\S+)", rhs)
    if not terms:
        return dependency
    others = [other for _, other in terms]
    expr = " ".join(f"{coef.strip()} × column of {other}" for coef, other in terms).replace(" -", " − ")
    subject = f"{name} and {' and '.join(others)}" if len(others) == 1 else f"{name}, {', '.join(others)}"
    return f"{subject} act alike (column of {name} = {expr}): only their combination is identifiable"


def _probe_poses(model: RobotModel) -> NDArray[np.float64]:
    # A fixed private stream: the analysis is a property of the model, not of any run.
    rng = np.random.default_rng(20231101)
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    return rng.uniform(lo, hi, size=(_N_PROBE_POSES, model.n_joints))


def structural_observability(
    model: RobotModel,
    params: NDArray[np.float64],
    candidates: NDArray[np.bool_],
    *,
    measurement: MeasurementType = POINT,
) -> Observability:
    """Find a maximal identifiable subset of the candidate parameters.

    Parameters
    ----------
    model : RobotModel
        Structure of the parameter vector and joint limits for the probe poses.
    params : ndarray, shape (n_params,) [m, rad]
        Linearisation point (nominal or current estimate).
    candidates : ndarray of bool, shape (n_params,)
        Which parameters one wants to estimate.
    measurement : MeasurementType
        What each pose measures (points by default); its equations, whitened by its weights,
        are the rows of the rank test.
    """
    layout = model.layout
    probe = _probe_poses(model)
    _, jac_poses = measurement.predict_and_jacobian(layout, params, probe)
    jac = stack_jacobian(measurement, jac_poses)
    norms = np.linalg.norm(jac, axis=0)
    # Exact zeros come out as round-off; anything 1e-9 below the largest column is no motion.
    norms = np.where(norms > 1e-9 * norms.max(), norms, 0.0)
    names = layout.names
    order = [k for k in range(layout.size) if names[k].startswith("base.")]
    order += [k for k in range(layout.size) if names[k].startswith("tool.")]
    order += [k for k in range(layout.size) if names[k].startswith("joint")]
    order += [k for k in range(layout.size) if names[k].startswith("mount.")]
    kept: list[int] = []
    dropped: list[int] = []
    basis = np.zeros((jac.shape[0], 0))
    for k in order:
        if not candidates[k]:
            continue
        if norms[k] == 0.0:
            dropped.append(k)
            continue
        col = jac[:, k] / norms[k]
        resid = col - basis @ (basis.T @ col)
        if np.linalg.norm(resid) > _STRUCTURAL_TOL:
            basis = np.column_stack((basis, resid / np.linalg.norm(resid)))
            kept.append(k)
        else:
            dropped.append(k)
    identifiable = np.zeros(layout.size, dtype=bool)
    identifiable[kept] = True
    deps = []
    for k in sorted(dropped):
        if norms[k] == 0.0:
            deps.append(f"{names[k]} does not move the {measurement.quantity}")
            continue
        coef, *_ = np.linalg.lstsq(jac[:, kept], jac[:, k], rcond=None)
        big = np.argsort(-np.abs(coef))
        terms = [f"{coef[i]:+.4g} * {names[kept[i]]}" for i in big[:4] if abs(coef[i]) > 1e-6 * np.abs(coef).max()]
        deps.append(f"{names[k]} = " + " ".join(terms).lstrip("+ "))
    return Observability(
        candidates=np.asarray(candidates, dtype=bool).copy(),
        identifiable=identifiable,
        dependencies=tuple(deps),
    )
