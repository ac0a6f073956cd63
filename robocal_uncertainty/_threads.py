"""One thread per process for BLAS and numba: the policy the command line and the nodes share.

Trials are batched into many small matrix products; BLAS threads only add synchronisation
there (measured 2.7x slower on 2 cores). Parallelism comes from worker processes (``--workers``,
the nodes' ``workers``). The numba backend's kernels likewise run on one thread per process (its
threads waiting between the many short kernel calls cost more than they gave on the shared
2-core machine). The same policy everywhere also means a node computes the command line's
numbers.

:func:`limit_threads` must run before numpy loads its BLAS, so this module imports nothing but
``os``; a user's explicit setting wins.
"""

from __future__ import annotations

import os

__all__ = ["THREAD_VARIABLES", "limit_threads"]

THREAD_VARIABLES: tuple[str, ...] = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
"""The environment variables that set the thread counts of OpenBLAS, OpenMP, MKL and numba."""


def limit_threads() -> None:
    """Set each of :data:`THREAD_VARIABLES` to 1 unless the environment sets it already."""
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
