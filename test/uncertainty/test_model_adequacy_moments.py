"""The low-rank residual-noise moments of the adequacy test against the dense n_eq x n_eq formula."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.measurement import row_weights, stack_jacobian
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.uncertainty.model_adequacy import _residual_noise_moments

REPO = Path(__file__).resolve().parents[2]


def _dense(a_mat: np.ndarray, gain: np.ndarray, noise: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float, float]:
    n, d, _ = noise.shape
    proj = np.eye(n * d) - a_mat @ gain
    sigma = np.zeros((n * d, n * d))
    for i in range(n):
        sigma[d * i : d * (i + 1), d * i : d * (i + 1)] = noise[i]
    m_cov = proj @ sigma @ proj.T
    q = m_cov * np.outer(w, w)
    blocks = np.stack([m_cov[d * i : d * (i + 1), d * i : d * (i + 1)] for i in range(n)])
    return blocks, float(np.trace(q)), float(np.sum(q * q))


@pytest.mark.parametrize("orientation_std", [None, 1e-4])
def test_low_rank_moments_equal_the_dense_ones(orientation_std: float | None) -> None:
    model = load_robot_model(REPO / "config" / "ur10.yaml")
    sim = simulate_campaign(
        model, SimulationSettings(frame="tracker", n_poses=25, orientation_std=orientation_std), seed=2
    )
    cal = identify(model, sim.campaign)
    m = cal.measurement
    n = cal.n_poses
    d = m.dimension
    est = np.flatnonzero(cal.estimated)
    _, jac = m.predict_and_jacobian(cal.model.layout, cal.estimate, sim.campaign.joint_positions)
    a_mat = jac.reshape(n * d, -1)[:, est] / cal.column_scale[est]
    penalty = cal.lambda_**2 * np.diag(cal.penalized[est].astype(np.float64))
    w = row_weights(m, n)
    if w is None:
        gain = np.linalg.solve(a_mat.T @ a_mat + penalty, a_mat.T)
        w = np.ones(n * d)
    else:
        a_w = stack_jacobian(m, jac, est) / cal.column_scale[est]
        gain = np.linalg.solve(a_w.T @ a_w + penalty, a_w.T * w)
    rng = np.random.default_rng(0)
    root = rng.normal(size=(n, d, d)) * np.concatenate((np.full(3, 1e-5), np.full(d - 3, 1e-4)))[None, :, None]
    noise = root @ np.swapaxes(root, 1, 2)  # block-diagonal SPD, anisotropic like the encoders'
    blocks, tr1, tr2 = _residual_noise_moments(a_mat, gain, noise, w)
    ref_blocks, ref_tr1, ref_tr2 = _dense(a_mat, gain, noise, w)
    np.testing.assert_allclose(blocks, ref_blocks, rtol=1e-9, atol=1e-12 * np.abs(ref_blocks).max())
    assert tr1 == pytest.approx(ref_tr1, rel=1e-10)
    assert tr2 == pytest.approx(ref_tr2, rel=1e-9)
