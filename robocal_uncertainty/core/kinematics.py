"""Vectorised forward kinematics of the measured point and its identification Jacobian.

This is the hot path of identification and of the Monte Carlo: every function takes a stack
of parameter vectors and a stack of joint configurations and evaluates them all at once with
numpy broadcasting, with no Python loop over poses or trials (only over the 6 joints).

Internally vectors are stored component-first, shape (3, *batch), so that each of x, y, z is a
contiguous array and the rotation algebra is a handful of fused multiply-adds.
A model read from a URDF starts the chain at its fixed mount and may have prismatic joints
(the reading adds to ``d``). The Jacobian is analytic: each revolute-like parameter (alpha, beta, theta, base angles)
moves the point by ``axis x (point - pivot)``, each prismatic-like one (a, d, tool, base xyz)
by its axis, all expressed in the measurement frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix

__all__ = [
    "NearbyPoints",
    "forward_points",
    "forward_points_and_jacobian",
    "forward_poses",
    "forward_poses_and_jacobian",
]

Array = NDArray[np.float64]


def _cross(u: Array, v: Array) -> Array:
    """Cross product of component-first vectors, shape (3, ...)."""
    return np.stack(
        (
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        )
    )


def _prepare(layout: ParameterLayout, params: Array, joint_positions: Array) -> tuple[Array, Array, tuple[int, ...]]:
    params = np.asarray(params, dtype=np.float64)
    q = np.asarray(joint_positions, dtype=np.float64)
    if params.shape[-1:] != (layout.size,):
        msg = f"params must have shape (..., {layout.size}), got {params.shape}"
        raise ValueError(msg)
    if q.ndim < 2 or q.shape[-1] != layout.n_joints:
        msg = f"joint_positions must have shape (..., n_poses, {layout.n_joints}), got {q.shape}"
        raise ValueError(msg)
    # Parameters broadcast against the pose axis of the joints.
    batch = np.broadcast_shapes(params.shape[:-1], q.shape[:-2])
    shape = (*batch, q.shape[-2])
    return params[..., None, :], q, shape


def _chain(
    layout: ParameterLayout, p: Array, q: Array, shape: tuple[int, ...], *, keep_axes: bool
) -> tuple[Array, Array, Array, list[tuple[str, Array, Array]]]:
    """Walk the chain; return point in base frame, last rotation columns, base rotation.

    When `keep_axes` is true, also return for each kinematic parameter its motion
    ``(kind, axis, pivot)`` with kind ``"rot"`` or ``"lin"``.
    """
    ones = np.ones(shape)
    m0 = layout.mount_index
    if m0 is None:
        zeros = np.zeros(shape)
        cx = np.stack((ones, zeros, zeros))
        cy = np.stack((zeros, ones, zeros))
        cz = np.stack((zeros, zeros, ones))
        origin = np.zeros((3, *shape))
    else:
        mount_cols, mount_origin, _ = _pose(p, m0)
        cx, cy, cz = (mount_cols[c] * ones for c in range(3))
        origin = mount_origin * ones
    motions: list[tuple[str, Array, Array]] = []
    for j, idx in enumerate(layout.joint_slices()):
        alpha = p[..., idx["alpha"]]
        a = p[..., idx["a"]]
        if keep_axes:
            motions.append(("rot", cx, origin))
            motions.append(("lin", cx, cx))
        ca, sa = np.cos(alpha), np.sin(alpha)
        cy, cz = ca * cy + sa * cz, ca * cz - sa * cy
        origin = origin + a * cx
        if "beta" in idx:
            beta = p[..., idx["beta"]]
            cb, sb = np.cos(beta), np.sin(beta)
            if keep_axes:
                motions.append(("rot", cy, origin))
            cx, cz = cb * cx - sb * cz, sb * cx + cb * cz
        prismatic = layout.is_prismatic(j)
        angle = p[..., idx["theta"]] if prismatic else q[..., j] + p[..., idx["theta"]]
        ct, st = np.cos(angle), np.sin(angle)
        cx, cy = ct * cx + st * cy, ct * cy - st * cx
        d = p[..., idx["d"]] + q[..., j] if prismatic else p[..., idx["d"]]
        if keep_axes:
            # Order must match layout.joint_slices(): alpha, a, theta, d, beta.
            beta_motion = motions.pop() if "beta" in idx else None
            motions.append(("rot", cz, origin))
            motions.append(("lin", cz, cz))
            if beta_motion is not None:
                motions.append(beta_motion)
        origin = origin + d * cz
    t0 = layout.tool_index
    tool = p[..., t0 : t0 + 3]
    point = origin + tool[..., 0] * cx + tool[..., 1] * cy + tool[..., 2] * cz
    return point, np.stack((cx, cy, cz)), origin, motions


def _base(p: Array, layout: ParameterLayout) -> tuple[Array, Array, Array]:
    """Base rotation columns (3 cols, 3 comps, ...), translation (3, ...), and roll/pitch axes."""
    return _pose(p, layout.base_index)


def _pose(p: Array, b0: int) -> tuple[Array, Array, Array]:
    """Rotation columns, translation and roll/pitch axes of the ``x y z roll pitch yaw`` at `b0`."""
    roll, pitch, yaw = p[..., b0 + 3], p[..., b0 + 4], p[..., b0 + 5]
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cyw, syw = np.cos(yaw), np.sin(yaw)
    zero = np.zeros_like(cr)
    # Columns of Rz(yaw) Ry(pitch) Rx(roll).
    col0 = np.stack((cyw * cp, syw * cp, -sp))
    col1 = np.stack((cyw * sp * sr - syw * cr, syw * sp * sr + cyw * cr, cp * sr))
    col2 = np.stack((cyw * sp * cr + syw * sr, syw * sp * cr - cyw * sr, cp * cr))
    translation = np.stack((p[..., b0], p[..., b0 + 1], p[..., b0 + 2]))
    # Roll turns about Rz Ry e_x, pitch about Rz e_y, yaw about e_z (all in world).
    roll_axis = col0
    pitch_axis = np.stack((-syw, cyw, zero))
    return np.stack((col0, col1, col2)), translation, np.stack((roll_axis, pitch_axis))


def _mount_motions(
    layout: ParameterLayout, p: Array, point: Array, shape: tuple[int, ...]
) -> list[tuple[int, tuple[Array, Array]]]:
    """For each mount parameter: its index and the (linear, angular) motion of the point in the
    robot base frame per unit change (component-first, shape (3, *shape)); empty without a mount."""
    m0 = layout.mount_index
    if m0 is None:
        return []
    _, origin, axes = _pose(p, m0)
    zero = np.zeros((3, *shape))
    out = []
    for i in range(3):
        unit = np.zeros((3, *shape))
        unit[i] = 1.0
        out.append((m0 + i, (unit, zero)))
    ez = np.zeros((3, *shape))
    ez[2] = 1.0
    for i, axis in enumerate((axes[0], axes[1], ez)):
        axis_b = np.broadcast_to(axis, (3, *shape))
        out.append((m0 + 3 + i, (_cross(axis_b, point - origin), axis_b)))
    return out


def _tool_rotation(layout: ParameterLayout, p: Array) -> tuple[Array, Array] | None:
    """Tool rotation ``Rz(rz) Ry(ry) Rx(rx)`` in the flange frame and its parameter axes.

    Returns None when the layout has no tool rotation; else two arrays of shape
    (..., 3, 3): the rotation, and as columns the flange-frame axes about which
    ``tool.rx``, ``tool.ry``, ``tool.rz`` turn the tool frame (``Rz Ry e_x``, ``Rz e_y``, ``e_z``).
    """
    r0 = layout.tool_rotation_index
    if r0 is None:
        return None
    rx, ry, rz = p[..., r0], p[..., r0 + 1], p[..., r0 + 2]
    rotation = rpy_to_matrix(np.stack((rx, ry, rz), axis=-1))
    cz, sz = np.cos(rz), np.sin(rz)
    axes = np.zeros((*rx.shape, 3, 3))
    axes[..., :, 0] = rotation[..., :, 0]
    axes[..., 0, 1], axes[..., 1, 1] = -sz, cz
    axes[..., 2, 2] = 1.0
    return rotation, axes


def _rotate(base_cols: Array, v: Array) -> Array:
    return np.asarray(base_cols[0] * v[0] + base_cols[1] * v[1] + base_cols[2] * v[2], dtype=np.float64)


def _frame_in_base(layout: ParameterLayout, p: Array, q: Array) -> tuple[tuple[Array, ...], ...]:
    """Last frame in the base frame: its x, y, z columns and origin, each three component arrays.

    Keeps the nine rotation entries as separate arrays and updates them with fused
    expressions: fewer temporaries than the component-first stacks used for the Jacobian.
    """
    # Start from the parameters' own shape (one entry per trial): until the first joint
    # angle enters, the chain is the same for every pose and needs no per-pose work.
    start = p.shape[:-1]
    m0 = layout.mount_index
    if m0 is None:
        x0, x1, x2 = np.ones(start), np.zeros(start), np.zeros(start)
        y0, y1, y2 = np.zeros(start), np.ones(start), np.zeros(start)
        z0, z1, z2 = np.zeros(start), np.zeros(start), np.ones(start)
        o0, o1, o2 = np.zeros(start), np.zeros(start), np.zeros(start)
    else:
        (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = _pose(p, m0)[0]
        o0, o1, o2 = p[..., m0], p[..., m0 + 1], p[..., m0 + 2]
    for j, idx in enumerate(layout.joint_slices()):
        alpha = p[..., idx["alpha"]]
        ca, sa = np.cos(alpha), np.sin(alpha)
        a = p[..., idx["a"]]
        o0, o1, o2 = o0 + a * x0, o1 + a * x1, o2 + a * x2
        y0, z0 = ca * y0 + sa * z0, ca * z0 - sa * y0
        y1, z1 = ca * y1 + sa * z1, ca * z1 - sa * y1
        y2, z2 = ca * y2 + sa * z2, ca * z2 - sa * y2
        if "beta" in idx:
            beta = p[..., idx["beta"]]
            cb, sb = np.cos(beta), np.sin(beta)
            x0, z0 = cb * x0 - sb * z0, sb * x0 + cb * z0
            x1, z1 = cb * x1 - sb * z1, sb * x1 + cb * z1
            x2, z2 = cb * x2 - sb * z2, sb * x2 + cb * z2
        prismatic = layout.is_prismatic(j)
        angle = p[..., idx["theta"]] if prismatic else q[..., j] + p[..., idx["theta"]]
        ct, st = np.cos(angle), np.sin(angle)
        x0, y0 = ct * x0 + st * y0, ct * y0 - st * x0
        x1, y1 = ct * x1 + st * y1, ct * y1 - st * x1
        x2, y2 = ct * x2 + st * y2, ct * y2 - st * x2
        d = p[..., idx["d"]] + q[..., j] if prismatic else p[..., idx["d"]]
        o0, o1, o2 = o0 + d * z0, o1 + d * z1, o2 + d * z2
    return (x0, x1, x2), (y0, y1, y2), (z0, z1, z2), (o0, o1, o2)


def _points_in_base(layout: ParameterLayout, p: Array, q: Array, shape: tuple[int, ...]) -> tuple[Array, Array, Array]:
    """Point in the base frame as three component arrays; the hot path of the Monte Carlo."""
    return _tool_point(layout, p, _frame_in_base(layout, p, q), shape)


def _tool_point(
    layout: ParameterLayout, p: Array, frame: tuple[tuple[Array, ...], ...], shape: tuple[int, ...]
) -> tuple[Array, Array, Array]:
    """Tool point in the base frame, three component arrays, from :func:`_frame_in_base`'s output."""
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2), (o0, o1, o2) = frame
    t0 = layout.tool_index
    tx, ty, tz = p[..., t0], p[..., t0 + 1], p[..., t0 + 2]
    return (
        np.broadcast_to(o0 + tx * x0 + ty * y0 + tz * z0, shape),
        np.broadcast_to(o1 + tx * x1 + ty * y1 + tz * z1, shape),
        np.broadcast_to(o2 + tx * x2 + ty * y2 + tz * z2, shape),
    )


