"""The field's conditional mean and covariance (kriging) against a dense brute-force draw.

Independent reference: draws of the field at the calibration poses and the test configurations
(one dense Cholesky factor of the kernel), measurement noise, the actual least-squares fit's
residuals and prediction errors; the empirical regression of the prediction error on the
residuals and the scatter left around it must be the function's conditional mean and covariance.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from robocal_uncertainty.core.field_kriging import KrigingBasis, field_correction, krige
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.robot_model import ParameterLayout


def _kernel(q_a: np.ndarray, q_b: np.ndarray, c: float, ell: float, s2: float, same: bool) -> np.ndarray:
    corr = c * kernel_correlation(chordal_distance(q_a, q_b), ell)
    return s2 * (corr + (1.0 - c) * np.eye(q_a.shape[0]) if same else corr)


def test_conditional_mean_and_covariance_match_a_brute_force_draw_of_the_field() -> None:
    rng = np.random.default_rng(29)
    n_t, n_c, k = 14, 3, 3
    q_t = rng.uniform(-0.6, 0.6, size=(n_t, 6))
    # Two test configurations near calibration poses, one far from all of them.
    q_c = np.vstack((q_t[:2] + rng.normal(0.0, 0.05, size=(2, 6)), np.full((1, 6), 2.5)))
    c, ell, s2, noise = 0.8, 0.6, 1.0, 0.05
    q_all = np.vstack((q_t, q_c))
    joint = _kernel(q_all, q_all, c, ell, s2, True)
    a_mat = rng.normal(size=(n_t, k))
    gain = np.linalg.solve(a_mat.T @ a_mat, a_mat.T)  # least squares
    j_c = rng.normal(size=(n_c, k))
    jg = j_c @ gain

    m = 200_000
    e = rng.standard_normal((m, n_t + n_c)) @ np.linalg.cholesky(joint).T
    y = e[:, :n_t] + np.sqrt(noise) * rng.standard_normal((m, n_t))
    residuals = y - y @ (a_mat @ gain).T  # the fit's residuals, draw by draw
    delta = e[:, n_t:] - y @ jg.T  # the calibrated prediction's error at q_c
    coef, *_ = np.linalg.lstsq(residuals, delta, rcond=None)
    scatter = np.cov((delta - residuals @ coef).T)

    r0 = residuals[0]
    out = field_correction(
        a_mat,
        r0,
        joint[:n_t, :n_t] + noise * np.eye(n_t),
        joint[n_t:, :n_t],
        joint[n_t:, n_t:],
        jg,
    )
    sd = np.sqrt(np.diag(out.prior_covariance))
    np.testing.assert_allclose(out.prior_covariance, np.cov(delta.T), rtol=0.02, atol=0.01 * sd.max() ** 2)
    np.testing.assert_allclose(out.covariance, scatter, rtol=0.02, atol=0.01 * sd.max() ** 2)
    np.testing.assert_allclose(out.mean, r0 @ coef, atol=0.02 * sd.max())
    # Near the calibration poses the residuals explain part of the error (measured 21 and 35 %
    # of its variance), far from them almost nothing (0.3 %): the correction fades.
    shrink = np.diag(out.covariance) / np.diag(out.prior_covariance)
    assert np.all(shrink[:2] < 0.9)
    assert shrink[2] > 0.98


def _small_basis(n_t: int = 40, seed: int = 3) -> tuple[KrigingBasis, ParameterLayout, np.ndarray]:
    """A UR10 calibration's field over `n_t` poses with residuals that are the field itself."""
    model = load_robot_model(resolve_robot_config("ur10"))
    layout, params = model.layout, model.parameter_vector()
    rng = np.random.default_rng(seed)
    q_t = rng.uniform(-1.0, 1.0, size=(n_t, 6))
    est = [i for i, n in enumerate(layout.names) if n.endswith((".d", ".a", ".theta")) and not n.startswith("base")]
    names = tuple(layout.names[i] for i in est)
    _, jac = forward_points_and_jacobian(layout, params, q_t)
    a_mat = jac[:, :, est].reshape(3 * n_t, len(est))
    gain = np.linalg.pinv(a_mat)
    s_m = np.diag([2.0, 1.0, 1.5]) * 1e-8
    noise = np.repeat((1e-5) ** 2 * np.eye(3)[None], n_t, axis=0)
    field = np.kron(0.9 * kernel_correlation(chordal_distance(q_t, q_t), 0.5) + 0.1 * np.eye(n_t), s_m)
    r = rng.multivariate_normal(np.zeros(3 * n_t), field).reshape(n_t, 3)
    residuals = r - (a_mat @ (gain @ r.reshape(-1))).reshape(n_t, 3)
    basis = KrigingBasis(
        joint_positions=q_t,
        residuals=residuals,
        noise=noise,
        per_pose_covariance=s_m,
        correlated_fraction=0.9,
        length_scale=0.5,
        gain_names=names,
        gain=gain,
        dof=40.0,
    )
    return basis, layout, params


