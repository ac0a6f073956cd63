"""Batched re-identification: many perturbed campaigns solved at once.

One Monte Carlo trial is a full re-identification. Here all trials of a chunk share the
nominal structure (which parameters are estimated, the column scaling) and are solved
together: batched Jacobians, batched regularised normal equations, no Python loop over
trials. Each trial has its own joint readings, measured values, pose weights (0/1 for subsets)
and lambda. The iteration is the same Tikhonov Gauss-Newton as
:func:`robocal_uncertainty.core.identification.identify`, warm-started at the calibration, on
the equations of the campaign's measurement type
(:class:`~robocal_uncertainty.core.measurement.MeasurementType`: its dimension, residual,
Jacobian and weights), so a new type needs no change here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.measurement import (
    POINT,
    MeasurementType,
    joint_columns,
    stack_jacobian,
    stack_residual,
)
from robocal_uncertainty.core.robot_model import ParameterLayout

__all__ = ["BatchProblem", "ChordSolver", "StepFactors", "reidentify_batch"]

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class BatchProblem:
    """The fixed structure shared by all trials.

    Attributes
    ----------
    layout : ParameterLayout
    start : ndarray, shape (n_params,) [m, rad]
        Nominal parameters (the Tikhonov penalty is on the deviation from these).
    estimated : ndarray of int, shape (k,)
        Indices of the estimated parameters.
    scale : ndarray, shape (k,)
        Column scaling of the estimated parameters.
    penalized : ndarray of bool, shape (k,), optional
        Which estimated parameters the Tikhonov term penalises (all but the base, see
        :func:`robocal_uncertainty.core.identification.identify`); None penalises all.
    measurement : MeasurementType
        What each pose measures (tool points by default).
    """

    layout: ParameterLayout
    start: Array
    estimated: NDArray[np.intp]
    scale: Array
    penalized: NDArray[np.bool_] | None = None
    measurement: MeasurementType = POINT

    @classmethod
    def from_calibration(cls, calibration: IdentificationResult) -> BatchProblem:
        """The structure of `calibration`: its start, estimated set, scaling, penalty and type."""
        est = np.flatnonzero(calibration.estimated)
        return cls(
            layout=calibration.model.layout,
            start=calibration.nominal,
            estimated=est,
            scale=calibration.column_scale[est],
            penalized=calibration.penalized[est],
            measurement=calibration.measurement,
        )

    @property
    def penalty_mask(self) -> Array:
        """1.0 for penalised, 0.0 for free estimated parameters, shape (k,)."""
        if self.penalized is None:
            return np.ones(self.estimated.size)
        return np.asarray(self.penalized, dtype=np.float64)

    def parameters(self, x: Array) -> Array:
        """Full parameter vectors (T, n_params) from scaled deviations x (T, k)."""
        p = np.repeat(self.start[None, :], x.shape[0], axis=0)
        p[:, self.estimated] += x / self.scale
        return p

    def scaled_deviation(self, params: Array) -> Array:
        """Scaled deviations x (..., k) of full parameter vectors (..., n_params) from the start."""
        return (params[..., self.estimated] - self.start[self.estimated]) * self.scale


def reidentify_batch(
    problem: BatchProblem,
    joint_positions: Array,
    measured: Array,
    weights: Array | None,
    lambdas: Array,
    x_start: Array,
    *,
    iterations: int,
    tolerance: float = 1e-12,
) -> tuple[Array, int]:
    """Solve T regularised identifications at once.

    Parameters
    ----------
    problem : BatchProblem
    joint_positions : ndarray, shape (T, n_poses, n_joints) or (n_poses, n_joints) [rad]
    measured : ndarray, shape (T, n_poses, value_size) [m for points]
        Measured values of each trial (``problem.measurement``'s; points by default).
    weights : ndarray, shape (T, n_poses), or None
        1 for poses used by a trial, 0 for poses left out; None uses all.
    lambdas : ndarray, shape (T,)
        Regularisation parameter of each trial (scaled units).
    x_start : ndarray, shape (k,) or (T, k)
        Starting scaled deviation (the calibration's).
    iterations : int
        Maximum Gauss-Newton iterations.
    tolerance : float
        Stop when every trial's scaled step is below ``tolerance * (1 + ||x||)``.

    Returns
    -------
    x : ndarray, shape (T, k)
        Scaled deviations from nominal of every trial.
    iterations_run : int
    """
    measurement = problem.measurement
    n_trials = measured.shape[0]
    k = problem.estimated.size
    x = np.array(np.broadcast_to(x_start, (n_trials, k)), dtype=np.float64)
    lam2 = (np.asarray(lambdas, dtype=np.float64) ** 2)[:, None, None] * np.diag(problem.penalty_mask)
    w = None if weights is None else np.repeat(weights, measurement.dimension, axis=1)[:, :, None]
    done = 0
    for done in range(1, iterations + 1):
        p = problem.parameters(x)
        pred, jac = measurement.predict_and_jacobian(problem.layout, p, joint_positions)
        a_mat = stack_jacobian(measurement, jac, problem.estimated)
        a_mat /= problem.scale
        r = stack_residual(measurement, measurement.residual(measured, pred))
        b = r + np.einsum("tek,tk->te", a_mat, x)
        aw = a_mat if w is None else a_mat * w
        normal = np.matmul(aw.transpose(0, 2, 1), a_mat) + lam2
        rhs = np.einsum("tek,te->tk", aw, b)
        x_new = np.linalg.solve(normal, rhs[..., None])[..., 0]
        step = np.linalg.norm(x_new - x, axis=1)
        x = x_new
        if np.all(step <= tolerance * (1.0 + np.linalg.norm(x, axis=1))):
            break
    return x, done


@dataclass(frozen=True, eq=False)
class StepFactors:
    """:meth:`ChordSolver._step`'s factors, contiguous, as a compiled kernel takes them (each
    product a dot product of contiguous rows).

    Attributes
    ----------
    penalized, free : ndarray of int64, shape (k_pen,), (k_free,)
        Indices of the penalised and the free estimated parameters.
    coupling : ndarray, shape (k_pen, k_free)
    eigenvectors, eigenvectors_t : ndarray, shape (k_pen, k_pen)
        The Schur complement's eigenvectors as columns, and as rows.
    eigenvalues : ndarray, shape (k_pen,)
    normal_fp : ndarray, shape (k_free, k_pen)
        ``N_pf`` transposed.
    free_inverse_t : ndarray, shape (k_free, k_free)
        ``N_ff^-1`` transposed.
    """

    penalized: NDArray[np.int64]
    free: NDArray[np.int64]
    coupling: Array
    eigenvectors: Array
    eigenvectors_t: Array
    eigenvalues: Array
    normal_fp: Array
    free_inverse_t: Array

    def as_tuple(self) -> tuple[NDArray[np.int64], NDArray[np.int64], Array, Array, Array, Array, Array, Array]:
        """In the order the kernel unpacks them."""
        return (
            self.penalized,
            self.free,
            self.coupling,
            self.eigenvectors,
            self.eigenvectors_t,
            self.eigenvalues,
            self.normal_fp,
            self.free_inverse_t,
        )


@dataclass(frozen=True, eq=False)
class ChordSolver:
    """Re-identification by the chord (simplified Newton) method, all trials at once.

    Each trial minimises the same regularised objective as :func:`identify`,
    ``||W^1/2 (S_t - F(p, Q_t))||^2 + lambda_t^2 ||x||^2``, iterating with the exact
    residual of its own readings, measured values and pose weights but with the Jacobian
    frozen at the calibration (equations whitened by the measurement type's weights).
    Perturbations in a Monte Carlo are tiny (micrometres, millidegrees),
    so the Jacobian moves by ~1e-4 relative and the chord iteration converges to the
    trial's own solution to well below 1e-6 of its deviation in two or three steps,
    while the normal matrix is factorised once instead of per trial. The exact batched
    Gauss-Newton (:func:`reidentify_batch`) is kept as the reference it is tested against.

    The first step needs no kinematics: the prediction at the calibration's parameters and
    the trial's readings is replaced by its first-order expansion in the reading errors,
    ``F(p, Q + dQ) ~ F(p, Q) + J_q dQ``, which enters the right-hand side as one product
    ``dQ @ joint_map``. What that leaves out (second order in the micro-radian reading errors,
    ~1e-4 of the step on the reference paper's case) is of the size of what the chord step itself leaves
    out, so the next, exact step brings the trial as close to its solution as two exact steps
    did (~3e-8 of its deviation, against ~1e-4 after the first); each trial then stops by the
    same rule as before, and only the trials that need more steps take them.

    Parameters the Tikhonov term does not penalise (the base) are eliminated by a Schur
    complement, so one eigen-decomposition still serves every lambda.

    Attributes
    ----------
    problem : BatchProblem
    jacobian : ndarray, shape (dimension * n_poses, k)
        Column-scaled (and whitened) Jacobian at the calibration, ``dimension`` the
        measurement type's equations per pose.
    pose_normal : ndarray, shape (n_poses, k * k)
        Per-pose contributions ``J_i^T J_i`` to the normal matrix, flattened.
    eigenvalues : ndarray, shape (k_pen,)
    eigenvectors : ndarray, shape (k_pen, k_pen)
        Eigen-decomposition of the Schur complement ``G = N_pp - N_pf N_ff^-1 N_fp`` of the
        normal matrix ``N = J^T J`` on the penalised parameters (``N`` itself when all are).
    coupling : ndarray, shape (k_pen, k_free)
        ``N_pf N_ff^-1``.
    free_inverse : ndarray, shape (k_free, k_free)
        ``N_ff^-1``.
    normal : ndarray, shape (k, k)
        ``N = J^T J``.
    joints : ndarray, shape (n_poses, n_joints) [rad]
        Readings the Jacobian is frozen at.
    reference : ndarray, shape (n_poses, value_size)
        The measurement type's prediction at the frozen parameters and `joints`.
    joint_map : ndarray, shape (n_poses * n_joints, k)
        ``J_q^T J``: a reading error ``dQ`` (flattened pose by pose) moves the right-hand side
        ``r^T J`` of the normal equations by ``-dQ @ joint_map`` to first order (``J_q`` the
        whitened, block-diagonal Jacobian of the equations with respect to the readings).
    predictor : callable or None
        ``predictor(params, joint_positions)``: the measurement type's prediction near the
        calibration (:meth:`~robocal_uncertainty.core.measurement.MeasurementType.nearby_predictor`),
        or None for its plain ``predict``. A predictor with a ``solve_chord`` method (a
        compiled backend's) is handed the whole iteration of :meth:`solve`.
    joint_jacobian : ndarray, shape (n_poses, dimension, n_joints), or None
        ``J_q`` pose by pose (whitened): a compiled iteration takes the first step's
        right-hand side as ``(r - J_q dQ) J``, the same as ``r J - dQ @ joint_map`` with a
        fraction of the products.
    """

    problem: BatchProblem
    jacobian: Array
    pose_normal: Array
    eigenvalues: Array
    eigenvectors: Array
    coupling: Array
    free_inverse: Array
    normal: Array
    joints: Array
    reference: Array
    joint_map: Array
    predictor: Callable[[Array, Array], Array] | None = None
    joint_jacobian: Array | None = None

    @classmethod
    def at(cls, problem: BatchProblem, params: Array, joint_positions: Array) -> ChordSolver:
        """Freeze the Jacobian at `params` (n_params,) and readings (n_poses, n_joints)."""
        measurement = problem.measurement
        joints = np.array(joint_positions, dtype=np.float64)
        reference, jac = measurement.predict_and_jacobian(problem.layout, params, joints)
        n_poses, n_joints = joints.shape
        k = problem.estimated.size
        per_pose = jac[:, :, problem.estimated] / problem.scale  # (n_poses, dimension, k)
        per_joint = jac[:, :, joint_columns(problem.layout)]  # (n_poses, dimension, n_joints)
        if measurement.weights is not None:
            per_pose = per_pose * measurement.weights[:, None]
            per_joint = per_joint * measurement.weights[:, None]
        joint_map = np.einsum("pij,pik->pjk", per_joint, per_pose).reshape(n_poses * n_joints, k)
        pose_normal = np.einsum("pik,pil->pkl", per_pose, per_pose).reshape(n_poses, k * k)
        a_mat = per_pose.reshape(measurement.dimension * n_poses, k)
        normal = a_mat.T @ a_mat
        pen = problem.penalty_mask > 0
        free_inverse: Array = np.linalg.inv(normal[np.ix_(~pen, ~pen)]).astype(np.float64, copy=False)
        coupling = normal[np.ix_(pen, ~pen)] @ free_inverse
        schur = normal[np.ix_(pen, pen)] - coupling @ normal[np.ix_(~pen, pen)]
        evals, evecs = np.linalg.eigh(schur)
        predictor = measurement.nearby_predictor(problem.layout, params, joint_positions)
        return cls(
            problem=problem,
            jacobian=a_mat,
            pose_normal=pose_normal,
            eigenvalues=evals,
            eigenvectors=evecs,
            coupling=coupling,
            free_inverse=free_inverse,
            normal=normal,
            joints=joints,
            reference=reference,
            joint_map=np.ascontiguousarray(joint_map),
            predictor=predictor,
            joint_jacobian=_contiguous(per_joint),
        )

    @cached_property
    def transposed_jacobian(self) -> Array:
        """:attr:`jacobian` transposed, shape (k, dimension * n_poses), contiguous."""
        return _contiguous(self.jacobian.T)

    @cached_property
    def contiguous_pose_normal(self) -> Array:
        """:attr:`pose_normal` contiguous (an einsum's result may not be), copied once per solver
        for a compiled iteration rather than once per sub-batch."""
        return _contiguous(self.pose_normal)

    @cached_property
    def kernel_arrays(self) -> tuple[Array, NDArray[np.int64], Array, Array, Array, Array, Array]:
        """The problem's start (n_params,), estimated indices (k,), scaling (k,) and penalty
        mask (k,), the whitening per component (dimension,; ones for none), the reference
        prediction (n_poses, value_size) and readings (n_poses, n_joints): contiguous, for a
        compiled iteration (built once per solver, not per sub-batch)."""
        problem = self.problem
        whitening = problem.measurement.weights
        return (
            _contiguous(problem.start),
            np.array(problem.estimated, dtype=np.int64),
            _contiguous(problem.scale),
            _contiguous(problem.penalty_mask),
            np.ones(problem.measurement.dimension) if whitening is None else _contiguous(whitening),
            _contiguous(self.reference),
            _contiguous(self.joints),
        )

    @cached_property
    def step_factors(self) -> StepFactors:
        """The pieces of :meth:`_step` as contiguous arrays, for a compiled iteration."""
        pen = self.problem.penalty_mask > 0
        return StepFactors(
            penalized=np.flatnonzero(pen).astype(np.int64),
            free=np.flatnonzero(~pen).astype(np.int64),
            coupling=_contiguous(self.coupling),
            eigenvectors=_contiguous(self.eigenvectors),
            eigenvectors_t=_contiguous(self.eigenvectors.T),
            eigenvalues=_contiguous(self.eigenvalues),
            normal_fp=_contiguous(self.normal[np.ix_(pen, ~pen)].T),
            free_inverse_t=_contiguous(self.free_inverse.T),
        )

    def _step(self, rhs: Array, lam2: Array) -> Array:
        """Solve ``(N + lam^2 M) step = rhs`` for all trials, M the penalty mask."""
        pen = self.problem.penalty_mask > 0
        rhs_p = rhs[:, pen]
        rhs_f = rhs[:, ~pen]
        if rhs_f.shape[1]:
            rhs_p = rhs_p - rhs_f @ self.coupling.T
        step = np.empty_like(rhs)
        step_p = ((rhs_p @ self.eigenvectors) / (self.eigenvalues + lam2)) @ self.eigenvectors.T
        step[:, pen] = step_p
        if rhs_f.shape[1]:
            step[:, ~pen] = (rhs_f - step_p @ self.normal[np.ix_(pen, ~pen)]) @ self.free_inverse
        return step

    def solve(
        self,
        joint_positions: Array,
        measured: Array,
        weights: Array | None,
        lambdas: Array,
        x_start: Array,
        *,
        initial_prediction: Array | None = None,
        max_iterations: int = 6,
        relative_tolerance: float = 1e-3,
        linear_start: bool = True,
        deviations: Array | None = None,
        reading_errors: Array | None = None,
    ) -> tuple[Array, int]:
        """Solve T regularised identifications.

        Parameters
        ----------
        joint_positions : ndarray, shape (T, n_poses, n_joints) or (n_poses, n_joints) [rad]
        measured : ndarray, shape (T, n_poses, value_size) [m for points]: each trial's values
        weights : ndarray, shape (T, n_poses), or None
            Pose weights (0/1 for subsets); None uses every pose.
        lambdas : ndarray, shape (T,)
            Regularisation parameter per trial (scaled units).
        x_start : ndarray, shape (k,)
            Calibration's scaled deviation from nominal (where the Jacobian is frozen).
        initial_prediction : ndarray, shape (n_poses, value_size) [m for points], optional
            ``F(p_start, Q)`` (the measurement type's prediction) when every trial shares
            the readings Q and `linear_start` is false (saves one kinematics pass).
        max_iterations : int
            Steps per trial at most, the first included.
        relative_tolerance : float
            A trial stops when its step is below this fraction of its first step (the chord
            iteration contracts by ~1e-4 per step: two steps usually suffice, leaving ~3e-8
            of the trial's deviation, ~1e-12 m on the reference paper's case against a 14-digit solution).
        linear_start : bool
            Take the first step from the first-order prediction ``reference + J_q dQ`` (no
            kinematics, see the class docstring); false evaluates the prediction at the
            start exactly (the method before this option, kept as its reference).
        deviations, reading_errors : ndarray, shape (T, n_poses, dimension), (T, n_poses, n_joints)
            Errors: the trials measure ``perturb(measured (1, n_poses, value_size), deviations)``
            at ``joint_positions (n_poses, n_joints) + reading_errors`` (a compiled iteration
            applies them itself, without copies).

        Returns
        -------
        x : ndarray, shape (T, k)
        iterations_run : int
            The most steps any trial took.
        """
        if linear_start:
            # A backend's compiled iteration (the same steps, trial by trial), if it takes the block.
            solved = self._compiled(
                joint_positions,
                measured,
                weights,
                lambdas,
                x_start,
                (max_iterations, relative_tolerance, deviations, reading_errors),
            )
            if solved is not None:
                return solved
        joint_positions, measured = self._with_errors(joint_positions, measured, deviations, reading_errors)
        n_trials = measured.shape[0]
        lam2 = np.asarray(lambdas, dtype=np.float64)[:, None] ** 2
        x = np.repeat(x_start[None, :], n_trials, axis=0)
        w_rows = None if weights is None else np.repeat(weights, self.problem.measurement.dimension, axis=1)
        normal = self._weighted_normals(weights, lam2, x_start.size)
        q = np.asarray(joint_positions, dtype=np.float64)
        rhs = self._first_rhs(q, measured, weights, w_rows, x, linear_start, initial_prediction)
        rhs -= lam2 * (x * self.problem.penalty_mask)
        step = self._solve(rhs, lam2, normal)
        x += step
        first = np.maximum(np.linalg.norm(step, axis=1), np.finfo(float).tiny)
        done = self._exact_steps(x, q, measured, w_rows, (lam2, normal, first), max_iterations, relative_tolerance)
        return x, done

    def _first_rhs(
        self,
        q: Array,
        measured: Array,
        weights: Array | None,
        w_rows: Array | None,
        x: Array,
        linear_start: bool,
        initial_prediction: Array | None,
    ) -> Array:
        """Right-hand side of the first step, at the start: from the first-order prediction
        (`linear_start`) or the exact one (`initial_prediction`, computed when None)."""
        if linear_start:
            return self._linear_rhs(q, measured, weights, w_rows)
        pred = initial_prediction if initial_prediction is not None else self._predict(x, q)
        r = stack_residual(self.problem.measurement, self.problem.measurement.residual(measured, pred))
        if w_rows is not None:
            r = r * w_rows
        return r @ self.jacobian

    def _compiled(
        self,
        joint_positions: Array,
        measured: Array,
        weights: Array | None,
        lambdas: Array,
        x_start: Array,
        settings: tuple[int, float, Array | None, Array | None],
    ) -> tuple[Array, int] | None:
        """:meth:`solve` by the predictor's compiled iteration (``solve_chord``), or None;
        `settings` the most steps, the relative tolerance and the measurement and reading errors."""
        max_iterations, relative_tolerance, deviations, reading_errors = settings
        kernel = getattr(self.predictor, "solve_chord", None)
        if kernel is None:
            return None
        solved: tuple[Array, int] | None = kernel(
            self,
            joint_positions,
            measured,
            weights,
            lambdas,
            x_start,
            max_iterations=max_iterations,
            relative_tolerance=relative_tolerance,
            **({} if deviations is None else {"deviations": deviations}),
            **({} if reading_errors is None else {"reading_errors": reading_errors}),
        )
        return solved

    def _with_errors(
        self, joint_positions: Array, measured: Array, deviations: Array | None, reading_errors: Array | None
    ) -> tuple[Array, Array]:
        """The trials' readings and measured values, the errors (when given) applied."""
        if deviations is not None:
            measured = self.problem.measurement.perturb(measured, deviations)
        if reading_errors is not None:
            joint_positions = joint_positions[None] + reading_errors
        return joint_positions, measured

    def _weighted_normals(self, weights: Array | None, lam2: Array, k: int) -> Array | None:
        """Per-trial normal matrices ``sum_i w_i J_i^T J_i + lam^2 M`` (T, k, k); None without weights."""
        if weights is None:
            return None
        normal: Array = (weights @ self.pose_normal).reshape(weights.shape[0], k, k)
        normal += lam2[:, :, None] * np.diag(self.problem.penalty_mask)
        return normal

    def _linear_rhs(self, q: Array, measured: Array, weights: Array | None, w_rows: Array | None) -> Array:
        """The first step's right-hand side from the first-order prediction ``reference + J_q dQ``."""
        measurement = self.problem.measurement
        n_trials = measured.shape[0]
        r = stack_residual(measurement, measurement.residual(measured, self.reference))
        if w_rows is not None:
            r = r * w_rows
        rhs: Array = r @ self.jacobian
        dq = q - self.joints
        if dq.ndim == 3 or np.any(dq):
            dq = np.broadcast_to(dq, (n_trials, *self.joints.shape))
            if weights is not None:
                dq = dq * weights[:, :, None]
            rhs -= dq.reshape(n_trials, -1) @ self.joint_map
        return rhs

    def _exact_steps(
        self,
        x: Array,
        q: Array,
        measured: Array,
        w_rows: Array | None,
        state: tuple[Array, Array | None, Array],
        max_iterations: int,
        relative_tolerance: float,
    ) -> int:
        """Exact steps on x (T, k) in place, each for the trials whose last step was not yet
        below `relative_tolerance` of their first; `state` is lambda^2 (T, 1), the per-trial
        normal matrices (or None) and the first steps' norms (T,). Returns the most steps."""
        lam2, normal, first = state
        measurement = self.problem.measurement
        mask = self.problem.penalty_mask
        active: slice | NDArray[np.intp] = slice(None)  # all trials, without copying their data
        done = 1
        for done in range(2, max_iterations + 1):
            xa = x[active]
            qa = q if q.ndim == 2 else q[active]
            r = stack_residual(measurement, measurement.residual(measured[active], self._predict(xa, qa)))
            if w_rows is not None:
                r *= w_rows[active]
            rhs = r @ self.jacobian - lam2[active] * (xa * mask)
            step = self._solve(rhs, lam2[active], None if normal is None else normal[active])
            x[active] = xa + step
            more = np.linalg.norm(step, axis=1) > relative_tolerance * first[active]
            if not more.any():
                break
            active = np.arange(x.shape[0])[active][more]
        return done

    def _predict(self, x: Array, joint_positions: Array) -> Array:
        """The measurement type's prediction at scaled deviations x (T, k) and the readings."""
        params = self.problem.parameters(x)
        if self.predictor is not None:
            return self.predictor(params, joint_positions)
        return self.problem.measurement.predict(self.problem.layout, params, joint_positions)

    def _solve(self, rhs: Array, lam2: Array, normal: Array | None) -> Array:
        """The step for right-hand sides (T, k): per-trial normal matrices (weights), or shared."""
        if normal is not None:
            return np.asarray(np.linalg.solve(normal, rhs[..., None])[..., 0], dtype=np.float64)
        return self._step(rhs, lam2)


def _contiguous(values: Array) -> Array:
    """A C-contiguous, writeable float64 copy (what a compiled kernel is compiled for)."""
    return np.array(values, dtype=np.float64, order="C")