def forward_points(model_or_layout: RobotModel | ParameterLayout, params: Array, joint_positions: Array) -> Array:
    """Measured point for every (parameter set, pose) pair.

    Parameters
    ----------
    model_or_layout : RobotModel or ParameterLayout
        Gives the structure of the parameter vector.
    params : ndarray, shape (..., n_params) [m, rad]
        Parameter vectors (see :class:`ParameterLayout`); leading dimensions broadcast
        against those of `joint_positions`.
    joint_positions : ndarray, shape (..., n_poses, n_joints) [rad]
        Joint readings.

    Returns
    -------
    ndarray, shape (..., n_poses, 3) [m]
        Points in the measurement frame (``world_T_base`` applied).
    """
    layout = model_or_layout.layout if isinstance(model_or_layout, RobotModel) else model_or_layout
    p, q, shape = _prepare(layout, params, joint_positions)
    px, py, pz = _points_in_base(layout, p, q, shape)
    base_cols, translation, _ = _base(p, layout)
    out = np.empty((*shape, 3))
    for i in range(3):
        out[..., i] = base_cols[0][i] * px + base_cols[1][i] * py + base_cols[2][i] * pz + translation[i]
    return out


_TAYLOR_LIMIT = 0.25
"""Largest angle change [rad] from the reference that :class:`NearbyPoints` expands in series."""
_TILED_ELEMENTS = 2**16
"""Trials x poses up to which :class:`NearbyPoints` keeps its reference cosines and sines
repeated per trial (12 such arrays for 6 joints: 6 MiB at most)."""
_TAYLOR_TOLERANCE = 2.0**-57
"""Truncation error allowed in the series of ``cos`` and ``sin`` (below half an ulp of 1)."""


