"""Where Monte Carlo trial blocks run: this process, local processes, or a Dask cluster.

The engine needs only ``submit(fn, *args) -> future`` with ``future.result()`` (and,
optionally, ``future.cancel()``): :class:`concurrent.futures.ProcessPoolExecutor`,
:class:`concurrent.futures.ThreadPoolExecutor` and ``dask.distributed.Client`` all fit.
The result never depends on the executor: every block draws from its own seeded stream
and blocks are collected in block order (see :mod:`.engine`).

``dask.distributed`` is an optional dependency (``pip install robocal_uncertainty[dask]``);
it is imported only when a Dask address is given or a Dask client is passed in.
"""

from __future__ import annotations

import importlib
import multiprocessing
from collections.abc import Callable, Generator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from types import TracebackType
from typing import Any, Protocol, runtime_checkable

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "LOCAL_DASK",
    "FutureLike",
    "RunContext",
    "SubmitExecutor",
    "WorkerPool",
    "check_executor",
    "executor_slots",
    "open_executor",
]

LOCAL_DASK = "local"
"""Dask address meaning: start a ``LocalCluster`` of ``workers`` single-threaded processes."""

_DEFAULT_SLOTS = 4
"""Parallel slots assumed for an executor that does not say how many it has."""


@runtime_checkable
class FutureLike(Protocol):
    """What :meth:`SubmitExecutor.submit` returns: a handle with a blocking ``result``."""

    def result(self, timeout: float | None = None) -> Any:
        """The task's return value, re-raising its exception."""
        ...


