"""Executors and the per-block reduction: same seed, same numbers wherever blocks run."""

from __future__ import annotations

import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import Normal, Rectangular
from robocal_uncertainty.montecarlo.engine import (
    DistributionTrials,
    ModelOutputError,
    monte_carlo,
    reduce_trials,
    run_trials,
)
from robocal_uncertainty.montecarlo.executor import check_executor, executor_slots, open_executor
from robocal_uncertainty.montecarlo.streaming import Moments, Reduction


def six_outputs(x: np.ndarray) -> np.ndarray:
    """Two correlated 3-vectors from three inputs (a tiny stand-in for tool positions)."""
    a, b, c = x[:, 0], x[:, 1], x[:, 2]
    return np.column_stack([a + b, a * c, np.sin(b), b - c, a * a, np.exp(0.1 * c)])


def nan_model(x: np.ndarray) -> np.ndarray:
    y = six_outputs(x)
    y[x[:, 0] > 2.0, 4] = np.nan
    return y


TRIALS = DistributionTrials(six_outputs, (Normal(0.0, 1.0), Rectangular(-1.0, 2.0), Normal(3.0, 0.2)))
KWARGS = {"seed": 7, "n_trials": 5_003, "block_size": 700}
GROUPS = np.arange(6).reshape(2, 3)


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    with open_executor(workers=2, dask="local") as runner:
        client = runner.client  # type: ignore[union-attr]
        assert isinstance(client, distributed.Client)
        assert executor_slots(runner) == 2  # two single-threaded worker processes
        yield client


def test_run_trials_bit_identical_on_processes_threads_and_dask(dask_client) -> None:
    reference = run_trials(TRIALS, **KWARGS)
    # forkserver: fork() beside the Dask client's threads can deadlock (Python 3.12 warns).
    forkserver = multiprocessing.get_context("forkserver")
    with ThreadPoolExecutor(2) as threads, ProcessPoolExecutor(2, mp_context=forkserver) as processes:
        runs = [
            run_trials(TRIALS, workers=2, **KWARGS),
            run_trials(TRIALS, executor=threads, chunk_blocks=2, **KWARGS),
            run_trials(TRIALS, executor=processes, **KWARGS),
            run_trials(TRIALS, executor=dask_client, **KWARGS),
        ]
    for run in runs:
        np.testing.assert_array_equal(run.samples, reference.samples)
    assert reference.n_blocks == 8


def test_monte_carlo_on_dask_equals_local(dask_client) -> None:
    inputs = [Normal(0.0, 1.0), Rectangular(-1.0, 2.0), Normal(3.0, 0.2)]
    local = monte_carlo(six_outputs, inputs, seed=3, trials=3_000, block_size=1_000)
    remote = monte_carlo(six_outputs, inputs, seed=3, trials=3_000, block_size=1_000, executor=dask_client)
    assert remote.outputs == local.outputs
    np.testing.assert_array_equal(remote.covariance, local.covariance)


