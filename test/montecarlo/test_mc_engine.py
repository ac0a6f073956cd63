"""Block engine: reproducibility, adaptive procedure (JCGM 101 §7.9), settings errors."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo import (
    AdaptiveSettings,
    DistributionTrials,
    ModelOutputError,
    Normal,
    Rectangular,
    block_rng,
    monte_carlo,
    run_trials,
)


def sum_model(x: np.ndarray) -> np.ndarray:
    return x.sum(axis=1)


def two_outputs(x: np.ndarray) -> np.ndarray:
    return np.column_stack([x.sum(axis=1), np.sin(x[:, 0]) * np.exp(0.1 * x[:, 1])])


def nan_model(x: np.ndarray) -> np.ndarray:
    y = x.sum(axis=1)
    return np.where(x[:, 0] > 2.5, np.nan, y)


class LeastSquaresTrials:
    """A custom batched trial block like the calibration module's: n noisy
    re-identifications of a 3-parameter line fit over 50 points, solved at once."""

    def __init__(self) -> None:
        self.t = np.linspace(0.0, 1.0, 50)
        self.design = np.column_stack([np.ones_like(self.t), self.t, self.t**2])
        self.truth = np.array([1.0, -2.0, 0.5])

    def __call__(self, rng: np.random.Generator, n: int) -> np.ndarray:
        noise = rng.normal(0.0, 0.01, (n, self.t.size))
        data = self.truth @ self.design.T + noise  # (n, 50)
        solution, *_ = np.linalg.lstsq(self.design, data.T, rcond=None)
        return solution.T  # (n, 3)


INPUTS = [Normal(0.0, 1.0), Rectangular(-1.0, 2.0), Normal(3.0, 0.2)]


def test_block_generator_is_spawned_child() -> None:
    # Documented contract: block b uses the b-th child of SeedSequence(seed).spawn.
    children = np.random.SeedSequence(42).spawn(4)
    for b, child in enumerate(children):
        expected = np.random.default_rng(child).random(5)
        np.testing.assert_array_equal(block_rng(42, b).random(5), expected)


def test_bit_identical_across_chunking_and_workers() -> None:
    # 25_003 trials in blocks of 4_000: six full blocks and a short last one.
    kwargs = {"seed": 2024, "trials": 25_003, "block_size": 4_000}
    reference = monte_carlo(two_outputs, INPUTS, **kwargs)
    assert reference.n_trials == 25_003 and reference.samples is not None
    for chunk_blocks, workers in [(3, 1), (7, 1), (1, 2), (2, 2)]:
        other = monte_carlo(two_outputs, INPUTS, chunk_blocks=chunk_blocks, workers=workers, **kwargs)
        assert other.samples is not None
        np.testing.assert_array_equal(other.samples, reference.samples)
        assert other.outputs == reference.outputs  # estimates, intervals, histograms
        np.testing.assert_array_equal(other.covariance, reference.covariance)
    different = monte_carlo(two_outputs, INPUTS, seed=2025, trials=25_003, block_size=4_000)
    assert different.samples is not None
    assert not np.array_equal(different.samples, reference.samples)


def test_staged_evaluation_equals_per_block_calls() -> None:
    # Vectorising the model over a chunk of blocks must not change a row-wise model.
    staged = DistributionTrials(two_outputs, tuple(INPUTS))
    a = run_trials(staged, seed=9, n_trials=12_345, block_size=1_000, chunk_blocks=5)
    b = run_trials(lambda rng, n: staged(rng, n), seed=9, n_trials=12_345, block_size=1_000)
    np.testing.assert_array_equal(a.samples, b.samples)


def test_custom_trial_block_with_workers() -> None:
    trials = LeastSquaresTrials()
    one = run_trials(trials, seed=1, n_trials=20_000, block_size=3_000)
    two = run_trials(trials, seed=1, n_trials=20_000, block_size=3_000, workers=2, chunk_blocks=2)
    np.testing.assert_array_equal(one.samples, two.samples)
    assert one.samples.shape == (20_000, 3) and one.n_blocks == 7 and one.converged
    summary = one.summary()
    # OLS: parameter covariance σ² (AᵀA)⁻¹ exactly; 20k trials estimate it to ~1 %
    # (se of a variance is sqrt(2/M) = 1 %), so 5 % is a safe but discriminating bound.
    expected = 0.01**2 * np.linalg.inv(trials.design.T @ trials.design)
    np.testing.assert_allclose(np.diag(summary.covariance), np.diag(expected), rtol=0.05)
    np.testing.assert_allclose([o.estimate for o in summary.outputs], trials.truth, atol=0.01)


def test_progress_reports_every_chunk() -> None:
    calls: list[tuple[int, int | None]] = []
    run_trials(
        LeastSquaresTrials(),
        seed=0,
        n_trials=10_500,
        block_size=1_000,
        chunk_blocks=4,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(4_000, 10_500), (8_000, 10_500), (10_500, 10_500)]


def test_adaptive_converges_for_jcgm101_9_2_2() -> None:
    inputs = [Normal(0.0, 1.0)] * 4
    result = monte_carlo(sum_model, inputs, seed=5, adaptive=AdaptiveSettings(n_dig=2))
    report = result.adaptive
    assert report is not None and report.converged and result.converged
    # §7.9.2: u(y) = 2.0 = 20 × 10^-1 with n_dig = 2, so δ = 0.05.
    assert report.delta == (0.05,)
    assert report.tolerance_reached[0] <= report.delta[0]
    assert report.sequence_trials == 10_000  # M = max(J = 2000, 10^4)
    assert result.n_trials == report.n_sequences * 10_000 and report.n_sequences >= 2
    # Stabilised to δ: estimate and u agree with 0 and 2 within 2δ.
    assert abs(result.outputs[0].estimate) <= 0.1
    assert abs(result.outputs[0].standard_uncertainty - 2.0) <= 0.1
    # The adaptive path is reproducible across workers too (look-ahead is discarded).
    again = monte_carlo(
        sum_model,
        inputs,
        seed=5,
        adaptive=AdaptiveSettings(n_dig=2),
        workers=2,
        chunk_blocks=2,
    )
    assert again.adaptive == report
    assert again.samples is not None and result.samples is not None
    np.testing.assert_array_equal(again.samples, result.samples)


def test_adaptive_tiny_max_trials_does_not_converge() -> None:
    result = monte_carlo(
        sum_model,
        [Normal(0.0, 1.0)] * 4,
        seed=5,
        adaptive=AdaptiveSettings(n_dig=3, max_trials=20_000),
    )
    assert result.adaptive is not None
    assert not result.adaptive.converged and result.adaptive.n_sequences == 2
    assert result.adaptive.tolerance_reached[0] > result.adaptive.delta[0]
    assert result.n_trials == 20_000


def test_adaptive_absolute_tolerance_vector_output() -> None:
    settings = AdaptiveSettings(tolerance=(0.05, 0.01), sequence_trials=5_000)
    result = run_trials(
        DistributionTrials(two_outputs, tuple(INPUTS)),
        seed=3,
        adaptive=settings,
        block_size=2_500,
    )
    report = result.adaptive
    assert report is not None and report.converged and report.n_dig is None
    assert report.delta == (0.05, 0.01)
    assert all(r <= d for r, d in zip(report.tolerance_reached, report.delta))
    assert report.sequence_trials == 5_000 and result.n_blocks == 2 * report.n_sequences
    assert result.summary().coverage_probability == 0.95


def test_nonfinite_outputs_raise_or_drop() -> None:
    inputs = [Normal(0.0, 1.0), Normal(0.0, 1.0)]
    with pytest.raises(ConfigError, match=r"non-finite values in \d+ of 10000 trials of block 0"):
        monte_carlo(nan_model, inputs, seed=1, trials=10_000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = monte_carlo(nan_model, inputs, seed=1, trials=10_000, nonfinite="drop")
    # P(N(0,1) > 2.5) = 0.0062, so about 62 of 10^4 trials are dropped.
    assert 20 < result.n_dropped < 120
    assert result.samples is not None and result.samples.shape == (
        10_000 - result.n_dropped,
        1,
    )
    assert any("dropped" in str(w.message) for w in caught)


def test_wrong_output_shape() -> None:
    with pytest.raises(ModelOutputError, match=r"model output must have shape \(1000,\)"):
        monte_carlo(lambda x: x[:-1, 0], [Normal(0.0, 1.0)], seed=0, trials=1_000)
    with pytest.raises(ConfigError, match=r"trial_block output must have shape \(10,\)"):
        run_trials(lambda rng, n: rng.random((n, 2, 2)), seed=0, n_trials=10)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"trials": 0}, "^trials must be an integer >= 1, got 0"),
        ({"trials": -5}, "^trials must be an integer >= 1, got -5"),
        ({"trials": 10, "coverage": 1.0}, "coverage must lie strictly between 0 and 1"),
        ({"trials": 10, "coverage": 0.0}, "coverage must lie strictly between 0 and 1"),
        ({}, "give exactly one of n_trials and adaptive, got neither"),
        ({"trials": 10, "adaptive": AdaptiveSettings()}, "got both"),
        ({"trials": 10, "block_size": 0}, "block_size must be an integer >= 1"),
        ({"trials": 10, "workers": 0}, "workers must be an integer >= 1"),
        ({"trials": 10, "nonfinite": "ignore"}, "nonfinite must be 'raise' or 'drop'"),
        (
            {"adaptive": AdaptiveSettings(max_trials=15_000)},
            "max_trials must allow 2 sequences of 10000 trials",
        ),
        (
            {"adaptive": AdaptiveSettings(coverage=0.99)},
            r"adaptive.coverage must equal coverage \(0.95\)",
        ),
    ],
)
def test_bad_settings(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        monte_carlo(sum_model, [Normal(0.0, 1.0)], seed=0, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: AdaptiveSettings(n_dig=0), "adaptive.n_dig must be an integer >= 1"),
        (
            lambda: AdaptiveSettings(tolerance=-1.0),
            "adaptive.tolerance must be positive",
        ),
        (
            lambda: AdaptiveSettings(sequence_trials=100),
            "sequence_trials must be an integer >= 2000",
        ),
        (lambda: AdaptiveSettings(interval="central"), "adaptive.interval must be"),
    ],
)
def test_bad_adaptive_settings(factory: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        factory()  # type: ignore[operator]


def test_bad_seed_and_inputs() -> None:
    with pytest.raises(ConfigError, match="seed must be an integer >= 0, got -1"):
        monte_carlo(sum_model, [Normal(0.0, 1.0)], seed=-1, trials=10)
    with pytest.raises(ConfigError, match="input 'a' must be a Distribution, got float"):
        monte_carlo(sum_model, {"a": 1.0}, seed=0, trials=10)  # type: ignore[dict-item]
    with pytest.raises(ConfigError, match="inputs must hold at least one distribution"):
        monte_carlo(sum_model, [], seed=0, trials=10)


def test_result_records_run_metadata() -> None:
    result = monte_carlo(sum_model, {"a": Normal(0.0, 1.0)}, seed=77, trials=3_000, keep_samples=False)
    assert (result.seed, result.block_size, result.n_trials) == (77, 10_000, 3_000)
    assert result.samples is None and result.adaptive is None
    assert result.input_names == ("a",) and result.input_columns == ("a",)
    assert math.isfinite(result.outputs[0].standard_uncertainty)
