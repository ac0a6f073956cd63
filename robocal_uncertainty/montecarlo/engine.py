"""Block-based, reproducible Monte Carlo engine (JCGM 101 §7, adaptive §7.9).

Reproducibility contract
------------------------
The trial stream is cut into blocks of ``block_size`` trials. Block ``b`` (0-based)
draws only from ``np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(b,)))``,
which is exactly the ``b``-th child of ``np.random.SeedSequence(seed).spawn(...)``, but
can be built for any ``b`` without spawning its predecessors (so a worker needs only
``seed`` and ``b``). Blocks are reassembled in block order, so the model values are
bit-identical whatever ``chunk_blocks`` and ``workers`` are. ``block_size`` *does*
change the stream, hence it is recorded in every result.

A trial block is either a plain callable ``trial_block(rng, n) -> (n, n_out)`` (called
once per block), or a :class:`StagedTrialBlock` with ``draw(rng, n)`` and
``evaluate(inputs)``: then each block draws its own inputs and the inputs of
``chunk_blocks`` consecutive blocks are evaluated in one vectorised call. The staged
form is bit-identical across ``chunk_blocks`` as long as ``evaluate`` computes each
row from that row alone, which JCGM 101 models (one model value per trial) do.

Chunks run in this process, on ``workers`` local processes, or on any ``executor`` with
``submit`` (``concurrent.futures``, a ``dask.distributed.Client``; see :mod:`.executor`);
the result is the same on all. :func:`run_trials` returns every model value;
:func:`reduce_trials` reduces each block where it ran (moments of all outputs, values of a
few columns, see :mod:`.streaming`) so the driver's memory does not grow with the
number of outputs.
"""

from __future__ import annotations

import math
import multiprocessing
import warnings
from collections import deque
from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import Distribution
from robocal_uncertainty.montecarlo.executor import FutureLike, check_executor, executor_slots, open_executor
from robocal_uncertainty.montecarlo.streaming import Moments, Reduction
from robocal_uncertainty.montecarlo.summary import (
    MonteCarloIntervalKind,
    OutputSummary,
    Summary,
    check_coverage,
    coverage_bounds,
    minimum_trials,
    numerical_tolerance,
    summarize,
)

__all__ = [
    "AdaptiveReport",
    "AdaptiveSettings",
    "DistributionTrials",
    "ModelOutputError",
    "MonteCarloResult",
    "NonFinitePolicy",
    "ProgressCallback",
    "ReducedTrials",
    "StagedTrialBlock",
    "TrialBlock",
    "TrialsResult",
    "block_rng",
    "monte_carlo",
    "monte_carlo_result",
    "reduce_trials",
    "resolve_inputs",
    "run_trials",
]

TrialBlock = Callable[[np.random.Generator, int], ArrayLike]
"""``trial_block(rng, n) -> array (n, n_out) or (n,)``: n trials, all randomness from rng."""

ProgressCallback = Callable[[int, int | None], None]
"""``progress(trials_done, trials_target)``; target is None for adaptive runs."""

NonFinitePolicy = Literal["raise", "drop"]
"""``raise``: a NaN/inf model value is a :class:`ModelOutputError`. ``drop``: trials
with any non-finite output are discarded, counted in ``n_dropped`` and warned about
(JCGM 101 forbids silently averaging them, not excluding them openly)."""

DEFAULT_BLOCK_SIZE = 10_000
_JCGM_MIN_SEQUENCE = 10_000


class ModelOutputError(ConfigError):
    """The model or trial block returned the wrong shape or non-finite values."""


@runtime_checkable
class StagedTrialBlock(Protocol):
    """A trial block split into per-block sampling and chunk-wide evaluation."""

    def draw(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw the inputs of n trials: array whose axis 0 has length n."""
        ...

    def evaluate(self, inputs: NDArray[np.float64]) -> ArrayLike:
        """Model values of the given trials: shape (n,) or (n, n_out)."""
        ...


def block_rng(seed: int, block: int) -> np.random.Generator:
    """Generator of block ``block``: ``default_rng(SeedSequence(seed, spawn_key=(block,)))``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(block,)))


