"""Backends of the Monte Carlo trial kernels, registered by name.

A trial block (:class:`~robocal_uncertainty.uncertainty.calibration.trials.CalibrationTrials`)
draws its inputs with numpy from its own seeded streams, then spends most of its time in the
re-identification (the chord iteration, whose exact steps walk the kinematic chain at the
campaign's poses) and walking the chain to the test (or map) configurations. A backend
supplies those walks, and may take over the whole re-identification of a sub-batch; the
draws, the executor around the blocks (processes, Dask) and the chunking stay the same, so a
backend consumes the very same draws and changes a result only at the level of rounding
(the tests hold every backend to 1e-12 relative of the numpy one).

``numpy``
    The reference: :class:`~robocal_uncertainty.core.kinematics.NearbyPoints` where it
    applies, :func:`~robocal_uncertainty.core.kinematics.forward_points` elsewhere. Always there.
``numba``
    Compiled (extra ``fast``): the whole chord re-identification of every trial, start to end
    (:func:`~robocal_uncertainty.kernels._numba_walk.chord_solve`), and the walk to the test
    configurations; per trial, short loops over the poses joint by joint (no temporaries of a
    whole batch), trials spread over numba's threads. Compiled on first use and cached on disk.
``cupy``
    The walk on a GPU (extra ``gpu``), written against an array module so that it runs with
    numpy standing in (how the tests check it).

``auto`` picks the fastest one installed: numba where it imports, else numpy. CuPy is used
only when asked for by name: with the re-identification's small batches on the host, its
transfers cost more than the walk (see ``benchmarks/bench_gpu.py``).
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.kernels.registry import (
        BACKEND_CHOICES,
        NEARBY_TEST_CONFIGURATIONS,
        Backend,
        BackendInfo,
        CupyBackend,
        NumbaBackend,
        NumpyBackend,
        ToolPredictor,
        available_backends,
        backend_names,
        get_backend,
        register_backend,
        resolve_backend,
    )

__all__ = [
    "BACKEND_CHOICES",
    "NEARBY_TEST_CONFIGURATIONS",
    "Backend",
    "BackendInfo",
    "CupyBackend",
    "NumbaBackend",
    "NumpyBackend",
    "ToolPredictor",
    "available_backends",
    "backend_names",
    "get_backend",
    "register_backend",
    "resolve_backend",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
