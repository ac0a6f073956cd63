"""The model-error field the residual source draws, against independent references.

* The Monte Carlo's covariance at test configurations (the field drawn jointly over the
  calibration poses and the test configurations, then re-identified) against a brute-force
  draw of the field from its dense covariance (built here from the formula) followed by the
  actual non-linear re-fit (:func:`identify`) of every draw.
* The GUM covariance against the Monte Carlo's.
* The draws' covariance against the formula, jointly and on the conditional (map) path.
* Reproducibility whatever the chunking and the worker count.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, forward_points, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration import preparation
from robocal_uncertainty.uncertainty.model_error_draws import FieldEstimate, FieldNormal, standardised_innovations

ROOT = Path(__file__).resolve().parents[2]
SIGMA = 150e-6  # per-axis model error [m]
ESTIMATE = FieldEstimate(correlated_fraction=0.85, length_scale=0.6, per_pose_covariance=SIGMA**2 * np.eye(3))


def _dense_field(q: np.ndarray, estimate: FieldEstimate) -> np.ndarray:
    """Covariance of the field over the configurations `q` (each a distinct instance), pose-major."""
    c, ell = estimate.correlated_fraction, estimate.length_scale
    diff = 2.0 * np.sin((q[:, None, :] - q[None, :, :]) / 2.0)
    dist = np.sqrt(np.sum(diff**2, axis=-1))
    corr = c * np.exp(-dist / ell) + (1.0 - c) * np.eye(q.shape[0])
    return np.kron(corr, estimate.per_pose_covariance)


@pytest.fixture(scope="module")
def field_case():
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    settings = SimulationSettings(n_poses=40, tracker_noise=TrackerNoise(a=1e-6), encoder_noise=EncoderNoise(1e-7))
    sim = simulate_campaign(model, settings, seed=3)
    q_t = sim.campaign.joint_positions
    rng = np.random.default_rng(29)
    # Test configurations: one next to a calibration pose, one between poses, one far off.
    q_c = np.stack([q_t[0] + 0.03, 0.5 * (q_t[1] + q_t[2]), q_t[3] + 0.9])
    # The campaign as measured: the truth plus one draw of the field (the model is inadequate).
    e = rng.multivariate_normal(np.zeros(3 * q_t.shape[0]), _dense_field(q_t, ESTIMATE)).reshape(-1, 3)
    campaign = dataclasses.replace(sim.campaign, points=sim.true_points + e)
    calibration = identify(model, campaign, lambda_=1e-3)
    return model, campaign, calibration, q_c


def _field_run(monkeypatch, model, campaign, calibration, q_c, **kw):
    monkeypatch.setattr(preparation, "estimate_field", lambda *a, **k: ESTIMATE)
    settings = UncertaintySettings(sources=("residual",), tracker_noise=TrackerNoise(a=1e-6), model_error="field")
    return evaluate_uncertainty(
        model, campaign, q_c, uncertainty=settings, calibration=calibration, trials=kw.pop("trials", 20_000), **kw
    )


@pytest.mark.slow
def test_monte_carlo_matches_brute_force_field_and_refit(field_case, monkeypatch) -> None:
    model, campaign, calibration, q_c = field_case
    result = _field_run(monkeypatch, model, campaign, calibration, q_c)
    assert result.model_error_field is ESTIMATE
    q_t = campaign.joint_positions
    n_t = q_t.shape[0]
    q_all = np.concatenate((q_t, q_c))
    cov = _dense_field(q_all, ESTIMATE)
    rng = np.random.default_rng(101)
    draws = 300
    e = rng.multivariate_normal(np.zeros(cov.shape[0]), cov, size=draws).reshape(draws, -1, 3)
    base = forward_points(calibration.model.layout, calibration.estimate, q_c)
    errors = np.empty((draws, q_c.shape[0], 3))
    shift = np.empty_like(errors)
    for k in range(draws):
        refit = identify(model, dataclasses.replace(campaign, points=campaign.points + e[k, :n_t]), lambda_=1e-3)
        shift[k] = forward_points(refit.model.layout, refit.estimate, q_c) - base
        errors[k] = e[k, n_t:] - shift[k]  # true error of the re-fitted prediction
    # The same draws with the test configurations' field made independent of the poses': the
    # statement of the independent model (no cross term), which the comparison must tell apart.
    unpaired = e[np.roll(np.arange(draws), 1), n_t:] - shift
    for i, pose in enumerate(result.poses):
        mc_var = np.diag(pose.covariance)
        brute_var = errors[:, i].var(axis=0, ddof=1)
        ratio = mc_var.sum() / brute_var.sum()
        # 300 draws: the pooled variance is known to about sqrt(2 / 900) = 5 %.
        assert 0.85 < ratio < 1.15, (i, mc_var, brute_var)
        gum_var = np.diag(pose.gum.covariance)
        np.testing.assert_allclose(gum_var, mc_var, rtol=0.08)
    near = 0
    independent_ratio = np.diag(result.poses[near].covariance).sum() / unpaired[:, near].var(axis=0, ddof=1).sum()
    # Measured 0.81: without the cross term the near configuration's variance is 1.24 times the
    # brute force's, outside the 0.85-1.15 band above, so the comparison tells the two apart.
    assert independent_ratio < 0.87


def test_gum_matches_monte_carlo_with_the_field(field_case, monkeypatch) -> None:
    model, campaign, calibration, q_c = field_case
    result = _field_run(monkeypatch, model, campaign, calibration, q_c, trials=8000)
    for pose in result.poses:
        np.testing.assert_allclose(np.diag(pose.gum.covariance), np.diag(pose.covariance), rtol=0.1)


def test_same_field_draws_whatever_chunks_and_workers(field_case, monkeypatch) -> None:
    model, campaign, calibration, q_c = field_case
    runs = [
        _field_run(monkeypatch, model, campaign, calibration, q_c, trials=1200, block_size=500, seed=4, run=run)
        for run in (RunContext(chunk_blocks=1), RunContext(chunk_blocks=3), RunContext(chunk_blocks=2, workers=2))
    ]
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0].samples, other.samples)


def test_draw_covariance_is_the_field_with_negated_test_block() -> None:
    rng = np.random.default_rng(0)
    q_t = rng.uniform(-2, 2, (12, 6))
    q_c = np.concatenate((q_t[:3] + 0.05, rng.uniform(-2, 2, (4, 6))))
    shape = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.2], [0.0, 0.2, 1.5]]) * 1e-8
    est = FieldEstimate(correlated_fraction=0.7, length_scale=0.4, per_pose_covariance=shape)
    draw = FieldNormal(q_t, q_c, est)
    expected = _dense_field(np.concatenate((q_t, q_c)), est)
    sign = np.kron(np.concatenate((np.ones(12), -np.ones(7))), np.ones(3))
    expected = expected * np.outer(sign, sign)
    np.testing.assert_allclose(draw.covariance(), expected, atol=1e-12 * np.abs(expected).max())
    samples = draw.sample(rng, 40_000)
    np.testing.assert_allclose(np.cov(samples.T), expected, atol=0.03 * np.abs(expected).max())
    # The GUM's factored sensitivities reproduce S Cov S^T.
    sens = rng.normal(size=(5, draw.size))
    white = draw.whitened_sensitivities(sens)
    np.testing.assert_allclose(white @ white.T, sens @ expected @ sens.T, rtol=1e-6)  # the 1e-10 jitter


def test_conditional_path_keeps_marginals_and_pose_correlation(monkeypatch) -> None:
    """Beyond JOINT_TEST_MAX test configurations each is drawn given the calibration poses
    alone: its marginal and its covariance with the poses are exact."""
    from robocal_uncertainty.uncertainty import model_error_draws

    rng = np.random.default_rng(1)
    q_t = rng.uniform(-2, 2, (10, 6))
    q_c = np.concatenate((q_t[:2] + 0.05, rng.uniform(-2, 2, (3, 6))))
    est = FieldEstimate(correlated_fraction=0.9, length_scale=0.5, per_pose_covariance=np.eye(3) * 1e-8)
    joint = FieldNormal(q_t, q_c, est).covariance()
    monkeypatch.setattr(model_error_draws, "JOINT_TEST_MAX", 2)
    marginal = FieldNormal(q_t, q_c, est).covariance()
    n_t = 30
    np.testing.assert_allclose(marginal[:, :n_t], joint[:, :n_t], atol=1e-20)
    np.testing.assert_allclose(np.diag(marginal), np.diag(joint), rtol=1e-6)  # the 1e-10 jitter
    for i in range(5):
        block = slice(n_t + 3 * i, n_t + 3 * i + 3)
        np.testing.assert_allclose(marginal[block, block], joint[block, block], atol=1e-20)


def test_innovations_keep_the_covariance_and_the_residual_shape() -> None:
    rng = np.random.default_rng(5)
    residuals = rng.standard_t(6, size=(400, 3)) @ np.array([[2.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.0, 0.3, 0.7]])
    z = standardised_innovations(residuals)
    assert z is not None
    np.testing.assert_allclose(z.T @ z / z.shape[0], np.eye(3), atol=1e-12)
    q_t = rng.uniform(-2, 2, (8, 6))
    est = FieldEstimate(correlated_fraction=0.0, length_scale=0.5, per_pose_covariance=np.eye(3) * 1e-8)
    draw = FieldNormal(q_t, q_t[:2] + 0.1, est, innovations=z)
    samples = draw.sample(np.random.default_rng(1), 20_000)
    np.testing.assert_allclose(np.cov(samples.T), draw.covariance(), atol=0.15 * 1e-8)  # heavy tails
    # c = 0: every drawn vector is one of the standardised residuals (the residual bootstrap).
    first = samples[:, :3] / 1e-4
    assert np.min(np.linalg.norm(first[:50, None, :] - z[None], axis=2), axis=1).max() < 1e-9
    assert standardised_innovations(np.zeros((40, 3))) is None


def test_model_error_field_flag_reaches_the_settings() -> None:
    from robocal_uncertainty.cli import main

    with pytest.raises(SystemExit):
        main(["validate", "--help"])
    import argparse

    from robocal_uncertainty.cli._evaluation import uncertainty_settings

    base = {
        "tracker_noise_um": 5.0,
        "tracker_noise_um_per_m": 0.0,
        "encoder_noise_deg": 0.005,
        "linear_encoder_noise_um": 5.0,
        "lambda_range": None,
        "min_poses": None,
        "subset_size": None,
    }
    off = uncertainty_settings(argparse.Namespace(independent_model_error=True, **base), None, ("residual",))
    on = uncertainty_settings(argparse.Namespace(independent_model_error=False, **base), None, ("residual",))
    assert (on.model_error, off.model_error) == ("field", "independent")


@pytest.mark.parametrize("verb", ["evaluate", "validate", "map", "suggest"])
def test_the_former_model_error_field_option_is_a_noted_no_op(verb: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Scripts written when the field needed --model-error-field keep running and get the field,
    with a one-line note; combined with --independent-model-error they are refused (usage error)."""
    from robocal_uncertainty.cli._evaluation import uncertainty_settings
    from robocal_uncertainty.cli._main import _build_parser

    parser = _build_parser()
    given = [verb, "c.mcap", "--robot", "ur10"]
    args = parser.parse_args([*given, "--model-error-field"])
    note = capsys.readouterr().err.strip().splitlines()
    assert len(note) == 1 and f"{verb}: note: --model-error-field is the default now" in note[0]
    assert uncertainty_settings(args, None, ("residual",)).model_error == "field"
    assert uncertainty_settings(parser.parse_args(given), None, ("residual",)).model_error == "field"
    assert capsys.readouterr().err == ""
    with pytest.raises(SystemExit) as refused:
        parser.parse_args([*given, "--model-error-field", "--independent-model-error"])
    assert refused.value.code == 2
    assert "not allowed with argument --model-error-field" in capsys.readouterr().err
