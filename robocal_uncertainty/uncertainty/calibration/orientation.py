"""The tool orientation's uncertainty statement, and which rotations the data cannot fix.

After the run the mean orientation is the chordal L2 mean (SVD projection of the mean
rotation matrix) and the reported deviations are re-expressed about it,
``log(R_trial R_mean^T)``.

Rotation components the campaign cannot determine are found by estimability, not from the
spread of the trials: a parameter the measurements cannot identify (e.g. the joint-6 offset
when only points on joint 6's axis are measured) is held at its nominal value in every trial,
so the trials show *no* spread along its direction although the data say nothing about it.
A rotation about a unit axis ``u`` is determined when ``u^T J_w dp = 0`` for every parameter
change ``dp`` the measurements cannot see (the null space of the candidates' measurement
Jacobian on the structural probe poses of
:func:`~robocal_uncertainty.core.observability.structural_observability`); ``J_w`` is the
angular Jacobian of the tool at the test configuration.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import forward_poses, forward_poses_and_jacobian
from robocal_uncertainty.core.measurement import stack_jacobian
from robocal_uncertainty.core.rotation import chordal_mean, quaternion_from_matrix, rotation_exp, rotation_log
from robocal_uncertainty.montecarlo.summary import Summary, summarize
from robocal_uncertainty.uncertainty.calibration.gum import gum_poses
from robocal_uncertainty.uncertainty.calibration.preparation import Prepared
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, OrientationUncertainty

__all__ = ["orientation_uncertainty", "undetermined_rotations"]

Array = NDArray[np.float64]
_ESTIMABLE_RTOL = 1e-6
_NULL_RTOL = 1e-7


def undetermined_rotations(prep: Prepared) -> list[Array]:
    """Per test configuration, the unit axes (output frame) of rotations the data cannot fix.

    See the module docstring: the null space ``N`` of the candidates' whitened measurement
    Jacobian on the structural probe poses (columns normalised, singular values below
    1e-7 of the largest) holds the parameter changes the measurements cannot see; the
    directions ``u`` with ``u^T J_w N != 0`` (left singular vectors of ``J_w N`` above 1e-6
    of the norm of ``J_w``) are undetermined.

    Returns
    -------
    list of ndarray, each shape (n_undetermined, 3)
    """
    calibration = prep.calibration
    model = calibration.model
    layout = model.layout
    measurement = calibration.measurement
    cand = np.flatnonzero(calibration.candidates)
    if prep.trials.drop_base:
        # In the robot base frame the identified base is dropped: that frame is defined by the
        # nominal joint-1 parameters the base absorbs (joint1.alpha = base.roll, ...), so those
        # combinations are a choice of frame, not unseen errors of the tool's orientation.
        b0 = layout.base_index
        cand = cand[(cand < b0) | (cand >= b0 + 6)]
    rng = np.random.default_rng(20231101)  # the probe poses of structural_observability
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    probe = rng.uniform(lo, hi, size=(200, model.n_joints))
    # Linearised at the nominal parameters, where identify decided what to estimate: a
    # parameter it held at nominal there (e.g. joint6.a for points on joint 6's axis) has an
    # unseen error even though at the estimate its column is no longer exactly dependent. The
    # rotation Jacobian below is taken at the same point, so that exact dependencies (joint6.theta
    # and tool.rz) cancel there as they do in the measurements; the directions found are then
    # carried with the tool (body-fixed, e.g. "about the tool axis") to the calibrated rotation.
    _, jac = measurement.predict_and_jacobian(layout, calibration.nominal, probe)
    a_mat = stack_jacobian(measurement, jac)[:, cand]
    norms = np.linalg.norm(a_mat, axis=0)
    scale = np.where(norms > 1e-9 * norms.max(), norms, 1.0)
    a_mat = np.where(norms > 1e-9 * norms.max(), a_mat / scale, 0.0)
    # With more rows than columns (always: 200 probe poses) the reduced SVD's V is the full
    # one, without the 600 x 600 left factor (ten times the work).
    _, sv, vt = np.linalg.svd(a_mat, full_matrices=a_mat.shape[0] < a_mat.shape[1])
    rank = int(np.sum(sv > _NULL_RTOL * sv[0]))
    null = vt[rank:].T  # (n_cand, n_null), normalised parameter coordinates
    p_out = calibration.nominal.copy()
    p_cal = calibration.estimate.copy()
    b0 = layout.base_index
    if prep.trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
        p_cal[b0 : b0 + 6] = 0.0
    _, r_nominal, g6 = forward_poses_and_jacobian(layout, p_out, prep.test_joints)
    _, r_calibrated = forward_poses(layout, p_cal, prep.test_joints)
    transport = r_calibrated @ np.swapaxes(r_nominal, -1, -2)
    j_w = g6[:, 3:, :]
    if prep.trials.drop_base:
        j_w[:, :, b0 : b0 + 6] = 0.0
    j_w = j_w[:, :, cand] / scale
    out = []
    for i in range(prep.test_joints.shape[0]):
        if null.shape[1] == 0:
            out.append(np.zeros((0, 3)))
            continue
        m_mat = j_w[i] @ null
        u, sm, _ = np.linalg.svd(m_mat, full_matrices=False)
        ref = max(float(np.linalg.norm(j_w[i], 2)), np.finfo(float).tiny)
        out.append(u[:, sm > _ESTIMABLE_RTOL * ref].T @ transport[i].T)
    return out


def orientation_uncertainty(
    prep: Prepared,
    samples: Array,
    pos_summaries: Summary,
    coverage: float,
    n_dig: int,
    *,
    per_pose: bool = False,
) -> list[OrientationUncertainty]:
    """Orientation statements from the rotation columns (deviations from the calibrated rotations);
    `per_pose` as for :func:`~robocal_uncertainty.uncertainty.calibration.gum.gum_poses`."""
    dim = N_AXES
    n_test = prep.test_joints.shape[0]
    k = prep.trials.x_hat.size
    raw = samples[:, dim * n_test + k :]
    ref = prep.trials.reference_rotations
    assert ref is not None
    # The GUM is about the calibrated rotation: validate it against deviations from it.
    raw_summary = summarize(raw, coverage)
    gums = gum_poses(prep, raw_summary, coverage, n_dig, angular=True, per_pose=per_pose)
    undetermined = undetermined_rotations(prep)
    out = []
    for i in range(n_test):
        dev_ref = raw[:, dim * i : dim * (i + 1)]
        # Chordal mean: R_mean = proj(mean_t exp(d_t)) R_ref; deviations about it.
        rot_ref = rotation_exp(dev_ref)
        mean_dev = chordal_mean(rot_ref)
        mean_rot = mean_dev @ ref[i]
        dev = rotation_log(rot_ref @ mean_dev.T)
        rot_summary = summarize(dev, coverage)
        pos = samples[:, dim * i : dim * (i + 1)]
        pose_cov = np.cov(np.hstack((pos, dev)), rowvar=False, ddof=1)
        pose_cov[:3, :3] = pos_summaries.covariance[dim * i : dim * (i + 1), dim * i : dim * (i + 1)]
        pose_cov[3:, 3:] = rot_summary.covariance
        dirs = undetermined[i]
        determined = tuple(bool(np.linalg.norm(dirs[:, a]) <= _ESTIMABLE_RTOL) for a in range(dim))
        out.append(
            OrientationUncertainty(
                mean_rotation=mean_rot,
                mean_quaternion=quaternion_from_matrix(mean_rot),
                calibrated_rotation=ref[i],
                covariance=rot_summary.covariance,
                axes=rot_summary.outputs,
                pose_covariance=pose_cov,
                determined=determined,
                undetermined_directions=dirs,
                gum=gums[i],
            )
        )
    return out
