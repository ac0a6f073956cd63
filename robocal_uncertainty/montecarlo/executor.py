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
from typing import Any, Protocol, runtime_checkable

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "LOCAL_DASK",
    "FutureLike",
    "SubmitExecutor",
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
        Start method of the local processes; None is the platform default.

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
    if mp_context is not None and mp_context not in multiprocessing.get_all_start_methods():
        msg = f"mp_context must be one of {multiprocessing.get_all_start_methods()}, got {mp_context!r}"
        raise ConfigError(msg)
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