def test_reduction_bit_identical_everywhere_and_equal_to_numpy(dask_client) -> None:
    reduction = Reduction(GROUPS, keep=[4, 1])
    reference = reduce_trials(TRIALS, reduction, **KWARGS)
    with ThreadPoolExecutor(2) as threads:
        runs = [
            reduce_trials(TRIALS, reduction, workers=2, **KWARGS),
            reduce_trials(TRIALS, reduction, executor=threads, chunk_blocks=3, **KWARGS),
            reduce_trials(TRIALS, reduction, executor=dask_client, **KWARGS),
        ]
    for run in runs:
        np.testing.assert_array_equal(run.kept, reference.kept)
        np.testing.assert_array_equal(run.moments.mean, reference.moments.mean)
        np.testing.assert_array_equal(run.moments.m2, reference.moments.m2)
        np.testing.assert_array_equal(run.moments.comoment, reference.moments.comoment)
    # Against all model values kept in memory: kept columns exactly, moments to rounding.
    full = run_trials(TRIALS, **KWARGS).samples
    np.testing.assert_array_equal(reference.kept, full[:, [4, 1]])
    assert reference.moments.count == full.shape[0] and reference.n_outputs == 6
    np.testing.assert_allclose(reference.moments.mean, full.mean(axis=0), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(reference.moments.variance, full.var(axis=0, ddof=1), rtol=1e-12)
    cov = np.cov(full, rowvar=False)
    for g, cols in enumerate(GROUPS):
        np.testing.assert_allclose(
            reference.moments.group_covariance[g], cov[np.ix_(cols, cols)], rtol=1e-11, atol=1e-16
        )
    summary = reference.summary(0.95)
    assert len(summary.outputs) == 2
    assert summary.outputs[0].estimate == pytest.approx(full[:, 4].mean(), rel=1e-13)


def test_moments_combine_any_split() -> None:
    values = np.random.default_rng(1).normal(size=(101, 4)) * [1.0, 1e-3, 5.0, 2.0] + [0.0, 1.0, -3.0, 1e3]
    groups = np.array([[0, 1], [2, 3]])
    whole = Moments.of(values, groups)
    parts = (
        Moments.of(values[:1], groups)
        .combine(Moments.of(values[1:60], groups))
        .combine(Moments.of(values[60:], groups))
    )
    np.testing.assert_allclose(parts.mean, whole.mean, rtol=1e-14)
    np.testing.assert_allclose(parts.m2, whole.m2, rtol=1e-12)
    np.testing.assert_allclose(parts.comoment, whole.comoment, rtol=1e-12, atol=1e-12)
    assert parts.count == 101
    np.testing.assert_allclose(whole.std, values.std(axis=0, ddof=1), rtol=1e-13)


def test_reduction_nonfinite_policies() -> None:
    trials = DistributionTrials(nan_model, TRIALS.distributions)
    reduction = Reduction(GROUPS, keep=[0])
    with pytest.raises(ModelOutputError, match=r"non-finite values in \d+ of 500 trials of block"):
        reduce_trials(trials, reduction, seed=1, n_trials=2_000, block_size=500)
    with pytest.warns(RuntimeWarning, match="dropped 39 of 2000 trials"):
        dropped = reduce_trials(trials, reduction, seed=1, n_trials=2_000, block_size=500, nonfinite="drop")
    with pytest.warns(RuntimeWarning, match="dropped 39 of 2000 trials"):
        full = run_trials(trials, seed=1, n_trials=2_000, block_size=500, nonfinite="drop")
    assert dropped.n_dropped == full.n_dropped == 39
    np.testing.assert_array_equal(dropped.kept[:, 0], full.samples[:, 0])
    np.testing.assert_allclose(dropped.moments.mean, full.samples.mean(axis=0), rtol=1e-13)


def test_executor_errors() -> None:
    with pytest.raises(ConfigError, match="either an executor or workers"):
        run_trials(TRIALS, workers=2, executor=ThreadPoolExecutor(1), **KWARGS)
    with pytest.raises(ConfigError, match="executor must have a submit"):
        run_trials(TRIALS, executor=object(), **KWARGS)
    with pytest.raises(ConfigError, match="names column 6, but the model has 6 outputs"):
        reduce_trials(TRIALS, Reduction(keep=[6]), **KWARGS)
    with pytest.raises(ConfigError, match="reduction groups must be non-negative integer"):
        Reduction(np.array([[0.5, 1.0]]))
    with pytest.raises(ConfigError, match="reduction must be a Reduction"):
        reduce_trials(TRIALS, [0, 1], **KWARGS)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="dask must be a scheduler address"), open_executor(dask=" "):
        pass
    with pytest.raises(ConfigError, match="workers must be an integer >= 1"), open_executor(workers=0):
        pass
    remote = open_executor(workers=2, dask="tcp://127.0.0.1:1")
    with pytest.raises(ConfigError, match="applies to local processes or dask='local'"), remote:
        pass


def test_executor_slots_and_resolution() -> None:
    with ThreadPoolExecutor(3) as pool:
        assert executor_slots(pool) == 3
        assert check_executor(pool) is pool
    with open_executor(workers=1) as runner:
        assert runner is None
    with open_executor(workers=2) as runner:
        assert isinstance(runner, ProcessPoolExecutor) and executor_slots(runner) == 2


def test_dask_missing_is_a_one_line_error(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    with pytest.raises(ConfigError, match=r"--dask needs dask.distributed: pip install"), open_executor(dask="local"):
        pass