def test_krige_per_configuration_equals_the_full_conditional_mean_and_covariance() -> None:
    # krige forms only per-configuration blocks; field_correction (checked against the brute
    # force above) the full matrices: the two must agree.
    basis, layout, params = _small_basis()
    q_t = basis.joint_positions
    q_c = np.vstack((q_t[:3] + 0.05, np.full((1, 6), 2.5)))
    out = krige(basis, layout, params, q_c, chunk=2)
    cols = [layout.names.index(n) for n in basis.gain_names]
    _, jac_t = forward_points_and_jacobian(layout, params, q_t)
    _, jac_c = forward_points_and_jacobian(layout, params, q_c)
    n_t, n_c = q_t.shape[0], q_c.shape[0]
    c, ell, s_m = basis.correlated_fraction, basis.length_scale, basis.per_pose_covariance
    k_tt = np.kron(_kernel(q_t, q_t, c, ell, 1.0, True), s_m) + np.kron(np.eye(n_t), basis.noise[0])
    full = field_correction(
        jac_t[:, :, cols].reshape(3 * n_t, -1),
        basis.residuals.reshape(-1),
        k_tt,
        np.kron(_kernel(q_c, q_t, c, ell, 1.0, False), s_m),
        np.kron(_kernel(q_c, q_c, c, ell, 1.0, True), s_m),
        jac_c[:, :, cols].reshape(3 * n_c, -1) @ basis.gain,
    )
    np.testing.assert_allclose(out.mean.reshape(-1), full.mean, rtol=1e-7, atol=1e-12)
    blocks = np.array([full.covariance[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(n_c)])
    prior = np.array([full.prior_covariance[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(n_c)])
    np.testing.assert_allclose(out.covariance, blocks, rtol=1e-7, atol=1e-20)
    np.testing.assert_allclose(out.prior_covariance, prior, rtol=1e-7, atol=1e-20)


def test_the_correction_fades_to_zero_far_from_the_calibration_poses() -> None:
    basis, layout, params = _small_basis()
    q_t = basis.joint_positions
    # Every joint half a turn away: chordal distance >> l = 0.5 rad, correlation ~ 1e-4.
    q_far = np.full((5, 6), np.pi)
    near = krige(basis, layout, params, q_t[:5] + 0.01)
    assert np.all(np.linalg.norm(near.mean, axis=1) > 20e-6)  # the field's std is ~120 um
    assert np.all(near.std_ratio < 0.7)
    # The field's own part fades; what stays far away is the fit's share of the field (the
    # parameters absorbed some of it at the calibration poses), the same wherever one predicts:
    # with a gain of zero nothing stays.
    far_field = krige(dataclasses.replace(basis, gain=np.zeros_like(basis.gain)), layout, params, q_far)
    assert np.all(np.linalg.norm(far_field.mean, axis=1) < 1e-3 * np.linalg.norm(near.mean, axis=1).min())
    np.testing.assert_allclose(far_field.std_ratio, 1.0, atol=1e-3)