@runtime_checkable
class SubmitExecutor(Protocol):
    """Anything that runs ``fn(*args)`` somewhere and returns a :class:`FutureLike`."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> FutureLike:
        """Schedule ``fn(*args, **kwargs)``."""
        ...


@dataclass(frozen=True, eq=False)
class RunContext:
    """How a Monte Carlo run is carried out: never what it gives.

    Every field is a choice of where and how fast the trial blocks run; the result is the
    same for every value (each block draws from its own seeded stream, blocks are collected
    in block order), so a run context is never part of a result's settings.

    Attributes
    ----------
    executor : SubmitExecutor or None
        Runs the trial blocks (a process pool, a ``dask.distributed`` client); None runs
        them in `workers` local processes.
    workers : int
        Local worker processes when no `executor` is given (1: in this process).
    progress : callable or None
        ``progress(trials_done, trials_target_or_None)`` after each chunk of the main run.
    chunk_blocks : int
        Blocks per task: a memory and overhead knob.
    mp_context : str or None
        Start method of local worker processes (None: ``forkserver`` where available).
    """

    executor: SubmitExecutor | None = None
    workers: int = 1
    progress: Callable[[int, int | None], None] | None = None
    chunk_blocks: int = 1
    mp_context: str | None = None

    def with_progress(self, progress: Callable[[int, int | None], None] | None) -> RunContext:
        """The same run context reporting to `progress` (e.g. a budget's or a sweep's phase)."""
        return replace(self, progress=progress)


def _is_dask_client(executor: object) -> bool:
    # Checked by module name so that dask is never imported for a local executor.
    return type(executor).__module__.split(".")[0] == "distributed" and type(executor).__name__ == "Client"


class _DaskSubmitter:
    """A Dask client whose tasks are never deduplicated by argument hash.

    ``Client.submit`` defaults to ``pure=True``, which tokenizes every argument (the
    whole trial block) on each call; blocks differ by their start index anyway.
    """

    def __init__(self, client: Any) -> None:
        self.client = client

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> FutureLike:
        future: FutureLike = self.client.submit(fn, *args, pure=False, **kwargs)
        return future


def check_executor(executor: object) -> SubmitExecutor:
    """Return ``executor`` ready for the engine, or raise ConfigError if it cannot submit.

    Parameters
    ----------
    executor : object
        A ``concurrent.futures.Executor``, a ``dask.distributed.Client`` or any object
        with ``submit(fn, *args)`` returning a future with ``result()``.

    Returns
    -------
    SubmitExecutor
        The executor itself, or a Dask client wrapped to submit with ``pure=False``.
    """
    if _is_dask_client(executor):
        return _DaskSubmitter(executor)
    if not callable(getattr(executor, "submit", None)):
        msg = (
            f"executor must have a submit(fn, *args) method (concurrent.futures or Dask), got {type(executor).__name__}"
        )
        raise ConfigError(msg)
    return executor  # type: ignore[return-value]  # checked: has a callable submit


def executor_slots(executor: object) -> int:
    """Tasks the executor runs at once (>= 1): it sizes the engine's look-ahead.

    ``max_workers`` of a ``concurrent.futures`` pool, the total worker threads of a
    Dask cluster, else 4. Never changes a result, only how many blocks are in flight.
    """
    client: Any = executor.client if isinstance(executor, _DaskSubmitter) else executor
    if _is_dask_client(client):
        try:
            workers = client.scheduler_info()["workers"]
            return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))
        except (KeyError, AttributeError, TypeError):
            return _DEFAULT_SLOTS
    slots = getattr(client, "_max_workers", None)
    if isinstance(slots, int) and slots >= 1:
        return slots
    return _DEFAULT_SLOTS


def _check_workers(workers: object) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        msg = f"workers must be an integer >= 1, got {workers!r}"
        raise ConfigError(msg)
    return workers


@contextmanager
def _without_malloc_trim() -> Generator[None, None, None]:
    """Start Dask workers without Dask's default ``MALLOC_TRIM_THRESHOLD_=65536``.

    Setting it stops glibc from raising its mmap threshold, so every large numpy
    temporary of a trial block is mapped and page-faulted afresh: trial blocks ran 2x
    slower (measured, 1 000 configurations x 4 000 trials). Only for the clusters started
    here; a user's cluster keeps its own configuration.
    """
    dask: Any = importlib.import_module("dask")  # optional extra, present with distributed

    environ = dask.config.get("distributed.nanny.pre-spawn-environ", default=None)
    if not isinstance(environ, dict) or "MALLOC_TRIM_THRESHOLD_" not in environ:
        yield
        return
    # None unsets a variable in this configuration (distributed.nanny._get_env_variables).
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        yield


@contextmanager
def _dask_client(address: str, workers: int) -> Generator[Any, None, None]:
    try:
        # Optional extra, untyped: held as Any.
        distributed: Any = importlib.import_module("distributed")
    except ImportError as err:
        msg = "--dask needs dask.distributed: pip install 'robocal_uncertainty[dask]'"
        raise ConfigError(msg) from err
    if address == LOCAL_DASK:
        # One thread per worker process: trial blocks are numpy-bound and hold the GIL.
        with _without_malloc_trim():
            cluster = distributed.LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
        try:
            with distributed.Client(cluster) as client:
                yield client
        finally:
            cluster.close()
        return
    try:
        client = distributed.Client(address, timeout=10)
    except OSError as err:
        msg = f"cannot connect to the Dask scheduler at {address!r}: {err}"
        raise ConfigError(msg) from err
    try:
        yield client
    finally:
        client.close()


@contextmanager
def open_executor(
    *,
    workers: int = 1,
    executor: object | None = None,
    dask: str | None = None,
    mp_context: str | None = None,
) -> Generator[SubmitExecutor | None, None, None]:
    """Resolve ``workers`` / ``executor`` / ``dask`` into one executor for a run.

    Parameters
    ----------
    workers : int
        Local worker processes (1 = run in this process); with ``dask="local"``, the
        number of worker processes of the ``LocalCluster``; must be 1 with a remote address.
    executor : object, optional
        An executor owned by the caller (left running on exit); excludes ``workers > 1``
        and ``dask``.
    dask : str, optional
        Dask scheduler address (``tcp://host:8786``) or ``"local"`` for a ``LocalCluster``
        started here and closed on exit.
    mp_context : str, optional
        Start method of the local processes. Default ``"forkserver"`` where the platform has
        it (else the platform default): ``fork`` copies a process whose other threads (BLAS,
        a ROS node's middleware, a Dask client) may hold locks, which can deadlock the child
        (Python 3.12 warns of it; 3.14 makes ``forkserver`` the default on Linux). Results do
        not depend on the start method.

    Yields
    ------
    SubmitExecutor or None
        None means: evaluate in this process.

    Raises
    ------
    ConfigError
        Conflicting options, a bad ``mp_context``, dask missing or its scheduler unreachable.
    """
    workers = _check_workers(workers)
    if executor is not None and (workers > 1 or dask is not None):
        msg = "give either an executor or workers/dask, not both"
        raise ConfigError(msg)
    mp_context = _start_method(mp_context)
    if executor is not None:
        yield check_executor(executor)
        return
    if dask is not None:
        if not isinstance(dask, str) or not dask.strip():
            msg = f"dask must be a scheduler address or 'local', got {dask!r}"
            raise ConfigError(msg)
        if dask.strip() != LOCAL_DASK and workers > 1:
            msg = f"workers={workers} applies to local processes or dask='local'; the cluster at {dask!r} has its own"
            raise ConfigError(msg)
        with _dask_client(dask.strip(), workers) as client:
            yield check_executor(client)
        return
    if workers == 1:
        yield None
        return
    context = None if mp_context is None else multiprocessing.get_context(mp_context)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _start_method(mp_context: str | None) -> str | None:
    """The start method to use: ``mp_context``, else ``"forkserver"`` where the platform has it."""
    methods = multiprocessing.get_all_start_methods()
    if mp_context is None:
        return "forkserver" if "forkserver" in methods else None
    if mp_context not in methods:
        msg = f"mp_context must be one of {methods}, got {mp_context!r}"
        raise ConfigError(msg)
    return mp_context


def _import_modules(modules: tuple[str, ...]) -> None:
    """Worker initializer: import what the trial blocks need once, at the worker's start.

    An entry ``module:function`` also calls ``function()`` of that module (e.g. loading
    compiled kernels from numba's disk cache).
    """
    for entry in modules:
        name, _, function = entry.partition(":")
        module = importlib.import_module(name)
        if function:
            getattr(module, function)()


def _ready() -> bool:
    return True


class WorkerPool:
    """Local worker processes kept across Monte Carlo runs (a long-running node's pool).

    :func:`open_executor` starts ``workers`` processes for one run and stops them after it;
    a node that evaluates every new calibration would pay the start (a fresh interpreter
    importing numpy and scipy per worker) on every sample. A ``WorkerPool`` starts them
    once and hands the same executor to every run (``run_trials(..., executor=pool.executor())``);
    results are the same as in-process, bit for bit (see :mod:`.engine`).

    Parameters
    ----------
    workers : int
        Worker processes; 1 means no pool: :meth:`executor` returns None (run in-process).
    mp_context : str, optional
        Start method. Default ``"forkserver"`` where the platform has it (else the platform
        default): forking a process with other threads (a ROS node's middleware threads)
        can deadlock the child, and the pool is started once, so the safer start costs once.
    preload : sequence of str
        Modules each worker imports when it starts (e.g. the trial block's module), so the
        first run does not pay the imports; ``module:function`` also calls that function.

    Raises
    ------
    ConfigError
        `workers` below 1 or a start method the platform lacks.

    Notes
    -----
    The pool is started on the first :meth:`executor` call (or :meth:`start`) and restarted
    if a worker died (a broken pool). Blocks of a run abandoned by an exception (e.g. a
    superseded evaluation) that are already running finish in the background; queued ones
    are cancelled (see the engine). Use as a context manager or call :meth:`close`.
    """

    def __init__(self, workers: int = 1, *, mp_context: str | None = None, preload: tuple[str, ...] = ()) -> None:
        self.workers = _check_workers(workers)
        self.mp_context = _start_method(mp_context)
        self.preload = tuple(preload)
        self.started = 0
        """How many times worker processes were started (1 after the first run, more after a crash)."""
        self._pool: ProcessPoolExecutor | None = None
        self._closed = False

    def executor(self) -> ProcessPoolExecutor | None:
        """The pool's executor (started if needed), or None when ``workers == 1``.

        Raises
        ------
        ConfigError
            The pool was closed.
        """
        if self._closed:
            msg = "the worker pool is closed"
            raise ConfigError(msg)
        if self.workers == 1:
            return None
        # A worker that died leaves the executor broken for good: start a fresh one.
        if self._pool is not None and getattr(self._pool, "_broken", False):
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        if self._pool is None:
            context = None if self.mp_context is None else multiprocessing.get_context(self.mp_context)
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=context,
                initializer=_import_modules,
                initargs=(self.preload,),
            )
            self.started += 1
        return self._pool

    def start(self, *, wait: bool = True) -> None:
        """Start every worker now (no-op for 1 worker).

        ``wait``: until each has imported `preload`; False returns at once, the workers
        starting while the caller prepares the run (a command's own start-up and preparation).
        """
        pool = self.executor()
        if pool is not None:
            futures = [pool.submit(_ready) for _ in range(self.workers)]
            for future in futures if wait else ():
                future.result()

    def close(self) -> None:
        """Stop the workers (waits for running blocks); :meth:`executor` refuses afterwards."""
        self._closed = True
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