def _series(largest: float, odd: bool) -> tuple[float, ...]:
    """Taylor coefficients, in powers of ``b^2``, of ``cos b`` (even) or ``sin(b) / b`` (odd).

    As many as needed for ``|b| <= largest``: the first term left out is below the tolerance.
    """
    coefficients: list[float] = []
    k = 0
    while True:
        order = 2 * k + odd
        if k and largest**order / math.factorial(order) <= _TAYLOR_TOLERANCE:
            return tuple(coefficients)
        coefficients.append((-1) ** k / math.factorial(order))
        k += 1


@dataclass(frozen=True, eq=False)
class NearbyPoints:
    """Measured points at parameters and joint readings close to a reference, cheaply.

    The Monte Carlo evaluates the chain many times at parameters and readings that differ
    from the calibration by micro-radians. The joint angle ``q + theta`` then is the
    reference angle ``a0`` plus a small ``b``, and ``cos(a0 + b) = cos a0 cos b - sin a0 sin b``
    with ``cos b`` and ``sin b`` from their Taylor series, cut where the next term is below
    half an ulp of 1 (two or three terms for micro-radians): a few multiply-adds instead of
    two transcendental calls per joint and pose. The chain is walked from the tool back to the
    base on the point alone (no rotation matrices; :meth:`poses` walks the tool's x and z axes
    too). When some ``|b|`` exceeds 0.25 rad the angles are evaluated directly. The points
    agree with :func:`forward_points` (the poses with :func:`forward_poses`) to a few ulps (the
    order of the floating-point operations differs), not bit for bit.

    Attributes
    ----------
    layout : ParameterLayout
    theta : ndarray, shape (n_joints,) [rad]
        Reference joint offsets.
    joints : ndarray, shape (n_poses, n_joints) [rad]
        Reference joint readings.
    cos_ref, sin_ref : ndarray, shape (n_joints, n_poses)
        Cosine and sine of the reference angles ``joints + theta``.
    """

    layout: ParameterLayout
    theta: Array
    joints: Array
    cos_ref: Array
    sin_ref: Array
    _cache: dict[int, tuple[Array, Array]] = field(default_factory=dict, init=False, repr=False, compare=False)

    @staticmethod
    def supports(layout: ParameterLayout) -> bool:
        """Whether the walk covers `layout`: revolute joints only and no mount (models read from
        a URDF with a prismatic joint or a base-link mount use :func:`forward_points`)."""
        return not layout.has_mount and not any(layout.prismatic)

    @classmethod
    def at(cls, layout: ParameterLayout, params: Array, joint_positions: Array) -> NearbyPoints:
        """Reference at `params` (n_params,) and readings `joint_positions` (n_poses, n_joints).

        Raises
        ------
        ValueError
            A layout the walk does not cover (see :meth:`supports`).
        """
        if not cls.supports(layout):
            msg = "NearbyPoints covers revolute chains without a mount; use forward_points for this layout"
            raise ValueError(msg)
        params = np.asarray(params, dtype=np.float64)
        joints = np.array(joint_positions, dtype=np.float64)
        theta = params[[idx["theta"] for idx in layout.joint_slices()]]
        angles = (joints + theta).T
        return cls(layout, theta, joints, np.cos(angles), np.sin(angles))

    def __call__(self, params: Array, joint_positions: Array) -> Array:
        """Points (..., n_poses, 3) [m], as :func:`forward_points` (same shapes and frame).

        `joint_positions` must have the reference's poses: shape (..., n_poses, n_joints).
        """
        p, shape, point, _ = self._walk(params, joint_positions, rotation=False)
        out = np.empty((p.shape[0], shape[-1], 3))
        _to_world(p, self.layout, [point], out, [range(3)])
        return out.reshape(*shape, 3)

    def poses(self, params: Array, joint_positions: Array) -> Array:
        """Tool poses as stored 6-DOF values (..., n_poses, 12): the point [m], then
        ``world_R_tool`` row by row, as ``pose_values(*forward_poses(...))`` gives them (to a
        few ulps). The x and z axes of the tool are walked with the point, y is ``z x x``."""
        p, shape, point, axes = self._walk(params, joint_positions, rotation=True)
        (x0, x1, x2), (z0, z1, z2) = axes
        cols = ((x0, x1, x2), (z1 * x2 - z2 * x1, z2 * x0 - z0 * x2, z0 * x1 - z1 * x0), (z0, z1, z2))
        out = np.empty((p.shape[0], shape[-1], 12))
        # Stored values: the point, then world_R_tool row by row (column c of row i at 3 + 3 i + c).
        _to_world(p, self.layout, [point, *cols], out, [range(3), range(3, 12, 3), range(4, 12, 3), range(5, 12, 3)])
        return out.reshape(*shape, 12)

    def _tiles(self, n_batch: int) -> tuple[Array, Array]:
        """``cos_ref`` and ``sin_ref`` repeated for `n_batch` trials, shape (n_joints, n_batch, n_poses).

        numpy multiplies two arrays of one shape about 2.5x faster than an array by a broadcast
        row, so up to ``_TILED_ELEMENTS`` per joint the rows are copied (and kept for the last
        two batch sizes: a block's full sub-batches and its remainder); beyond, they are
        broadcast views (no memory).
        """
        shape = (self.cos_ref.shape[0], n_batch, self.cos_ref.shape[1])
        if n_batch * self.cos_ref.shape[1] > _TILED_ELEMENTS:
            return np.broadcast_to(self.cos_ref[:, None, :], shape), np.broadcast_to(self.sin_ref[:, None, :], shape)
        tiles = self._cache.get(n_batch)
        if tiles is None:
            tiles = (
                np.ascontiguousarray(np.broadcast_to(self.cos_ref[:, None, :], shape)),
                np.ascontiguousarray(np.broadcast_to(self.sin_ref[:, None, :], shape)),
            )
            while len(self._cache) >= 2:
                del self._cache[next(iter(self._cache))]
            self._cache[n_batch] = tiles
        return tiles

    def __getstate__(self) -> dict[str, object]:
        """Pickled without the tiles (a worker builds its own)."""
        state = dict(self.__dict__)
        state["_cache"] = {}
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        for name, value in state.items():
            object.__setattr__(self, name, value)

    def _check_readings(self, q: Array) -> None:
        """Refuse joint readings whose poses are not the reference's."""
        if q.shape[-2:] != self.joints.shape:
            msg = (
                f"joint_positions must have shape (..., {self.joints.shape[0]}, {self.layout.n_joints}), got {q.shape}"
            )
            raise ValueError(msg)

    def _walk(
        self, params: Array, joint_positions: Array, *, rotation: bool
    ) -> tuple[Array, tuple[int, ...], tuple[Array, Array, Array], list[tuple[Array, Array, Array]]]:
        """The tool point and (with `rotation`) the tool's x and z axes in the base frame.

        Returns the parameters as (n_batch, 1, n_params), the output shape (..., n_poses) and
        the vectors' components, each (n_batch, n_poses). Every operation writes into an array
        allocated once per call, in the order of the formulas in the comments, so the values
        do not depend on how the trials are batched.
        """
        layout = self.layout
        p, q, shape = _prepare(layout, params, joint_positions)
        self._check_readings(q)
        n_poses, n_joints = self.joints.shape
        n_batch = math.prod(shape[:-1])
        full = (n_batch, n_poses)
        pf = np.broadcast_to(p, (*shape[:-1], 1, layout.size)).reshape(n_batch, 1, layout.size)
        # Readings as (n_batch, n_poses, n_joints), or (1, n_poses, n_joints) when shared.
        qf = q[None] if q.ndim == 2 else np.broadcast_to(q, (*shape, n_joints)).reshape(*full, n_joints)
        slices = layout.joint_slices()
        # Their changes joint by joint, each (n_batch or 1, n_poses) contiguous.
        dq = np.subtract(np.moveaxis(qf, -1, 0), self.joints.T[:, None, :])
        dtheta = pf[:, :, [idx["theta"] for idx in slices]] - self.theta  # (n_batch, 1, n_joints)
        largest = max(float(np.max(dq, initial=0.0)), -float(np.min(dq, initial=0.0)))
        largest += float(np.max(np.abs(dtheta), initial=0.0))
        direct = not largest <= _TAYLOR_LIMIT  # also for NaN
        alphas = pf[:, :, [idx["alpha"] for idx in slices]]
        cos_alpha, sin_alpha = np.cos(alphas), np.sin(alphas)
        with_beta = [j for j, idx in enumerate(slices) if "beta" in idx]
        betas = pf[:, :, [slices[j]["beta"] for j in with_beta]]
        cos_beta, sin_beta = np.cos(betas), np.sin(betas)

        def column(k: int) -> Array:
            return pf[:, :, k]  # (n_batch, 1)

        vectors = _tool_vectors(layout, pf, full, rotation=rotation)
        b, b2, cos_b, sin_b, c, s, cos_x, sin_x, tmp, spare = (np.empty(full) for _ in range(10))
        if not direct:
            cos_series, sin_series = _series(largest, odd=False), _series(largest, odd=True)
            cos_tiles, sin_tiles = self._tiles(n_batch)
        for j in range(n_joints - 1, -1, -1):
            idx = slices[j]
            point = vectors[0]
            np.add(point[2], column(idx["d"]), out=point[2])  # z + d
            if direct:
                np.add(qf[..., j], column(idx["theta"]), out=b)  # q + theta
                np.cos(b, out=c)
                np.sin(b, out=s)
            else:
                np.add(dq[j], dtheta[..., j], out=b)  # the angle's change from the reference
                np.multiply(b, b, out=b2)
                cb = _horner_into(cos_series, b2, cos_b)
                np.multiply(b, _horner_into(sin_series, b2, sin_b), out=sin_b)
                # c = cos_ref cos b - sin_ref sin b; s = sin_ref cos b + cos_ref sin b
                np.multiply(cos_tiles[j], cb, out=c)
                np.multiply(sin_tiles[j], sin_b, out=tmp)
                np.subtract(c, tmp, out=c)
                np.multiply(sin_tiles[j], cb, out=s)
                np.multiply(cos_tiles[j], sin_b, out=tmp)
                np.add(s, tmp, out=s)
            beta = "beta" in idx
            if beta:
                np.copyto(cos_b, cos_beta[..., with_beta.index(j)])
                np.copyto(sin_b, sin_beta[..., with_beta.index(j)])
            np.copyto(cos_x, cos_alpha[..., j])
            np.copyto(sin_x, sin_alpha[..., j])
            for v in vectors:
                # x, y = c x - s y, s x + c y
                spare = _turn_into(v, 0, 1, c, s, tmp, spare)
                if beta:
                    # x, z = cb x + sb z, cb z - sb x
                    spare = _turn_into(v, 2, 0, cos_b, sin_b, tmp, spare)
                # y, z = ca y - sa z, sa y + ca z
                spare = _turn_into(v, 1, 2, cos_x, sin_x, tmp, spare)
            np.add(point[0], column(idx["a"]), out=point[0])  # x + a
        point = vectors[0]
        axes = [(v[0], v[1], v[2]) for v in vectors[1:]]
        return pf, shape, (point[0], point[1], point[2]), axes


