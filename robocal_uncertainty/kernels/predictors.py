"""Predictors of the tool near a reference, for the compiled and the array-module backends.

Both have the interface of :class:`~robocal_uncertainty.core.kinematics.NearbyPoints`:
``predictor(params, joint_positions)`` gives tool points (..., n_poses, 3) and
``predictor.poses(params, joint_positions)`` the stored 6-DOF values (..., n_poses, 12), in the
measurement frame, for parameters (..., n_params) and readings (..., n_poses, n_joints) whose
leading dimensions broadcast (one of them shared, or both n_trials). They are picklable
(process and Dask workers rebuild nothing but the arrays).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.kernels._layout import FlatLayout, flat_layout, reference_angles

__all__ = ["ArrayModulePredictor", "CompiledMeasurement", "CompiledPredictor"]

Array = NDArray[np.float64]


def _batched(
    layout: ParameterLayout, params: Array, joint_positions: Array, n_poses: int
) -> tuple[Array, Array, tuple[int, ...]]:
    """Parameters (n_p, n_params) and readings (n_q, n_poses, n_joints), C-contiguous, and the
    leading shape of the result."""
    p = np.asarray(params, dtype=np.float64)
    q = np.asarray(joint_positions, dtype=np.float64)
    if p.shape[-1:] != (layout.size,):
        msg = f"params must have shape (..., {layout.size}), got {p.shape}"
        raise ValueError(msg)
    if q.ndim < 2 or q.shape[-2:] != (n_poses, layout.n_joints):
        msg = f"joint_positions must have shape (..., {n_poses}, {layout.n_joints}), got {q.shape}"
        raise ValueError(msg)
    batch = np.broadcast_shapes(p.shape[:-1], q.shape[:-2])
    n = math.prod(batch)
    pf = p.reshape(1, layout.size) if p.ndim == 1 else np.broadcast_to(p, (*batch, layout.size)).reshape(n, layout.size)
    qf = (
        q.reshape(1, n_poses, layout.n_joints)
        if q.ndim == 2
        else np.broadcast_to(q, (*batch, n_poses, layout.n_joints)).reshape(n, n_poses, layout.n_joints)
    )
    return _kernel_array(pf), _kernel_array(qf), batch


_SCRATCH = threading.local()
"""Per thread: reused buffers of the per-trial inputs that arrive strided (see :func:`_scratch_array`)."""


def _scratch_array(name: str, values: Array) -> Array:
    """`values` as :func:`_kernel_array` gives it, copied into a buffer this thread reuses call after call.

    The reading errors of a sub-batch arrive as a strided view (one segment of a source's
    draws): a fresh copy of megabytes costs mostly the first touch of its pages, a reused
    buffer only the copy. The buffer is read by one kernel call and overwritten by the next.
    """
    if values.flags.c_contiguous and values.flags.writeable and values.dtype == np.float64:
        return values
    buffers: dict[str, Array] = _SCRATCH.__dict__.setdefault("buffers", {})
    buffer = buffers.get(name)
    if buffer is None or buffer.shape != values.shape:
        buffer = buffers[name] = np.empty(values.shape)
    np.copyto(buffer, values)
    return buffer


def _kernel_array(values: Array) -> Array:
    """C-contiguous and writeable: numba compiles one specialisation per array type, and a
    read-only array is another type (another compilation, ~15 s, on first use)."""
    out = np.ascontiguousarray(values, dtype=np.float64)
    return out if out.flags.writeable else out.copy()


@dataclass(frozen=True, eq=False)
class CompiledPredictor:
    """The tool near a reference by the numba kernel (:mod:`~robocal_uncertainty.kernels._numba_walk`).

    Attributes
    ----------
    layout : ParameterLayout
    flat : FlatLayout
    joints : ndarray, shape (n_poses, n_joints)
        Reference readings.
    theta : ndarray, shape (n_joints,)
        Reference joint offsets.
    cos_ref, sin_ref : ndarray, shape (n_joints, n_poses)
        Of the reference angles, joint by joint (contiguous over the poses).
    reference_params : ndarray, shape (n_params,)
        The reference parameters (the link angles' cosines and sines are taken near them).
    """

    layout: ParameterLayout
    flat: FlatLayout
    joints: Array
    theta: Array
    cos_ref: Array
    sin_ref: Array
    reference_params: Array

    @classmethod
    def at(cls, layout: ParameterLayout, params: Array, joint_positions: Array) -> CompiledPredictor:
        """Reference at `params` (n_params,) and readings (n_poses, n_joints)."""
        params = np.asarray(params, dtype=np.float64)
        joints = np.array(joint_positions, dtype=np.float64, order="C")  # a writeable copy
        angles = reference_angles(layout, params, joints).T
        theta = params[[idx["theta"] for idx in layout.joint_slices()]]
        return cls(
            layout,
            flat_layout(layout),
            joints,
            theta,
            np.ascontiguousarray(np.cos(angles)),
            np.ascontiguousarray(np.sin(angles)),
            np.array(params, dtype=np.float64),
        )

    @cached_property
    def parameter_trig(self) -> tuple[Array, Array, Array]:
        """The reference parameters, their cosines and their sines, each (n_params,)."""
        p = np.array(self.reference_params, dtype=np.float64)
        return p, np.cos(p), np.sin(p)

    @cached_property
    def reference_readings(self) -> Array:
        """The reference readings joint by joint, shape (n_joints, n_poses), contiguous."""
        return np.ascontiguousarray(self.joints.T)

    def __call__(self, params: Array, joint_positions: Array) -> Array:
        """Tool points (..., n_poses, 3) [m]."""
        return self._run(params, joint_positions, poses=False)

    def poses(self, params: Array, joint_positions: Array) -> Array:
        """Stored 6-DOF values (..., n_poses, 12): the point [m], then ``world_R_tool`` row by row."""
        return self._run(params, joint_positions, poses=True)

    def _run(self, params: Array, joint_positions: Array, *, poses: bool) -> Array:
        from robocal_uncertainty.kernels._numba_walk import chunk_count, walk

        n_poses = self.joints.shape[0]
        p, q, batch = _batched(self.layout, params, joint_positions, n_poses)
        out = np.empty((max(p.shape[0], q.shape[0]), n_poses, 12 if poses else 3))
        walk(
            p,
            q,
            self.flat.joints,
            self.flat.blocks,
            self.reference_readings,
            self.theta,
            self.cos_ref,
            self.sin_ref,
            *self.parameter_trig,
            poses,
            out,
            chunk_count(out.shape[0]),
        )
        return out.reshape(*batch, n_poses, out.shape[-1])


@dataclass(frozen=True, eq=False)
class ArrayModulePredictor(CompiledPredictor):
    """The tool by :func:`~robocal_uncertainty.kernels._walk_xp.walk_xp` on an array module.

    The same reference as :class:`CompiledPredictor`, plus the array module's name
    (``"cupy"``, or ``"numpy"`` standing in for it), imported where the predictor runs so that
    it pickles without it.
    """

    module: str = "cupy"

    @classmethod
    def on(cls, module: str, layout: ParameterLayout, params: Array, joint_positions: Array) -> ArrayModulePredictor:
        """Reference at `params` (n_params,) and readings (n_poses, n_joints), walked on `module`."""
        ref = CompiledPredictor.at(layout, params, joint_positions)
        return cls(ref.layout, ref.flat, ref.joints, ref.theta, ref.cos_ref, ref.sin_ref, ref.reference_params, module)

    def _run(self, params: Array, joint_positions: Array, *, poses: bool) -> Array:
        from robocal_uncertainty.kernels._walk_xp import as_numpy, walk_xp

        xp: Any = __import__(self.module)
        n_poses = self.joints.shape[0]
        p, q, batch = _batched(self.layout, params, joint_positions, n_poses)
        reference = tuple(xp.asarray(a) for a in (self.joints.T, self.theta, self.cos_ref, self.sin_ref))
        out = as_numpy(walk_xp(xp, self.flat, xp.asarray(p), xp.asarray(q), reference, poses=poses))
        return out.reshape(*batch, n_poses, out.shape[-1])


@dataclass(frozen=True, eq=False)
class CompiledMeasurement:
    """The measurement type's prediction near the calibration by the numba walk, and the whole
    chord re-identification of a block of trials in the compiled kernel.

    Called, it predicts like :class:`CompiledPredictor` (points, or with `orientation` the
    stored 6-DOF values); :meth:`solve_chord` is what
    :meth:`~robocal_uncertainty.uncertainty.reidentification.ChordSolver.solve` hands its
    iteration to.

    Attributes
    ----------
    walker : CompiledPredictor
        The reference (the calibration's parameters and readings).
    orientation : bool
        6-DOF measurements (12 stored values and 6 equations per pose) instead of points.
    """

    walker: CompiledPredictor
    orientation: bool

    def __call__(self, params: Array, joint_positions: Array) -> Array:
        """Predicted values (..., n_poses, 3 or 12)."""
        return self.walker._run(params, joint_positions, poses=self.orientation)

    def solve_chord(
        self,
        solver: Any,
        joint_positions: Array,
        measured: Array,
        weights: Array | None,
        lambdas: Array,
        x_start: Array,
        *,
        max_iterations: int,
        relative_tolerance: float,
        deviations: Array | None = None,
        reading_errors: Array | None = None,
    ) -> tuple[Array, int] | None:
        """:meth:`ChordSolver.solve` (its ``linear_start`` iteration) for every trial, compiled.

        Parameters as there (`solver` the :class:`ChordSolver`; with `deviations`, the
        measurement errors (T, n_poses, dimension) that the kernel applies to the shared
        `measured` itself, as the measurement type's ``perturb`` does; with `reading_errors`
        (T, n_poses, n_joints), those it adds to the shared readings). Returns None, for the
        solver's own numpy iteration on this block, where a trial needs what the kernel does
        not do (a residual rotation near pi, a normal matrix that is not positive definite).
        """
        from robocal_uncertainty.kernels._numba_walk import chord_solve, chunk_count

        if solver.joint_jacobian is None:  # a solver built without ChordSolver.at
            return None
        walker = self.walker
        n_trials = max([measured.shape[0], *(len(e) for e in (deviations, reading_errors) if e is not None)])
        n_poses = walker.joints.shape[0]
        k = x_start.size
        q = np.asarray(joint_positions, dtype=np.float64)
        q = _kernel_array(q.reshape(1, *q.shape) if q.ndim == 2 else _shared(q))
        read_errors = np.empty((0, *walker.joints.shape))
        if reading_errors is not None:
            if q.shape[0] != 1:
                return None  # errors for readings that differ from trial to trial: the numpy path
            read_errors = _scratch_array("reading_errors", reading_errors)
        values = _kernel_array(_shared(np.asarray(measured, dtype=np.float64)))
        if deviations is None:
            errors = np.empty((0, n_poses, solver.problem.measurement.dimension))
        elif values.shape[0] != 1:
            return None  # errors for values that differ from trial to trial: the numpy path
        else:
            errors = _scratch_array("deviations", deviations)
        w = (
            np.empty((0, n_poses))
            if weights is None
            else _kernel_array(np.broadcast_to(np.asarray(weights, dtype=np.float64), (n_trials, n_poses)))
        )
        x = np.empty((n_trials, k))
        steps = np.empty(n_trials, dtype=np.int64)
        failed = np.zeros(n_trials, dtype=np.bool_)
        chord_solve(
            q,
            read_errors,
            values,
            errors,
            w,
            _kernel_array(np.broadcast_to(np.asarray(lambdas, dtype=np.float64), (n_trials,))),
            _kernel_array(np.asarray(x_start, dtype=np.float64).reshape(k)),
            _problem_arrays(solver),
            solver.step_factors.as_tuple(),
            self._walk_reference(),
            self.orientation,
            int(max_iterations),
            float(relative_tolerance),
            x,
            steps,
            failed,
            chunk_count(n_trials),
        )
        if failed.any():
            return None
        return x, int(steps.max()) if n_trials else 1

    def _walk_reference(self) -> tuple[Any, ...]:
        """The walk's layout and reference as the kernel takes them (``joints .. sin_p``)."""
        walker = self.walker
        flat = walker.flat
        return (
            flat.joints,
            flat.blocks,
            walker.reference_readings,
            walker.theta,
            walker.cos_ref,
            walker.sin_ref,
            *walker.parameter_trig,
        )


def _problem_arrays(solver: Any) -> tuple[Any, ...]:
    """The chord solver's problem as the kernel takes it (see ``chord_solve``)."""
    start, estimated, scale, mask, whitening, reference, ref_joints = solver.kernel_arrays
    return (
        start,
        estimated,
        scale,
        mask,
        solver.transposed_jacobian,
        whitening,
        solver.joint_jacobian,
        solver.contiguous_pose_normal,
        reference,
        ref_joints,
    )


def _shared(values: Array) -> Array:
    """`values` (n_trials, ...) as (1, ...) when every trial holds the same (a broadcast view)."""
    if values.shape[0] > 1 and values.strides[0] == 0:
        return values[:1]
    return values
