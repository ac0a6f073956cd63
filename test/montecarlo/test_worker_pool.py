"""A worker pool kept across runs: same numbers as in-process, started once, restarted after a crash;
adaptive runs keep one chunk per slot in flight."""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import Normal, Rectangular
from robocal_uncertainty.montecarlo.engine import AdaptiveSettings, DistributionTrials, run_trials
from robocal_uncertainty.montecarlo.executor import WorkerPool, executor_slots


def three_outputs(x: np.ndarray) -> np.ndarray:
    a, b, c = x[:, 0], x[:, 1], x[:, 2]
    return np.column_stack([a + b, a * c, np.sin(b)])


TRIALS = DistributionTrials(three_outputs, (Normal(0.0, 1.0), Rectangular(-1.0, 2.0), Normal(3.0, 0.2)))
ADAPTIVE = AdaptiveSettings(n_dig=1, max_trials=200_000)


def _crash() -> None:
    os._exit(3)  # a worker dying (killed, out of memory) breaks a process pool for good


def test_kept_pool_gives_the_in_process_numbers_run_after_run() -> None:
    fixed = run_trials(TRIALS, seed=5, n_trials=3_001, block_size=500)
    adaptive = run_trials(TRIALS, seed=5, adaptive=ADAPTIVE, block_size=2_500)
    with WorkerPool(2, mp_context="spawn", preload=("robocal_uncertainty.montecarlo.engine",)) as pool:
        pool.start()
        executor = pool.executor()
        assert executor is not None and executor_slots(executor) == 2
        for _ in range(2):  # the same processes serve every run
            again = run_trials(TRIALS, seed=5, n_trials=3_001, block_size=500, executor=pool.executor())
            np.testing.assert_array_equal(again.samples, fixed.samples)
            again = run_trials(TRIALS, seed=5, adaptive=ADAPTIVE, block_size=2_500, executor=pool.executor())
            np.testing.assert_array_equal(again.samples, adaptive.samples)
            assert again.adaptive == adaptive.adaptive
        assert pool.executor() is executor
        assert pool.started == 1
    with pytest.raises(ConfigError, match="closed"):
        pool.executor()


def test_broken_pool_is_restarted() -> None:
    reference = run_trials(TRIALS, seed=1, n_trials=2_000, block_size=500)
    with WorkerPool(2, mp_context="spawn") as pool:
        broken = pool.executor()
        assert broken is not None
        with pytest.raises(Exception, match="terminated abruptly"):
            broken.submit(_crash).result()
        fresh = pool.executor()
        assert fresh is not broken and pool.started == 2
        again = run_trials(TRIALS, seed=1, n_trials=2_000, block_size=500, executor=fresh)
        np.testing.assert_array_equal(again.samples, reference.samples)


def test_one_worker_means_in_process_and_bad_settings_are_refused() -> None:
    with WorkerPool(1) as pool:
        pool.start()
        assert pool.executor() is None and pool.started == 0
    with pytest.raises(ConfigError, match="workers must be an integer >= 1, got 0"):
        WorkerPool(0)
    with pytest.raises(ConfigError, match="mp_context must be one of"):
        WorkerPool(2, mp_context="teleport")


class _CountingExecutor(ThreadPoolExecutor):
    """Two threads that count the chunks submitted to them."""

    def __init__(self) -> None:
        super().__init__(max_workers=2)
        self.submitted = 0

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future[Any]:
        self.submitted += 1
        return super().submit(fn, *args, **kwargs)


def test_adaptive_run_keeps_one_chunk_per_slot_in_flight() -> None:
    """Chunks past the converged sequence are wasted work that a kept pool still runs."""
    with _CountingExecutor() as executor:
        result = run_trials(TRIALS, seed=2, adaptive=ADAPTIVE, block_size=2_500, executor=executor)
    assert result.adaptive is not None and result.adaptive.converged
    # At the last block yielded, at most one more chunk (one per slot, less the one yielded) is out.
    assert result.n_blocks <= executor.submitted <= result.n_blocks + 1


def test_started_without_waiting_and_preload_calls_a_function() -> None:
    # The section command starts its workers before it prepares the run; a preload entry
    # ``module:function`` calls the function in each worker (numba's kernels from the cache).
    fixed = run_trials(TRIALS, seed=8, n_trials=2_001, block_size=500)
    preload = ("robocal_uncertainty.montecarlo.engine", "robocal_uncertainty.montecarlo.executor:executor_slots")
    # The function ran in the initializer (and failed there: it needs an argument).
    with WorkerPool(2, mp_context="spawn", preload=preload) as pool, pytest.raises(BrokenProcessPool):
        pool.start()
    preload = ("robocal_uncertainty.kernels.registry:available_backends",)
    with WorkerPool(2, mp_context="spawn", preload=preload) as pool:
        pool.start(wait=False)
        again = run_trials(TRIALS, seed=8, n_trials=2_001, block_size=500, executor=pool.executor())
    assert np.array_equal(again.samples, fixed.samples)