def _tool_vectors(layout: ParameterLayout, pf: Array, full: tuple[int, int], *, rotation: bool) -> list[list[Array]]:
    """The tool point and (with `rotation`) the tool's x and z axes in the flange frame.

    `pf` is (n_batch, 1, n_params); each component comes back as a full-size (n_batch, n_poses)
    copy, so that every later operation of the walk runs in place.
    """
    n_batch = full[0]
    t0 = layout.tool_index
    starts = [(pf[:, :, t0], pf[:, :, t0 + 1], pf[:, :, t0 + 2])]
    if rotation:
        tool = _tool_rotation(layout, pf[:, 0, :])
        if tool is None:
            one, zero = np.ones((n_batch, 1)), np.zeros((n_batch, 1))
            starts += [(one, zero, zero), (zero, zero, one)]
        else:
            r = tool[0][:, None]
            starts += [(r[..., 0, 0], r[..., 1, 0], r[..., 2, 0]), (r[..., 0, 2], r[..., 1, 2], r[..., 2, 2])]
    return [[np.array(np.broadcast_to(u, full)) for u in v] for v in starts]


def _horner_into(coefficients: tuple[float, ...], b2: Array, out: Array) -> Array | float:
    """``sum_k coefficients[k] * b2**k`` by Horner's rule, written into `out` (a float when constant)."""
    if len(coefficients) == 1:
        return coefficients[0]
    np.multiply(b2, coefficients[-1], out=out)
    np.add(out, coefficients[-2], out=out)
    for c in coefficients[-3::-1]:
        np.multiply(out, b2, out=out)
        np.add(out, c, out=out)
    return out


