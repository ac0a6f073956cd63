"""The parameter layout as flat integer arrays, the form compiled kernels can take.

A compiled kernel cannot read a :class:`~robocal_uncertainty.core.robot_model.ParameterLayout`;
it gets the index of every field of every joint (``-1`` for a missing ``beta``), the
prismatic flags and the start indices of the tool, tool rotation, mount and base blocks
(``-1`` where the layout has none).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import ParameterLayout

__all__ = ["FlatLayout", "flat_layout", "reference_angles"]

_FIELDS = ("alpha", "a", "theta", "d", "beta")


@dataclass(frozen=True, eq=False)
class FlatLayout:
    """Indices of a layout's parameters.

    Attributes
    ----------
    joints : ndarray of int64, shape (n_joints, 6)
        Per joint the indices of alpha, a, theta, d, beta (-1 without beta), then 1 for a
        prismatic joint (its reading adds to d), 0 for a revolute one.
    blocks : ndarray of int64, shape (4,)
        Index of tool.x, of tool.rx (-1 without tool rotation), of mount.x (-1 without a
        mount) and of base.x.
    """

    joints: NDArray[np.int64]
    blocks: NDArray[np.int64]


def flat_layout(layout: ParameterLayout) -> FlatLayout:
    """The indices of `layout` as :class:`FlatLayout`."""
    rows = []
    for j, idx in enumerate(layout.joint_slices()):
        rows.append([idx.get(f, -1) for f in _FIELDS] + [int(layout.is_prismatic(j))])
    rot = layout.tool_rotation_index
    mount = layout.mount_index
    blocks = [layout.tool_index, -1 if rot is None else rot, -1 if mount is None else mount, layout.base_index]
    return FlatLayout(np.asarray(rows, dtype=np.int64).reshape(-1, 6), np.asarray(blocks, dtype=np.int64))


def reference_angles(
    layout: ParameterLayout, params: NDArray[np.float64], joints: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Joint angles ``q + theta`` (``theta`` alone for a prismatic joint) at the reference.

    Parameters
    ----------
    params : ndarray, shape (n_params,) [m, rad]
    joints : ndarray, shape (n_poses, n_joints) [rad or m]

    Returns
    -------
    ndarray, shape (n_poses, n_joints) [rad]
    """
    slices = layout.joint_slices()
    theta = np.asarray(params, dtype=np.float64)[[idx["theta"] for idx in slices]]
    revolute = np.array([not layout.is_prismatic(j) for j in range(layout.n_joints)])
    return np.asarray(np.where(revolute, joints, 0.0) + theta, dtype=np.float64)
