"""A check campaign made ready for the test: its points, exact repeats, noise and degrees of freedom.

A check must hold 3-D positions and enough poses to re-register its nuisance (tracker pose,
tool point) and leave :data:`~robocal_uncertainty.core.session.MIN_CHECK_DOF` equations for the
test; a pose measured twice counts once. The per-pose noise and the Welch-Satterthwaite degrees
of freedom of each residual component are what the verdict's intervals use.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel
from robocal_uncertainty.core.session import LENGTH_SCALE, MIN_CHECK_DOF, SessionState, effect_jacobian
from robocal_uncertainty.errors import IdentifiabilityError, InputError

__all__ = ["block_diagonal", "check_campaign", "effective_dof", "pose_noise", "unique_poses"]

Array = NDArray[np.float64]


def check_campaign(model: RobotModel, campaign: Campaign, retool: bool) -> tuple[Campaign, Array, int]:
    if not isinstance(campaign, Campaign):
        msg = f"check campaign must be a Campaign, got {type(campaign).__name__}"
        raise InputError(msg)
    campaign = campaign.reorder_joints(model.joint_names)
    positions = campaign.measurement.positions(campaign.points)
    if positions is None:
        msg = f"check campaign holds no 3-D positions ({campaign.measurement.quantity}): cannot verify"
        raise InputError(msg)
    k = (6 if campaign.frame == "tracker" else 0) + (3 if retool else 0)
    need = int(np.ceil((k + MIN_CHECK_DOF) / 3))
    if campaign.n_poses < need:
        what = "the tracker pose" + (" and the tool point" if retool else "") if k else "nothing"
        msg = (
            f"check campaign too small: {campaign.n_poses} poses give {3 * campaign.n_poses} equations; "
            f"re-registering {what} takes {k}, and the test needs at least {MIN_CHECK_DOF} more "
            f"(measure at least {need} poses, 5-20 spread over the workspace)"
        )
        raise IdentifiabilityError(msg)
    return campaign, np.asarray(positions, dtype=np.float64), k


def block_diagonal(blocks: Array) -> Array:
    """The block-diagonal matrix of `blocks`, shape (n, b, b) -> (n b, n b).

    The same matrix as ``scipy.linalg.block_diag(*blocks)`` (the values placed, nothing
    summed), built by one indexed assignment: scipy builds it block by block (a Kronecker
    product each in recent versions), quadratic in the poses per block, which made it the
    costliest step of a re-registration of a few hundred poses.
    """
    n, b = blocks.shape[0], blocks.shape[1]
    out = np.zeros((n, b, n, b), dtype=np.result_type(blocks, np.float64))
    idx = np.arange(n)
    out[idx, :, idx, :] = blocks
    return np.asarray(out.reshape(n * b, n * b), dtype=np.float64)


def pose_noise(
    jac: Array,
    theta_cols: list[int],
    distances: Array,
    tracker: TrackerNoise,
    encoder: EncoderNoise,
    prismatic: tuple[bool, ...] = (),
) -> Array:
    """Per-pose covariance of tracker and encoder noise, shape (n, 3, 3) [m^2]."""
    cov = encoder.covariance(jac[:, :, theta_cols], prismatic)
    cov += np.eye(3) * (tracker.std(distances) ** 2)[:, None, None]
    return cov


def effective_dof(
    res_std: Array,
    jac: Array,
    params: Array,
    q: Array,
    layout: ParameterLayout,
    state: SessionState,
    rotation: Array,
    between_names: tuple[str, ...] | None,
) -> Array:
    """Welch-Satterthwaite dof of each residual component's variance, shape (n, 3).

    Parts with finite dof: the model error (``state.model_error_dof``) and each group of
    between-session effects (joint offsets, length scale; ``state.between_session_dof`` for the
    smaller group, the group sizes' ratio for the other). The rest of the variance is exact.
    """
    n = res_std.shape[0]
    total = res_std**2
    parts: list[tuple[Array, float]] = []
    if state.model_error_dof is not None and np.isfinite(state.model_error_dof):
        me = np.diag(rotation @ state.model_error_covariance @ rotation.T)
        parts.append((np.broadcast_to(me, (n, 3)), float(state.model_error_dof)))
    if between_names and state.between_session_covariance is not None and state.between_session_dof is not None:
        g = effect_jacobian(layout, params, q, between_names)
        groups = {nm == LENGTH_SCALE for nm in between_names}
        sizes = {key: sum(1 for nm in between_names if (nm == LENGTH_SCALE) == key) for key in groups}
        per_effect = float(state.between_session_dof) / min(sizes.values())
        for key in groups:
            cols = [c for c, nm in enumerate(between_names) if (nm == LENGTH_SCALE) == key]
            sub = state.between_session_covariance[np.ix_(cols, cols)]
            var = np.einsum("pik,kl,pil->pi", g[:, :, cols], sub, g[:, :, cols])
            parts.append((var, per_effect * sizes[key]))
    if not parts:
        return np.full((n, 3), np.inf)
    denominator = sum(np.minimum(var, total) ** 2 / dof for var, dof in parts)
    with np.errstate(divide="ignore"):
        return np.asarray(np.where(denominator > 0, total**2 / denominator, np.inf), dtype=np.float64)


def unique_poses(campaign: Campaign, y: Array) -> tuple[Campaign, Array, int]:
    """The check without exact repeats (same joints and measured point): a pose counts once."""
    rows = np.concatenate((campaign.joint_positions, y), axis=1)
    _, first = np.unique(rows, axis=0, return_index=True)
    if first.size == campaign.n_poses:
        return campaign, y, 0
    keep = np.sort(first)
    return campaign.subset(keep), y[keep], int(campaign.n_poses - keep.size)