def _turn_into(v: list[Array], i: int, k: int, c: Array, s: Array, tmp: Array, spare: Array) -> Array:
    """``v[i], v[k] = c v[i] - s v[k], s v[i] + c v[k]`` in place; returns the array left spare."""
    np.multiply(c, v[i], out=spare)
    np.multiply(s, v[k], out=tmp)
    np.subtract(spare, tmp, out=spare)
    np.multiply(s, v[i], out=tmp)
    np.multiply(c, v[k], out=v[k])
    np.add(tmp, v[k], out=v[k])
    old, v[i] = v[i], spare
    return old


def _to_world(
    p: Array, layout: ParameterLayout, vectors: list[tuple[Array, Array, Array]], out: Array, columns: list[range]
) -> None:
    """``out[..., columns[m][i]] = (world_R_base v_m)_i``, plus ``world_t_base_i`` for the first vector.

    `p` (n_batch, 1, n_params); each vector's components (n_batch, n_poses); `out`
    (n_batch, n_poses, m). Sums run into contiguous arrays, each written to its (strided)
    column of `out` once; the rotation entries are spread to full arrays once.
    """
    base_cols, translation, _ = _base(p, layout)
    full = vectors[0][0].shape
    entries = [[np.array(np.broadcast_to(base_cols[k][i], full)) for k in range(3)] for i in range(3)]
    acc, tmp = np.empty(full), np.empty(full)
    for m, v in enumerate(vectors):
        for i in range(3):
            row = entries[i]
            np.multiply(row[0], v[0], out=acc)
            np.multiply(row[1], v[1], out=tmp)
            np.add(acc, tmp, out=acc)
            np.multiply(row[2], v[2], out=tmp)
            if m == 0:
                np.add(acc, tmp, out=acc)
                np.add(acc, translation[i], out=out[..., columns[m][i]])
            else:
                np.add(acc, tmp, out=out[..., columns[m][i]])