def _check_int(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        msg = f"{name} must be an integer >= {minimum}, got {value!r}"
        raise ConfigError(msg)
    return int(value)


@dataclass(frozen=True)
class AdaptiveSettings:
    """Settings of the JCGM 101 §7.9 adaptive Monte Carlo procedure.

    Attributes
    ----------
    n_dig : int
        Significant decimal digits of u(y) regarded as meaningful (§7.9.2).
    tolerance : float, tuple of float, or None
        Absolute numerical tolerance δ in output units (one value for all outputs or
        one per output); overrides ``n_dig`` when given.
    coverage : float
        Coverage probability p of the monitored interval endpoints.
    interval : {"probabilistically_symmetric", "shortest"}
        Which interval's endpoints are monitored.
    max_trials : int
        Cap on the trials run; hitting it gives ``converged=False``.
    sequence_trials : int or None
        M, trials per sequence; None means max(J, 10^4) with J = ceil(100/(1-p)).
        Rounded up to whole blocks.
    monitored : tuple of int or None
        Output columns whose tolerance decides convergence (the measurand); None means all.
        Other columns are still summarised and their tolerance reached is reported.
    """

    n_dig: int = 2
    tolerance: float | tuple[float, ...] | None = None
    coverage: float = 0.95
    interval: MonteCarloIntervalKind = "probabilistically_symmetric"
    max_trials: int = 10_000_000
    sequence_trials: int | None = None
    monitored: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        _check_int("adaptive.n_dig", self.n_dig, 1)
        check_coverage(self.coverage, "adaptive.coverage")
        if self.interval not in ("probabilistically_symmetric", "shortest"):
            msg = f"adaptive.interval must be 'probabilistically_symmetric' or 'shortest', got {self.interval!r}"
            raise ConfigError(msg)
        _check_int("adaptive.max_trials", self.max_trials, 1)
        if self.sequence_trials is not None:
            _check_int("adaptive.sequence_trials", self.sequence_trials, self.min_sequence)
        if self.monitored is not None and (
            not self.monitored or any(isinstance(i, bool) or not isinstance(i, int) or i < 0 for i in self.monitored)
        ):
            msg = f"adaptive.monitored must be non-empty non-negative column indices, got {self.monitored!r}"
            raise ConfigError(msg)
        if self.tolerance is not None:
            values = np.atleast_1d(np.asarray(self.tolerance, dtype=np.float64))
            if values.ndim != 1 or not (np.isfinite(values).all() and (values > 0).all()):
                msg = f"adaptive.tolerance must be positive and finite, got {self.tolerance!r}"
                raise ConfigError(msg)

    @property
    def min_sequence(self) -> int:
        """J = ceil(100/(1-p)), the least M for which the interval is meaningful."""
        return minimum_trials(self.coverage)

    @property
    def target_sequence(self) -> int:
        """Requested M before rounding to whole blocks."""
        if self.sequence_trials is not None:
            return int(self.sequence_trials)
        return max(self.min_sequence, _JCGM_MIN_SEQUENCE)


@dataclass(frozen=True)
class AdaptiveReport:
    """Outcome of an adaptive run.

    Attributes
    ----------
    converged : bool
        Whether 2s <= δ held for every monitored quantity of every output.
    n_dig : int or None
        Digits used for δ; None when an absolute tolerance was given.
    delta : tuple of float, length n_out
        Numerical tolerance δ used per output, in output units.
    tolerance_reached : tuple of float, length n_out
        Largest of 2s(y), 2s(u), 2s(y_low), 2s(y_high) per output, in output units.
    n_sequences : int
        h, number of sequences run.
    sequence_trials : int
        Trials per sequence (M rounded up to whole blocks).
    coverage_probability : float
        p of the monitored interval.
    interval : {"probabilistically_symmetric", "shortest"}
        Which interval's endpoints were monitored.
    max_trials : int
        The cap in force.
    """

    converged: bool
    n_dig: int | None
    delta: tuple[float, ...]
    tolerance_reached: tuple[float, ...]
    n_sequences: int
    sequence_trials: int
    coverage_probability: float
    interval: MonteCarloIntervalKind
    max_trials: int


@dataclass(frozen=True, eq=False)
class TrialsResult:
    """Model values of a :func:`run_trials` call and how they were produced.

    Attributes
    ----------
    samples : ndarray, shape (n_trials - n_dropped, n_out)
        Model values in block order (read-only), in the outputs' units.
    n_trials : int
        Trials evaluated.
    seed : int
        Root seed of the block generators.
    block_size : int
        Trials per block (the last block of a fixed-size run may be shorter).
    n_blocks : int
        Blocks evaluated.
    n_dropped : int
        Trials discarded for non-finite outputs (``nonfinite="drop"``), else 0.
    adaptive : AdaptiveReport or None
        Adaptive-procedure outcome; None for a fixed number of trials.
    """

    samples: NDArray[np.float64]
    n_trials: int
    seed: int
    block_size: int
    n_blocks: int
    n_dropped: int
    adaptive: AdaptiveReport | None

    @property
    def n_outputs(self) -> int:
        """Number of output components."""
        return int(self.samples.shape[1])

    @property
    def converged(self) -> bool:
        """True for fixed runs; the adaptive verdict otherwise."""
        return True if self.adaptive is None else self.adaptive.converged

    def summary(
        self,
        coverage: float | None = None,
        *,
        bins: int | str = 100,
        expanded_from: MonteCarloIntervalKind = "probabilistically_symmetric",
    ) -> Summary:
        """:func:`summarize` the samples; coverage defaults to the adaptive one, else 0.95."""
        if coverage is None:
            coverage = 0.95 if self.adaptive is None else self.adaptive.coverage_probability
        return summarize(self.samples, coverage, bins=bins, expanded_from=expanded_from)


def _as_outputs(label: str, values: ArrayLike, n: int) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim == 1 and array.shape[0] == n:
        return array[:, np.newaxis]
    if array.ndim == 2 and array.shape[0] == n and array.shape[1] >= 1:
        return array
    msg = f"{label} output must have shape ({n},) or ({n}, n_out), got {np.shape(values)}"
    raise ModelOutputError(msg)


def _evaluate_chunk(
    trial_block: TrialBlock | StagedTrialBlock,
    seed: int,
    first_block: int,
    sizes: tuple[int, ...],
) -> list[NDArray[np.float64]]:
    """Model values of blocks ``first_block, first_block + 1, ...`` with the given sizes."""
    blocks = range(first_block, first_block + len(sizes))
    if isinstance(trial_block, StagedTrialBlock):
        draws = [trial_block.draw(block_rng(seed, b), n) for b, n in zip(blocks, sizes)]
        for draw, n in zip(draws, sizes):
            if np.shape(draw)[:1] != (n,):
                msg = f"draw output must have {n} rows, got shape {np.shape(draw)}"
                raise ModelOutputError(msg)
        total = sum(sizes)
        values = _as_outputs("model", trial_block.evaluate(np.concatenate(draws)), total)
        return np.split(values, np.cumsum(sizes)[:-1])
    return [_as_outputs("trial_block", trial_block(block_rng(seed, b), n), n) for b, n in zip(blocks, sizes)]


@dataclass(frozen=True, eq=False)
class _ReducedBlock:
    """One block reduced on the worker: moments of its finite rows and its kept columns."""

    n_rows: int
    n_outputs: int
    n_bad: int
    moments: Moments | None  # None when no row is left (or the policy is to raise)
    kept: NDArray[np.float64]


def _reduce_chunk(
    trial_block: TrialBlock | StagedTrialBlock,
    seed: int,
    first_block: int,
    sizes: tuple[int, ...],
    reduction: Reduction,
    nonfinite: NonFinitePolicy,
) -> list[_ReducedBlock]:
    """:func:`_evaluate_chunk`, then each block reduced where it was evaluated."""
    out = []
    for values in _evaluate_chunk(trial_block, seed, first_block, sizes):
        finite = np.isfinite(values).all(axis=1)
        n_bad = int(values.shape[0] - finite.sum())
        if n_bad and nonfinite == "raise":
            out.append(_ReducedBlock(values.shape[0], values.shape[1], n_bad, None, np.zeros((0, reduction.keep.size))))
            continue
        good = values if not n_bad else values[finite]
        if good.shape[0] == 0:
            reduction.check(values.shape[1])
            out.append(_ReducedBlock(values.shape[0], values.shape[1], n_bad, None, good[:, reduction.keep]))
            continue
        moments, kept = reduction.reduce(good)
        out.append(_ReducedBlock(values.shape[0], values.shape[1], n_bad, moments, kept))
    return out


_ChunkTask = Callable[..., list[Any]]


def _fixed_blocks(total: int, block_size: int) -> tuple[int, Callable[[int], int]]:
    """Number of blocks of a fixed run of `total` trials and each block's size (the last one short)."""
    n_blocks = math.ceil(total / block_size)
    last = total - (n_blocks - 1) * block_size
    return n_blocks, lambda b: last if b == n_blocks - 1 else block_size


def _iter_blocks(
    trial_block: TrialBlock | StagedTrialBlock,
    seed: int,
    sizes: Callable[[int], int],
    n_blocks: int,
    *,
    chunk_blocks: int,
    workers: int,
    mp_context: str | None,
    executor: object | None = None,
    task: tuple[_ChunkTask, tuple[Any, ...]] = (_evaluate_chunk, ()),
    lookahead: int = 2,
) -> Generator[Any, None, None]:
    """Yield each block's result in block order, evaluating chunks lazily.

    ``task`` is the chunk function and its extra arguments after the chunk's sizes;
    chunks run in this process, on ``workers`` local processes or on ``executor``.
    At most ``lookahead`` chunks per executor slot are submitted and not yet yielded.
    """
    function, extra = task
    chunks = (
        (
            start,
            tuple(sizes(b) for b in range(start, min(start + chunk_blocks, n_blocks))),
        )
        for start in range(0, n_blocks, chunk_blocks)
    )
    with open_executor(workers=workers, executor=executor, mp_context=mp_context) as runner:
        if runner is None:
            for start, chunk in chunks:
                yield from function(trial_block, seed, start, chunk, *extra)
            return
        window = lookahead * executor_slots(runner)
        pending: deque[FutureLike] = deque()
        try:
            # A bounded look-ahead keeps memory flat and lets an adaptive run stop early.
            for start, chunk in chunks:
                pending.append(runner.submit(function, trial_block, seed, start, chunk, *extra))
                if len(pending) >= window:
                    yield from pending.popleft().result()
            while pending:
                yield from pending.popleft().result()
        finally:
            # An executor owned by the caller keeps running: drop what is still queued.
            for future in pending:
                cancel = getattr(future, "cancel", None)
                if callable(cancel):
                    cancel()


class _Collector:
    """Checks each block for non-finite values and applies the policy."""

    def __init__(self, policy: NonFinitePolicy) -> None:
        self.policy = policy
        self.n_outputs: int | None = None
        self.n_dropped = 0

    def accept(self, block: int, values: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.n_outputs is None:
            self.n_outputs = values.shape[1]
        elif values.shape[1] != self.n_outputs:
            msg = f"model output of block {block} has {values.shape[1]} components, earlier blocks had {self.n_outputs}"
            raise ModelOutputError(msg)
        finite_rows = np.isfinite(values).all(axis=1)
        if finite_rows.all():
            return values
        bad = int(values.shape[0] - finite_rows.sum())
        if self.policy == "raise":
            msg = (
                f"model returned non-finite values in {bad} of {values.shape[0]} trials of "
                f"block {block}; they must not be averaged (use nonfinite='drop' to discard)"
            )
            raise ModelOutputError(msg)
        self.n_dropped += bad
        return values[finite_rows]


def _check_common(seed: int, block_size: int, chunk_blocks: int, workers: int, nonfinite: str) -> None:
    _check_int("seed", seed, 0)
    _check_int("block_size", block_size, 1)
    _check_int("chunk_blocks", chunk_blocks, 1)
    _check_int("workers", workers, 1)
    if nonfinite not in ("raise", "drop"):
        msg = f"nonfinite must be 'raise' or 'drop', got {nonfinite!r}"
        raise ConfigError(msg)


def _check_runner(trial_block: object, workers: int, executor: object | None, mp_context: str | None) -> None:
    if not callable(trial_block) and not isinstance(trial_block, StagedTrialBlock):
        msg = f"trial_block must be callable or have draw/evaluate, got {type(trial_block)}"
        raise ConfigError(msg)
    if mp_context is not None and mp_context not in multiprocessing.get_all_start_methods():
        msg = f"mp_context must be one of {multiprocessing.get_all_start_methods()}, got {mp_context!r}"
        raise ConfigError(msg)
    if executor is not None:
        if workers > 1:
            msg = f"give either an executor or workers > 1, not both (workers={workers})"
            raise ConfigError(msg)
        check_executor(executor)


def _sequence_stats(
    values: NDArray[np.float64], settings: AdaptiveSettings
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(count, mean, M2) of one sequence, shape (3, n_out), and its (y, u, y_low, y_high)."""
    mean = values.mean(axis=0)
    m2 = ((values - mean) ** 2).sum(axis=0)
    low, high = coverage_bounds(np.sort(values, axis=0), settings.coverage, settings.interval)
    std = np.sqrt(m2 / (values.shape[0] - 1))
    moments = np.stack([np.full_like(mean, values.shape[0]), mean, m2])
    return moments, np.stack([mean, std, low, high])


def _pooled_std(moments: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Standard deviation (ddof=1) of all sequences from their (count, mean, M2)."""
    stacked = np.stack(moments)  # (h, 3, n_out)
    counts, means, m2 = stacked[:, 0], stacked[:, 1], stacked[:, 2]
    total = counts.sum(axis=0)
    grand = (counts * means).sum(axis=0) / total
    # Chan et al. pooling avoids re-reducing all h×M values after every sequence.
    pooled = m2.sum(axis=0) + (counts * (means - grand) ** 2).sum(axis=0)
    return np.asarray(np.sqrt(pooled / (total - 1)), dtype=np.float64)


def _deltas(settings: AdaptiveSettings, u: NDArray[np.float64], n_outputs: int) -> NDArray[np.float64]:
    if settings.tolerance is None:
        return np.array([numerical_tolerance(float(v), settings.n_dig) for v in u])
    given = np.atleast_1d(np.asarray(settings.tolerance, dtype=np.float64))
    if given.shape[0] == 1:
        return np.full(n_outputs, given[0])
    if given.shape[0] != n_outputs:
        msg = f"adaptive.tolerance must have 1 or {n_outputs} values, got {given.shape[0]}"
        raise ConfigError(msg)
    return given


def run_trials(
    trial_block: TrialBlock | StagedTrialBlock,
    *,
    seed: int,
    n_trials: int | None = None,
    adaptive: AdaptiveSettings | None = None,
    block_size: int = DEFAULT_BLOCK_SIZE,
    chunk_blocks: int = 1,
    workers: int = 1,
    progress: ProgressCallback | None = None,
    nonfinite: NonFinitePolicy = "raise",
    mp_context: str | None = None,
    executor: object | None = None,
) -> TrialsResult:
    """Evaluate Monte Carlo trials block by block, reproducibly (see module docstring).

    Parameters
    ----------
    trial_block : callable or StagedTrialBlock
        ``trial_block(rng, n)`` returning n model values, shape (n,) or (n, n_out); all
        randomness must come from ``rng``. Must be picklable when ``workers > 1``.
    seed : int
        Root seed (>= 0) of the per-block generators.
    n_trials : int, optional
        Fixed number of trials (>= 1); the last block holds the remainder.
        Exactly one of ``n_trials`` and ``adaptive`` must be given.
    adaptive : AdaptiveSettings, optional
        Run the JCGM 101 §7.9 adaptive procedure instead.
    block_size : int
        Trials per block; part of the random stream, so recorded in the result.
    chunk_blocks : int
        Blocks per task (and per vectorised ``evaluate`` of a staged block): a
        memory/overhead knob that never changes the result.
    workers : int
        Local processes (1 = in this process); never changes the result.
    progress : callable, optional
        ``progress(trials_done, trials_target_or_None)`` after each chunk.
    nonfinite : {"raise", "drop"}
        Policy for NaN/inf model values (see :data:`NonFinitePolicy`).
    mp_context : str, optional
        Multiprocessing start method for the workers; None is the platform default.
    executor : object, optional
        Where chunks run instead of ``workers`` local processes: anything with
        ``submit(fn, *args)`` returning a future with ``result()``
        (``concurrent.futures`` executors, ``dask.distributed.Client``; see
        :mod:`.executor`). Owned by the caller, left running; never changes the result.

    Returns
    -------
    TrialsResult
        Model values (n_trials, n_out) and run metadata.

    See Also
    --------
    reduce_trials : the same trials reduced block by block, for many outputs.
    """
    _check_common(seed, block_size, chunk_blocks, workers, nonfinite)
    if (n_trials is None) == (adaptive is None):
        msg = "give exactly one of n_trials and adaptive, got " + ("both" if adaptive is not None else "neither")
        raise ConfigError(msg)
    _check_runner(trial_block, workers, executor, mp_context)
    collector = _Collector(nonfinite)
    if adaptive is None:
        total = _check_int("n_trials", n_trials, 1)
        stream_args = (trial_block, seed, block_size, chunk_blocks, workers, mp_context, executor)
        return _run_fixed(total, stream_args, progress, collector)
    return _run_adaptive(
        trial_block,
        adaptive,
        seed,
        block_size=block_size,
        chunk_blocks=chunk_blocks,
        workers=workers,
        progress=progress,
        collector=collector,
        mp_context=mp_context,
        executor=executor,
    )


def _run_fixed(
    total: int,
    stream_args: tuple[TrialBlock | StagedTrialBlock, int, int, int, int, str | None, object | None],
    progress: ProgressCallback | None,
    collector: _Collector,
) -> TrialsResult:
    """`total` trials in blocks of ``block_size`` (the last one the remainder); `stream_args`
    are :func:`run_trials`' trial block, seed, block size, chunk blocks, workers, start method
    and executor."""
    trial_block, seed, block_size, chunk_blocks, workers, mp_context, executor = stream_args
    n_blocks, sizes = _fixed_blocks(total, block_size)
    blocks: list[NDArray[np.float64]] = []
    stream = _iter_blocks(
        trial_block,
        seed,
        sizes,
        n_blocks,
        chunk_blocks=chunk_blocks,
        workers=workers,
        mp_context=mp_context,
        executor=executor,
    )
    done = 0
    try:
        for b, values in enumerate(stream):
            blocks.append(collector.accept(b, values))
            done += values.shape[0]
            if progress is not None and ((b + 1) % chunk_blocks == 0 or b == n_blocks - 1):
                progress(done, total)
    finally:
        stream.close()
    samples = np.concatenate(blocks)
    samples.setflags(write=False)
    _warn_dropped(collector.n_dropped, total)
    return TrialsResult(samples, total, seed, block_size, n_blocks, collector.n_dropped, None)


def _warn_dropped(n_dropped: int, n_trials: int) -> None:
    if n_dropped:
        warnings.warn(
            f"dropped {n_dropped} of {n_trials} trials with non-finite model values",
            RuntimeWarning,
            stacklevel=3,
        )


def _run_adaptive(
    trial_block: TrialBlock | StagedTrialBlock,
    settings: AdaptiveSettings,
    seed: int,
    *,
    block_size: int,
    chunk_blocks: int,
    workers: int,
    progress: ProgressCallback | None,
    collector: _Collector,
    mp_context: str | None,
    executor: object | None,
) -> TrialsResult:
    """JCGM 101 §7.9.4 steps: sequences of M trials until 2s <= δ everywhere."""
    blocks_per_sequence = math.ceil(settings.target_sequence / block_size)
    sequence_trials = blocks_per_sequence * block_size
    max_sequences = settings.max_trials // sequence_trials
    if max_sequences < 2:
        msg = f"adaptive.max_trials must allow 2 sequences of {sequence_trials} trials, got {settings.max_trials}"
        raise ConfigError(msg)
    n_blocks = max_sequences * blocks_per_sequence
    # One chunk in flight per slot, not two: chunks submitted past the sequence that
    # converges are wasted, and they still run (a process pool cannot cancel a chunk once
    # it is queued to a worker): a pool shut down after the run waits for them, a pool
    # kept for the next run (WorkerPool) starts that run late. The driver's work between
    # two chunks (one sequence's statistics) is short against a chunk.
    stream = _iter_blocks(
        trial_block,
        seed,
        lambda _b: block_size,
        n_blocks,
        chunk_blocks=chunk_blocks,
        workers=workers,
        mp_context=mp_context,
        executor=executor,
        lookahead=1,
    )
    try:
        sequences, converged, delta, reached = _adaptive_sequences(
            stream, settings, blocks_per_sequence, chunk_blocks, progress, collector
        )
    finally:
        stream.close()
    samples = np.concatenate(sequences)
    samples.setflags(write=False)
    n_run = len(sequences) * sequence_trials
    _warn_dropped(collector.n_dropped, n_run)
    report = AdaptiveReport(
        converged=converged,
        n_dig=None if settings.tolerance is not None else settings.n_dig,
        delta=tuple(float(v) for v in delta),
        tolerance_reached=tuple(float(v) for v in reached),
        n_sequences=len(sequences),
        sequence_trials=sequence_trials,
        coverage_probability=settings.coverage,
        interval=settings.interval,
        max_trials=settings.max_trials,
    )
    return TrialsResult(
        samples,
        n_run,
        seed,
        block_size,
        len(sequences) * blocks_per_sequence,
        collector.n_dropped,
        report,
    )


def _adaptive_sequences(
    stream: Iterator[NDArray[np.float64]],
    settings: AdaptiveSettings,
    blocks_per_sequence: int,
    chunk_blocks: int,
    progress: ProgressCallback | None,
    collector: _Collector,
) -> tuple[list[NDArray[np.float64]], bool, NDArray[np.float64], NDArray[np.float64]]:
    """Sequences of blocks from `stream` until the §7.9.4 stopping rule holds (or the stream
    ends); returns the sequences, whether it held, and the last tolerances δ and 2s."""
    sequences: list[NDArray[np.float64]] = []
    moments: list[NDArray[np.float64]] = []
    monitored: list[NDArray[np.float64]] = []
    current: list[NDArray[np.float64]] = []
    delta = reached = np.zeros(0)
    done = 0
    for b, values in enumerate(stream):
        current.append(collector.accept(b, values))
        done += values.shape[0]
        if progress is not None and (b + 1) % chunk_blocks == 0:
            progress(done, None)
        if (b + 1) % blocks_per_sequence:
            continue
        sequence = np.concatenate(current)
        current = []
        sequences.append(sequence)
        seq_moments, seq_monitored = _sequence_stats(sequence, settings)
        moments.append(seq_moments)
        monitored.append(seq_monitored)
        h = len(sequences)
        if h < 2:
            continue
        spread = np.stack(monitored).std(axis=0, ddof=1) / math.sqrt(h)  # (4, n_out)
        reached = 2.0 * spread.max(axis=0)
        delta = _deltas(settings, _pooled_std(moments), sequence.shape[1])
        watched = slice(None) if settings.monitored is None else list(settings.monitored)
        if bool((reached[watched] <= delta[watched]).all()):
            return sequences, True, delta, reached
    return sequences, False, delta, reached


@dataclass(frozen=True, eq=False)
class ReducedTrials:
    """Trials of a :func:`reduce_trials` call: moments of every output, values of a few.

    Attributes
    ----------
    moments : Moments
        Count, mean, variance terms and group co-moments of all n_out outputs, combined
        over blocks in block order.
    kept_columns : ndarray of int, shape (n_keep,)
        Output columns whose model values are kept.
    kept : ndarray, shape (n_trials - n_dropped, n_keep)
        Their model values in block order (read-only), in the outputs' units.
    n_trials : int
        Trials evaluated.
    seed : int
        Root seed of the block generators.
    block_size : int
        Trials per block (the last block may be shorter).
    n_blocks : int
        Blocks evaluated.
    n_dropped : int
        Trials discarded for non-finite outputs (``nonfinite="drop"``), else 0.
    """

    moments: Moments
    kept_columns: NDArray[np.intp]
    kept: NDArray[np.float64]
    n_trials: int
    seed: int
    block_size: int
    n_blocks: int
    n_dropped: int

    @property
    def n_outputs(self) -> int:
        """Number of output components of the model."""
        return int(self.moments.mean.shape[0])

    def summary(
        self,
        coverage: float = 0.95,
        *,
        bins: int | str = 100,
        expanded_from: MonteCarloIntervalKind = "probabilistically_symmetric",
    ) -> Summary:
        """JCGM 101 :func:`summarize` of the kept columns (in ``kept_columns`` order)."""
        return summarize(self.kept, coverage, bins=bins, expanded_from=expanded_from)


def _combine_reduced(
    blocks: Generator[_ReducedBlock, None, None],
    reduction: Reduction,
    policy: NonFinitePolicy,
    total: int,
    progress: ProgressCallback | None,
    chunk_blocks: int,
    n_blocks: int,
) -> tuple[Moments | None, list[NDArray[np.float64]], int]:
    moments: Moments | None = None
    kept: list[NDArray[np.float64]] = []
    n_outputs: int | None = None
    n_dropped = done = 0
    for b, block in enumerate(blocks):
        if n_outputs is None:
            n_outputs = block.n_outputs
        elif block.n_outputs != n_outputs:
            msg = f"model output of block {b} has {block.n_outputs} components, earlier blocks had {n_outputs}"
            raise ModelOutputError(msg)
        if block.n_bad and policy == "raise":
            msg = (
                f"model returned non-finite values in {block.n_bad} of {block.n_rows} trials of "
                f"block {b}; they must not be averaged (use nonfinite='drop' to discard)"
            )
            raise ModelOutputError(msg)
        n_dropped += block.n_bad
        if block.moments is not None:
            # Fixed left-to-right order: the rounding never depends on who computed what.
            moments = block.moments if moments is None else moments.combine(block.moments)
            kept.append(block.kept)
        done += block.n_rows
        if progress is not None and ((b + 1) % chunk_blocks == 0 or b == n_blocks - 1):
            progress(done, total)
    return moments, kept, n_dropped


def reduce_trials(
    trial_block: TrialBlock | StagedTrialBlock,
    reduction: Reduction,
    *,
    seed: int,
    n_trials: int,
    block_size: int = DEFAULT_BLOCK_SIZE,
    chunk_blocks: int = 1,
    workers: int = 1,
    executor: object | None = None,
    progress: ProgressCallback | None = None,
    nonfinite: NonFinitePolicy = "raise",
    mp_context: str | None = None,
) -> ReducedTrials:
    """Run trials like :func:`run_trials`, reducing each block where it is evaluated.

    The driver holds the running moments of all outputs and the model values of
    ``reduction.keep`` only, so its memory does not grow with n_trials x n_out. The
    blocks and their generators are those of :func:`run_trials` with the same arguments,
    and the moments are combined in block order, so the result is bit-identical whatever
    ``workers``, ``executor`` and ``chunk_blocks`` are; ``kept`` equals the same columns
    of ``run_trials(...).samples`` exactly, and the moments equal the mean and covariance
    of those samples to rounding.

    Parameters
    ----------
    trial_block : callable or StagedTrialBlock
        As for :func:`run_trials`.
    reduction : Reduction
        Co-moment groups and kept columns.
    seed, n_trials, block_size, chunk_blocks, workers, executor, progress, nonfinite, mp_context
        As for :func:`run_trials` (a fixed number of trials only).

    Returns
    -------
    ReducedTrials

    Raises
    ------
    ConfigError
        Bad settings, or reduction columns beyond the model's outputs.
    ModelOutputError
        Wrong output shapes, non-finite values under ``nonfinite="raise"``, or every
        trial dropped.
    """
    _check_common(seed, block_size, chunk_blocks, workers, nonfinite)
    _check_runner(trial_block, workers, executor, mp_context)
    if not isinstance(reduction, Reduction):
        msg = f"reduction must be a Reduction, got {type(reduction).__name__}"
        raise ConfigError(msg)
    total = _check_int("n_trials", n_trials, 1)
    n_blocks, sizes = _fixed_blocks(total, block_size)
    stream = _iter_blocks(
        trial_block,
        seed,
        sizes,
        n_blocks,
        chunk_blocks=chunk_blocks,
        workers=workers,
        mp_context=mp_context,
        executor=executor,
        task=(_reduce_chunk, (reduction, nonfinite)),
    )
    try:
        moments, kept, n_dropped = _combine_reduced(
            stream, reduction, nonfinite, total, progress, chunk_blocks, n_blocks
        )
    finally:
        stream.close()
    if moments is None:
        msg = f"all {total} trials had non-finite model values"
        raise ModelOutputError(msg)
    _warn_dropped(n_dropped, total)
    samples = np.concatenate(kept)
    samples.setflags(write=False)
    return ReducedTrials(moments, reduction.keep, samples, total, seed, block_size, n_blocks, n_dropped)


@dataclass(frozen=True)
class DistributionTrials:
    """Staged trial block of a JCGM 101 model with independent input distributions.

    ``draw`` samples every input in order from the block's generator and stacks the
    components into columns; ``evaluate`` calls the vectorised model.

    Attributes
    ----------
    model : callable
        ``model(x)`` with x of shape (n, n_columns), returning (n,) or (n, n_out).
    distributions : tuple of Distribution
        Inputs, in column order; a size-k input fills k consecutive columns.
    """

    model: Callable[[NDArray[np.float64]], ArrayLike]
    distributions: tuple[Distribution, ...]

    @property
    def n_columns(self) -> int:
        """Total number of scalar input components."""
        return sum(d.size for d in self.distributions)

    def draw(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Input values of n trials, shape (n, n_columns)."""
        columns = [np.reshape(d.sample(rng, n), (n, d.size)) for d in self.distributions]
        return np.concatenate(columns, axis=1)

    def evaluate(self, inputs: NDArray[np.float64]) -> ArrayLike:
        """Model values, shape (n,) or (n, n_out)."""
        return self.model(inputs)

    def __call__(self, rng: np.random.Generator, n: int) -> ArrayLike:
        return self.evaluate(self.draw(rng, n))


def resolve_inputs(
    inputs: Sequence[Distribution] | Mapping[str, Distribution],
) -> tuple[tuple[str, ...], tuple[Distribution, ...], tuple[str, ...]]:
    """Names, distributions and per-column labels (``name[i]`` for vector inputs)."""
    if isinstance(inputs, Mapping):
        names = tuple(str(k) for k in inputs)
        distributions = tuple(inputs.values())
    else:
        distributions = tuple(inputs)
        names = tuple(f"x{i}" for i in range(len(distributions)))
    if not distributions:
        msg = "inputs must hold at least one distribution, got none"
        raise ConfigError(msg)
    for name, dist in zip(names, distributions):
        if not isinstance(dist, Distribution):
            msg = f"input {name!r} must be a Distribution, got {type(dist).__name__}"
            raise ConfigError(msg)
    columns: list[str] = []
    for name, dist in zip(names, distributions):
        columns.extend([name] if dist.size == 1 else [f"{name}[{i}]" for i in range(dist.size)])
    return names, distributions, tuple(columns)


@dataclass(frozen=True, eq=False)
class MonteCarloResult:
    """JCGM 101 propagation of distributions through a model.

    Attributes
    ----------
    outputs : tuple of OutputSummary, length n_out
        Estimate, u, intervals, expanded uncertainty and histogram per output.
    covariance : ndarray, shape (n_out, n_out)
        Covariance (ddof=1) of the outputs, in products of their units.
    coverage_probability : float
        p of every interval.
    samples : ndarray, shape (M, n_out), or None
        Model values (read-only), None when ``keep_samples=False``.
    input_names : tuple of str
        Input names (mapping keys, or ``x0, x1, ...``).
    input_columns : tuple of str
        Label of each model-input column (``name[i]`` for vector inputs).
    n_trials : int
        Trials evaluated.
    seed : int
        Root seed.
    block_size : int
        Trials per block.
    n_dropped : int
        Trials dropped for non-finite outputs.
    adaptive : AdaptiveReport or None
        Adaptive-procedure outcome, None for a fixed number of trials.
    """

    outputs: tuple[OutputSummary, ...]
    covariance: NDArray[np.float64]
    coverage_probability: float
    samples: NDArray[np.float64] | None
    input_names: tuple[str, ...]
    input_columns: tuple[str, ...]
    n_trials: int
    seed: int
    block_size: int
    n_dropped: int
    adaptive: AdaptiveReport | None

    @property
    def converged(self) -> bool:
        """True for fixed runs; the adaptive verdict otherwise."""
        return True if self.adaptive is None else self.adaptive.converged


def monte_carlo(
    model: Callable[[NDArray[np.float64]], ArrayLike],
    inputs: Sequence[Distribution] | Mapping[str, Distribution],
    *,
    seed: int,
    trials: int | None = None,
    adaptive: AdaptiveSettings | None = None,
    coverage: float = 0.95,
    block_size: int = DEFAULT_BLOCK_SIZE,
    chunk_blocks: int = 1,
    workers: int = 1,
    progress: ProgressCallback | None = None,
    keep_samples: bool = True,
    bins: int | str = 100,
    expanded_from: MonteCarloIntervalKind = "probabilistically_symmetric",
    nonfinite: NonFinitePolicy = "raise",
    mp_context: str | None = None,
    executor: object | None = None,
) -> MonteCarloResult:
    """Propagate input distributions through a vectorised model (JCGM 101 §7).

    Parameters
    ----------
    model : callable
        ``model(x)``, x of shape (n, n_columns) in input units, returning (n,) or
        (n, n_out) in output units; row i must depend on x[i] only. Picklable
        (e.g. a module-level function) when ``workers > 1``.
    inputs : sequence of Distribution or mapping of str to Distribution
        Independent inputs, in column order; vector inputs fill consecutive columns.
    seed : int
        Root seed (>= 0).
    trials : int, optional
        Fixed number of trials; exactly one of ``trials`` and ``adaptive``.
    adaptive : AdaptiveSettings, optional
        JCGM 101 §7.9 adaptive procedure; its coverage must equal ``coverage``.
    coverage : float
        Coverage probability p.
    block_size, chunk_blocks, workers, progress, nonfinite, mp_context, executor
        As for :func:`run_trials`.
    keep_samples : bool
        Keep the raw model values in the result.
    bins : int or str
        Histogram bins.
    expanded_from : {"probabilistically_symmetric", "shortest"}
        Interval defining the expanded uncertainty.

    Returns
    -------
    MonteCarloResult
    """
    p = _checked_coverage(model, coverage, trials, adaptive)
    names, distributions, columns = resolve_inputs(inputs)
    run = run_trials(
        DistributionTrials(model, distributions),
        seed=seed,
        n_trials=trials,
        adaptive=adaptive,
        block_size=block_size,
        chunk_blocks=chunk_blocks,
        workers=workers,
        progress=progress,
        nonfinite=nonfinite,
        mp_context=mp_context,
        executor=executor,
    )
    return monte_carlo_result(
        run, p, names=names, columns=columns, bins=bins, keep_samples=keep_samples, expanded_from=expanded_from
    )


def monte_carlo_result(
    run: TrialsResult,
    coverage: float,
    *,
    names: tuple[str, ...],
    columns: tuple[str, ...],
    bins: int | str = 100,
    keep_samples: bool = False,
    expanded_from: MonteCarloIntervalKind = "probabilistically_symmetric",
) -> MonteCarloResult:
    """The JCGM 101 statement of a finished run (:func:`run_trials`' result) at `coverage`.

    `names` and `columns` name the model's inputs and its output columns (see
    :class:`MonteCarloResult`); `keep_samples` keeps the raw model values.
    """
    summary = run.summary(coverage, bins=bins, expanded_from=expanded_from)
    return MonteCarloResult(
        outputs=summary.outputs,
        covariance=summary.covariance,
        coverage_probability=coverage,
        samples=run.samples if keep_samples else None,
        input_names=names,
        input_columns=columns,
        n_trials=run.n_trials,
        seed=run.seed,
        block_size=run.block_size,
        n_dropped=run.n_dropped,
        adaptive=run.adaptive,
    )


def _checked_coverage(model: object, coverage: float, trials: int | None, adaptive: AdaptiveSettings | None) -> float:
    """:func:`monte_carlo`'s arguments checked; returns the coverage probability."""
    p = check_coverage(coverage)
    if trials is not None:
        _check_int("trials", trials, 1)
    if adaptive is not None and adaptive.coverage != p:
        msg = f"adaptive.coverage must equal coverage ({p}), got {adaptive.coverage}"
        raise ConfigError(msg)
    if not callable(model):
        msg = f"model must be callable, got {type(model).__name__}"
        raise ConfigError(msg)
    return p
