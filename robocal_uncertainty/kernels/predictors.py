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
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.kernels._layout import FlatLayout, flat_layout, reference_angles

__all__ = ["ArrayModulePredictor", "CompiledPredictor"]

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
    """

    layout: ParameterLayout
    flat: FlatLayout
    joints: Array
    theta: Array
    cos_ref: Array
    sin_ref: Array

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
        )

    def __call__(self, params: Array, joint_positions: Array) -> Array:
        """Tool points (..., n_poses, 3) [m]."""
        return self._run(params, joint_positions, poses=False)

    def poses(self, params: Array, joint_positions: Array) -> Array:
        """Stored 6-DOF values (..., n_poses, 12): the point [m], then ``world_R_tool`` row by row."""
        return self._run(params, joint_positions, poses=True)

    def _run(self, params: Array, joint_positions: Array, *, poses: bool) -> Array:
        from robocal_uncertainty.kernels._numba_walk import walk

        n_poses = self.joints.shape[0]
        p, q, batch = _batched(self.layout, params, joint_positions, n_poses)
        out = np.empty((max(p.shape[0], q.shape[0]), n_poses, 12 if poses else 3))
        q_ref = np.ascontiguousarray(self.joints.T)
        walk(p, q, self.flat.joints, self.flat.blocks, q_ref, self.theta, self.cos_ref, self.sin_ref, poses, out)
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
        return cls(ref.layout, ref.flat, ref.joints, ref.theta, ref.cos_ref, ref.sin_ref, module)

    def _run(self, params: Array, joint_positions: Array, *, poses: bool) -> Array:
        from robocal_uncertainty.kernels._walk_xp import as_numpy, walk_xp

        xp: Any = __import__(self.module)
        n_poses = self.joints.shape[0]
        p, q, batch = _batched(self.layout, params, joint_positions, n_poses)
        reference = tuple(xp.asarray(a) for a in (self.joints.T, self.theta, self.cos_ref, self.sin_ref))
        out = as_numpy(walk_xp(xp, self.flat, xp.asarray(p), xp.asarray(q), reference, poses=poses))
        return out.reshape(*batch, n_poses, out.shape[-1])