def forward_points_and_jacobian(
    model_or_layout: RobotModel | ParameterLayout, params: Array, joint_positions: Array
) -> tuple[Array, Array]:
    """Measured points and their Jacobian with respect to every parameter.

    Parameters
    ----------
    model_or_layout : RobotModel or ParameterLayout
        Gives the structure of the parameter vector.
    params : ndarray, shape (..., n_params) [m, rad]
        Parameter vectors.
    joint_positions : ndarray, shape (..., n_poses, n_joints) [rad]
        Joint readings.

    Returns
    -------
    points : ndarray, shape (..., n_poses, 3) [m]
        Points in the measurement frame.
    jacobian : ndarray, shape (..., n_poses, 3, n_params) [m/m, m/rad]
        d point / d parameter, expressed in the measurement (world) frame.
    """
    layout = model_or_layout.layout if isinstance(model_or_layout, RobotModel) else model_or_layout
    p, q, shape = _prepare(layout, params, joint_positions)
    point, last_cols, _, motions = _chain(layout, p, q, shape, keep_axes=True)
    base_cols, translation, base_axes = _base(p, layout)
    rel_world = _rotate(base_cols, point)
    world = rel_world + translation

    jac = np.empty((layout.size, 3, *shape))
    for k, (kind, axis, pivot) in enumerate(motions):
        if kind == "rot":
            local = _cross(axis, point - pivot)
        else:
            local = np.broadcast_to(axis, (3, *shape))
        jac[k] = _rotate(base_cols, local)
    t0 = layout.tool_index
    for i in range(3):
        jac[t0 + i] = _rotate(base_cols, last_cols[i])
    r0 = layout.tool_rotation_index
    if r0 is not None:
        jac[r0 : r0 + 3] = 0.0  # the tool rotation does not move the point
    for k, (linear, angular) in _mount_motions(layout, p, point, shape):
        jac[k] = _rotate(base_cols, linear)
    b0 = layout.base_index
    for i in range(3):
        jac[b0 + i] = 0.0
        jac[b0 + i, i] = 1.0
    jac[b0 + 3] = _cross(base_axes[0], rel_world)
    jac[b0 + 4] = _cross(base_axes[1], rel_world)
    ez = np.zeros((3, *shape))
    ez[2] = 1.0
    jac[b0 + 5] = _cross(ez, rel_world)
    return np.moveaxis(world, 0, -1), np.moveaxis(jac, (0, 1), (-1, -2))


