"""The field's fast paths against straightforward formulations on small cases.

* The leave-one-out blocks (scale, per-component factors, degrees of freedom) from the fit basis
  at ``O(N^2 k)`` against the dense projector ``P = I - U U^T`` and a dense block-diagonal
  ``(I - H_ii)^-1`` (the formulation they replace).
* The posterior grid's contrast matrices, linear in ``c``, against ``G V(c, l) G^T`` per point.
* The draws (component-major, a triangular product, one d x d factor per draw) against the
  straightforward einsum formulation, with the same random stream.
* A field re-scaled with its own calibration's hyperparameters held gives back that estimate.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy import linalg

from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.uncertainty import model_error_draws as med
from robocal_uncertainty.uncertainty.model_error_draws import (
    SHAPE_TAU,
    FieldEstimate,
    FieldHypothesis,
    FieldNormal,
    _leave_one_out_components,
    _leave_one_out_dof,
    _leave_one_out_scale,
    _projected_blocks,
)

SERIES_D = Path(__file__).resolve().parents[1] / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


def _case(seed: int, n: int = 14, d: int = 3, k: int = 5) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, (n, 6))
    fit = np.linalg.svd(rng.normal(size=(n * d, k)), full_matrices=False)[0]
    corr = 0.7 * kernel_correlation(chordal_distance(q, q), 0.8) + 0.3 * np.eye(n)
    shape = np.array([[1.0, 0.3, 0.1], [0.3, 1.4, 0.2], [0.1, 0.2, 0.7]])[:d, :d]
    unit = np.kron(corr, shape)
    noise = linalg.block_diag(*[0.02 * (1.0 + i / n) * np.eye(d) for i in range(n)])
    r = np.linalg.cholesky(noise + 2.0 * unit) @ rng.normal(size=n * d)
    return r, fit, noise, unit, q


def _dense_blocks(x: np.ndarray, fit: np.ndarray, d: int) -> np.ndarray:
    proj = np.eye(x.shape[0]) - fit @ fit.T
    n = x.shape[0] // d
    idx = np.arange(n)
    return (proj @ x @ proj).reshape(n, d, n, d)[idx, :, idx, :]


def _dense_dof(r, fit, noise, unit, d, factors, local_variance):  # type: ignore[no-untyped-def]
    """The straightforward formulation: dense P, dense block-diagonal (I - H_ii)^-1."""
    n = r.size // d
    proj = np.eye(r.size) - fit @ fit.T
    idx = np.arange(n)
    lever = (fit @ fit.T).reshape(n, d, n, d)[idx, :, idx, :]
    inv = np.linalg.pinv(np.eye(d)[None] - lever)
    scaled = unit * np.outer(np.tile(factors, n), np.tile(factors, n))
    block_inv = linalg.block_diag(*inv)
    cov_e = block_inv @ (proj @ (noise + scaled) @ proj) @ block_inv.T
    e = (block_inv @ (proj @ r)).reshape(n, d)
    sd = np.sqrt(np.diag(cov_e))
    cov_z = cov_e / np.outer(sd, sd)
    z = e.reshape(-1) / sd
    out = np.empty(d)
    for j in range(d):
        cj = cov_z[j::d, j::d]
        tr2 = float(np.sum(cj * cj))
        gaussian = float(np.trace(cj)) ** 2 / tr2
        zj = z[j::d]
        kurtosis = float(np.mean(zj**4)) / float(np.mean(zj**2)) ** 2
        var_v = max(kurtosis / 3.0 - 1.0, local_variance, 0.0)
        spatial = float(np.sum(np.clip(cj, 0.0, 1.0) * (1.0 + 2.0 * cj * cj)))
        mixed = 2.0 * float(np.trace(cj)) ** 2 / (2.0 * tr2 + var_v * spatial)
        out[j] = min(gaussian * min(1.0, 2.0 / (kurtosis - 1.0)), mixed)
    white = np.empty((n, d))
    for i in range(n):
        evals, evecs = np.linalg.eigh(cov_e[i * d : (i + 1) * d, i * d : (i + 1) * d])
        white[i] = (evecs / np.sqrt(evals)).T @ e[i]
    return out, white


def test_leave_one_out_blocks_equal_the_dense_projector() -> None:
    r, fit, noise, unit, _ = _case(1)
    d = 3
    factors = np.array([0.8, 1.1, 1.3])
    for x in (noise, unit):
        np.testing.assert_allclose(_projected_blocks(x, fit, d), _dense_blocks(x, fit, d), rtol=0, atol=1e-12)
    scaled = unit * np.outer(np.tile(factors, r.size // d), np.tile(factors, r.size // d))
    np.testing.assert_allclose(_projected_blocks(unit, fit, d, factors), _dense_blocks(scaled, fit, d), atol=1e-12)
    dof, white, _ = _leave_one_out_dof(r, fit, noise, unit, d, factors, local_variance=0.2)
    ref_dof, ref_white = _dense_dof(r, fit, noise, unit, d, factors, 0.2)
    np.testing.assert_allclose(dof, ref_dof, rtol=1e-10)
    # Eigenvectors are defined up to sign: compare the whitened errors' squares.
    np.testing.assert_allclose(white**2, ref_white**2, rtol=1e-8, atol=1e-12)


def test_leave_one_out_scale_and_factors_match_their_definition() -> None:
    r, fit, noise, unit, _ = _case(2)
    d, n = 3, r.size // 3
    scale = _leave_one_out_scale(r, fit, noise, unit, d, (1e-4, 1e4))
    assert scale is not None
    # Definition: the mean standardised square of the leave-one-out errors is d (dense formulation).
    proj = np.eye(r.size) - fit @ fit.T
    blocks = _dense_blocks(noise + scale * unit, fit, d)
    r_pose = (proj @ r).reshape(n, d)
    mean_sq = np.mean([r_pose[i] @ np.linalg.solve(blocks[i], r_pose[i]) for i in range(n)])
    assert abs(mean_sq / d - 1.0) < 1e-9
    factors = _leave_one_out_components(r, fit, noise, unit, d, scale, iterations=200)
    idx = np.arange(n)
    lever = (fit @ fit.T).reshape(n, d, n, d)[idx, :, idx, :]
    inv = np.linalg.pinv(np.eye(d)[None] - lever)
    scaled = unit * np.outer(np.tile(factors, n), np.tile(factors, n))
    stated = np.einsum("pij,pjk,plk->pil", inv, _dense_blocks(noise + scaled, fit, d), inv)
    err = np.einsum("pij,pj->pi", inv, r_pose)
    ratio = np.mean(err**2 / np.diagonal(stated, axis1=1, axis2=2), axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=1e-3)


def test_grid_contrast_matrices_are_linear_in_the_correlated_fraction() -> None:
    r, fit, noise, _, q = _case(3, d=2)
    d, n = 2, q.shape[0]
    shape = np.array([[1.0, 0.3], [0.3, 1.4]])
    system = med._FieldSystem(
        residuals=r[: n * d],
        fit=fit,
        noise=noise,
        white=np.kron(np.eye(n), shape),
        kron_ones=np.kron(np.ones((n, n)), shape),
        distance=chordal_distance(q, q),
        shape=shape,
        dimension=d,
    )
    basis = np.linalg.qr(fit, mode="complete")[0][:, fit.shape[1] :]
    g_mat = linalg.solve_triangular(linalg.cholesky(basis.T @ noise @ basis, lower=True), basis.T, lower=True)
    for ell in med.HYPER_LENGTHS[::3]:
        for c in med.HYPER_FRACTIONS:
            direct = g_mat @ system.unit_covariance(float(c), float(ell)) @ g_mat.T
            linear = (1.0 - c) * (g_mat @ system.unit_covariance(0.0, 1.0) @ g_mat.T) + c * (
                g_mat @ system.unit_covariance(1.0, float(ell)) @ g_mat.T
            )
            np.testing.assert_allclose(linear, direct, rtol=0, atol=1e-12 * np.abs(direct).max())


def _straightforward_sample(fn: FieldNormal, rng: np.random.Generator, n: int) -> np.ndarray:
    """The draws as the einsum formulation makes them: pose-major, ``L z`` as a general product,
    then the Wishart factor, the root and the scale factors one after the other."""
    n_inst, d = fn.size // fn.dimension, fn.dimension
    parts, weights = fn._parts, fn._weights
    many = len(parts) > 1
    which = rng.choice(len(parts), size=n, p=weights) if many else np.zeros(n, dtype=np.int64)
    shape_w = fn.estimate.shape_weights
    varying = shape_w is not None and float(shape_w[0]) < 1.0
    if fn.innovations is None or varying:
        z = rng.standard_normal((n, n_inst, d))
    else:
        z = fn.innovations[rng.integers(0, fn.innovations.shape[0], size=(n, n_inst))]
    values = np.empty((n, n_inst, d))
    for k, part in enumerate(parts):
        mask = which == k
        n_t = part.tt.shape[0]
        head, tail = z[mask][:, :n_t], z[mask][:, n_t:]
        e_t = np.einsum("ts,nsm->ntm", part.tt, head)
        e_c = np.einsum("ct,ntm->ncm", part.ct, head) + np.einsum("cs,nsm->ncm", part.cc, tail)
        values[mask] = np.concatenate((e_t, -e_c), axis=1)
    if varying:
        tau = SHAPE_TAU[rng.choice(SHAPE_TAU.size, size=n, p=shape_w)]
        k_w = d / np.where(tau > 0.0, tau, 1.0)
        factor = np.tril(rng.standard_normal((n, d, d)), -1)
        factor[:, np.arange(d), np.arange(d)] = np.sqrt(rng.chisquare(k_w[:, None] - np.arange(d)))
        factor = np.where((tau > 0.0)[:, None, None], factor / np.sqrt(k_w)[:, None, None], np.eye(d))
        values = np.einsum("nij,nsj->nsi", factor, values)
    for k, part in enumerate(parts):
        mask = which == k
        values[mask] = values[mask] @ part.root.T
    dofs = np.stack([p.dof for p in parts])[which]
    values = values * np.sqrt(dofs / fn._chi2(rng, dofs))[:, None, :]
    return values.reshape(n, fn.size)


def test_draws_equal_the_straightforward_formulation() -> None:
    rng = np.random.default_rng(4)
    n_t, d = 25, 3
    qt = rng.uniform(-1.5, 1.5, (n_t, 6))
    qc = rng.uniform(-1.5, 1.5, (4, 6))
    sigma = np.array([[1.0, 0.2, 0.0], [0.2, 0.8, 0.1], [0.0, 0.1, 1.2]]) * 1e-8
    hyps = (
        FieldHypothesis(0.5, 0.8, 0.3, sigma, np.array([12.0, 20.0, 9.0])),
        FieldHypothesis(0.25, 0.4, 1.5, 1.3 * sigma, np.array([15.0, 8.0, 30.0])),
        FieldHypothesis(0.25, 0.6, 0.05, 0.7 * sigma, np.array([6.0, 25.0, 11.0])),
    )
    shape_weights = np.linspace(1.0, 2.0, SHAPE_TAU.size)
    innovations = rng.standard_normal((40, d))
    base = FieldEstimate(0.6, 0.5, sigma, scale_dof=np.array([12.0, 20.0, 9.0]), scale_correlation=0.3)
    for estimate in (
        dataclasses.replace(base, hypotheses=hyps, shape_weights=shape_weights / shape_weights.sum()),
        dataclasses.replace(base, hypotheses=hyps[:1], shape_weights=np.eye(SHAPE_TAU.size)[0]),
    ):
        fn = FieldNormal(qt, qc, estimate, innovations=innovations)
        for part, h in zip(fn._parts, estimate.hypotheses or ()):
            r_ct = h.correlated_fraction * kernel_correlation(chordal_distance(qc, qt), h.length_scale)
            np.testing.assert_allclose(part.ct, np.linalg.lstsq(part.tt, r_ct.T, rcond=None)[0].T, atol=1e-13)
        fast = fn.sample(np.random.default_rng(11), 500)
        slow = _straightforward_sample(fn, np.random.default_rng(11), 500)
        np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12 * np.abs(slow).max())


def test_rescaled_field_with_its_own_hyperparameters_is_the_estimate() -> None:
    from robocal_uncertainty.core.identification import identify
    from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
    from robocal_uncertainty.uncertainty import UncertaintySettings
    from robocal_uncertainty.uncertainty.calibration.preparation import _tracker_distances
    from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy, pose_noise_covariances

    model = load_robot_model(resolve_robot_config("ur10"))
    campaign = read_tracker_csv(SERIES_D).subset(np.arange(0, 632, 12))
    calibration = identify(model, campaign)
    settings = UncertaintySettings()
    dist = _tracker_distances(settings, campaign)
    q = campaign.joint_positions
    noise = pose_noise_covariances(calibration, q, settings.tracker_noise, settings.encoder_noise, dist)
    shape = assess_model_adequacy(calibration, q, settings.tracker_noise, settings.encoder_noise, dist)
    estimate = med.estimate_field(calibration, q, noise, shape.residual_covariance)
    again = med.rescaled_field(estimate, calibration, q, noise, shape.residual_covariance)
    np.testing.assert_allclose(again.per_pose_covariance, estimate.per_pose_covariance, rtol=1e-9)
    np.testing.assert_allclose(again.scale_dof, estimate.scale_dof, rtol=1e-9)
    assert estimate.hypotheses is not None and again.hypotheses is not None
    for h_again, h in zip(again.hypotheses, estimate.hypotheses):
        np.testing.assert_allclose(h_again.per_pose_covariance, h.per_pose_covariance, rtol=1e-9)
        np.testing.assert_allclose(h_again.scale_dof, h.scale_dof, rtol=1e-9)


def test_scale_profile_equals_the_eigendecomposition() -> None:
    rng = np.random.default_rng(5)
    m = 40
    root = rng.normal(size=(m, m)) * np.linspace(0.01, 1.0, m)
    matrix = root @ root.T
    y = rng.normal(size=m) * 3.0
    lam, vecs = np.linalg.eigh(matrix)
    u2 = (vecs.T @ y) ** 2
    profile = med._ScaleProfile.of(matrix, y)
    np.testing.assert_allclose(np.sort(profile.lam), np.clip(lam, 0.0, None), rtol=1e-10, atol=1e-13 * lam.max())
    for a in (-6.0, -1.0, 0.0, 2.5, 7.0):
        s = np.exp(a)
        den = 1.0 + s * lam
        t = s * lam / den
        half = 0.5 * (np.sum(np.log(den)) + np.sum(u2 / den))
        curv = 0.5 * (np.sum(t * (1.0 - t)) + np.sum(u2 / den * t * (2.0 * t - 1.0)))
        assert abs(profile.half_nll(a) - half) < 1e-12 * abs(half)
        assert abs(profile.curvature(a) - curv) < 1e-10 * abs(curv)


def test_a_calibration_estimates_its_field_once_and_the_lambda_sweep_holds_its_correlation(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from robocal_uncertainty.core.identification import identify
    from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
    from robocal_uncertainty.uncertainty import UncertaintySettings, default_sources
    from robocal_uncertainty.uncertainty.calibration import preparation
    from robocal_uncertainty.uncertainty.calibration.evaluation import evaluate_uncertainty
    from robocal_uncertainty.uncertainty.sweeps import sweep_lambda

    model = load_robot_model(resolve_robot_config("ur10"))
    campaign = read_tracker_csv(SERIES_D).subset(np.arange(3, 632, 12))
    calibration = identify(model, campaign)
    settings = UncertaintySettings(sources=default_sources(False), model_error="field")
    full, rescaled = [], []
    real_full, real_rescaled = preparation.estimate_field, preparation.rescaled_field

    def count_full(*args, **kwargs):  # type: ignore[no-untyped-def]
        full.append(real_full(*args, **kwargs))
        return full[-1]

    def count_rescaled(held, *args, **kwargs):  # type: ignore[no-untyped-def]
        rescaled.append((held, real_rescaled(held, *args, **kwargs)))
        return rescaled[-1][1]

    monkeypatch.setattr(preparation, "estimate_field", count_full)
    monkeypatch.setattr(preparation, "rescaled_field", count_rescaled)
    q = campaign.joint_positions[0]
    first = evaluate_uncertainty(model, campaign, q, trials=50, uncertainty=settings, calibration=calibration)
    again = evaluate_uncertainty(model, campaign, q, trials=50, uncertainty=settings, calibration=calibration)
    assert len(full) == 1  # the same calibration: the same estimate, the same statement
    np.testing.assert_array_equal(first.samples, again.samples)
    lam = calibration.lambda_
    sweep_lambda(model, campaign, calibration, q, [lam, 3.0 * lam], trials=30, settings=settings)
    assert len(full) == 1 and len(rescaled) == 1
    held, other = rescaled[0]
    assert held is full[0]
    assert (other.correlated_fraction, other.length_scale) == (held.correlated_fraction, held.length_scale)
    assert other.hypotheses is not None and held.hypotheses is not None
    same = [(h.weight, h.length_scale) for h in held.hypotheses]
    assert [(h.weight, h.length_scale) for h in other.hypotheses] == same
    # Its own residuals' scale and shape ([m^2]: no absolute tolerance).
    assert not np.allclose(other.per_pose_covariance, held.per_pose_covariance, rtol=1e-3, atol=0.0)