def forward_poses(
    model_or_layout: RobotModel | ParameterLayout, params: Array, joint_positions: Array
) -> tuple[Array, Array]:
    """Tool point and tool orientation for every (parameter set, pose) pair.

    The tool frame is the last modified-DH frame (the flange frame of the model) translated
    to the tool point and, when the layout has a tool rotation, rotated by it; without one its
    orientation is the flange's.

    Parameters
    ----------
    model_or_layout, params, joint_positions
        As for :func:`forward_points`.

    Returns
    -------
    points : ndarray, shape (..., n_poses, 3) [m]
        Equal, bit for bit, to :func:`forward_points`.
    rotations : ndarray, shape (..., n_poses, 3, 3)
        ``world_R_tool``: columns are the tool frame's axes in the measurement frame.
    """
    layout = model_or_layout.layout if isinstance(model_or_layout, RobotModel) else model_or_layout
    p, q, shape = _prepare(layout, params, joint_positions)
    cols = _frame_in_base(layout, p, q)
    px, py, pz = _tool_point(layout, p, cols, shape)
    base_cols, translation, _ = _base(p, layout)
    points = np.empty((*shape, 3))
    rotations = np.empty((*shape, 3, 3))
    for i in range(3):
        points[..., i] = base_cols[0][i] * px + base_cols[1][i] * py + base_cols[2][i] * pz + translation[i]
        for c in range(3):
            col = cols[c]
            rotations[..., i, c] = np.broadcast_to(
                base_cols[0][i] * col[0] + base_cols[1][i] * col[1] + base_cols[2][i] * col[2], shape
            )
    tool = _tool_rotation(layout, p)
    if tool is not None:
        rotations = np.asarray(rotations @ tool[0], dtype=np.float64)
    return points, rotations


def forward_poses_and_jacobian(
    model_or_layout: RobotModel | ParameterLayout, params: Array, joint_positions: Array
) -> tuple[Array, Array, Array]:
    """Tool poses and their Jacobian (linear and angular) with respect to every parameter.

    Returns
    -------
    points : ndarray, shape (..., n_poses, 3) [m]
    rotations : ndarray, shape (..., n_poses, 3, 3)
        ``world_R_tool`` (the tool rotation applied when the layout has one).
    jacobian : ndarray, shape (..., n_poses, 6, n_params) [m/m, m/rad; rad/m, rad/rad]
        Rows 0-2: d point / d parameter; rows 3-5: angular velocity per unit parameter, in the
        measurement (world) frame: ``R(p + dp) ~ exp([J_w dp]x) R(p)``.
    """
    layout = model_or_layout.layout if isinstance(model_or_layout, RobotModel) else model_or_layout
    p, q, shape = _prepare(layout, params, joint_positions)
    point, last_cols, _, motions = _chain(layout, p, q, shape, keep_axes=True)
    base_cols, translation, base_axes = _base(p, layout)
    rel_world = _rotate(base_cols, point)
    world = rel_world + translation
    jac = np.zeros((layout.size, 6, *shape))
    for k, (kind, axis, pivot) in enumerate(motions):
        if kind == "rot":
            jac[k, :3] = _rotate(base_cols, _cross(axis, point - pivot))
            jac[k, 3:] = _rotate(base_cols, np.broadcast_to(axis, (3, *shape)))
        else:
            jac[k, :3] = _rotate(base_cols, np.broadcast_to(axis, (3, *shape)))
    t0 = layout.tool_index
    for i in range(3):
        jac[t0 + i, :3] = _rotate(base_cols, last_cols[i])
    for k, (linear, angular) in _mount_motions(layout, p, point, shape):
        jac[k, :3] = _rotate(base_cols, linear)
        jac[k, 3:] = _rotate(base_cols, angular)
    b0 = layout.base_index
    for i in range(3):
        jac[b0 + i, i] = 1.0
    ez = np.zeros((3, *shape))
    ez[2] = 1.0
    for i, axis in enumerate((base_axes[0], base_axes[1], ez)):
        axis_b = np.broadcast_to(axis, (3, *shape))
        jac[b0 + 3 + i, :3] = _cross(axis_b, rel_world)
        jac[b0 + 3 + i, 3:] = axis_b
    rot = np.stack([_rotate(base_cols, last_cols[c]) for c in range(3)], axis=1)  # (comp, col, ...)
    flange = np.moveaxis(rot, (0, 1), (-2, -1))
    jacobian = np.moveaxis(jac, (0, 1), (-1, -2))
    tool = _tool_rotation(layout, p)
    r0 = layout.tool_rotation_index
    if tool is not None and r0 is not None:
        # Tool rotation parameters turn the tool frame about flange axes, seen in the world.
        jacobian[..., 3:, r0 : r0 + 3] = flange @ tool[1]
        flange = flange @ tool[0]
    return np.moveaxis(world, 0, -1), np.asarray(flange, dtype=np.float64), jacobian
