"""Backends of the trial kernels registered by name; see :mod:`robocal_uncertainty.kernels`."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import NearbyPoints
from robocal_uncertainty.core.measurement import MeasurementType, PointMeasurement
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.errors import ConfigError

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

Array = NDArray[np.float64]
Predictor = Callable[[Array, Array], Array]

NEARBY_TEST_CONFIGURATIONS = 64
"""Test configurations up to which the numpy backend evaluates them by the nearby-point walk:
it holds about 20 arrays of a slice's size, where :func:`forward_points` holds fewer; a
workspace map's thousands keep the smaller footprint. (The compiled walk holds none.)"""

NUMPY_WALK_UP_TO = 4
"""Test configurations up to which the numba backend, too, takes the numpy nearby-point walk.
The compiled walk sets up every trial's link rotations, about 0.9 us per trial whatever the
configurations; numpy's walk runs over all trials at once (at one configuration 0.37 against
0.95 us per trial, at four 0.70 against 1.0; at 16 the compiled one is faster)."""


class ToolPredictor(Protocol):
    """The tool near a reference: points by calling it, 6-DOF values by :meth:`poses`."""

    def __call__(self, params: Array, joint_positions: Array) -> Array: ...

    def poses(self, params: Array, joint_positions: Array) -> Array: ...


class Backend(Protocol):
    """The trial kernels of one backend.

    ``measurement_predictor`` returns what the re-identification evaluates at every step
    (the measurement type's prediction near the calibration), or None to use the type's own
    ``predict``; ``tool_predictor`` the tool at the test configurations, or None to use
    :func:`~robocal_uncertainty.core.kinematics.forward_points` and ``forward_poses``.
    """

    name: str

    def available(self) -> bool: ...

    def version(self) -> str: ...

    def measurement_predictor(
        self, measurement: MeasurementType, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Predictor | None: ...

    def tool_predictor(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> ToolPredictor | None: ...


@dataclass(frozen=True)
class BackendInfo:
    """What a report records of the backend that ran the trials.

    Attributes
    ----------
    name : str
        ``numpy``, ``numba`` or ``cupy``.
    version : str
        Version of the library behind it (numpy's for ``numpy``).
    requested : str
        What was asked for (``auto`` or a name).
    """

    name: str
    version: str
    requested: str

    def describe(self) -> str:
        """E.g. ``numba 0.59.0 (auto)``."""
        suffix = f" ({self.requested})" if self.requested != self.name else ""
        return f"{self.name} {self.version}{suffix}"


class NumpyBackend:
    """The reference backend: the kinematics module's own walks."""

    name = "numpy"

    def available(self) -> bool:
        return True

    def version(self) -> str:
        return str(np.__version__)

    def measurement_predictor(
        self, measurement: MeasurementType, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Predictor | None:
        return measurement.nearby_predictor(layout, params, joint_positions)

    def tool_predictor(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> ToolPredictor | None:
        if not NearbyPoints.supports(layout) or joint_positions.shape[0] > NEARBY_TEST_CONFIGURATIONS:
            return None
        return NearbyPoints.at(layout, params, joint_positions)


def _kind(measurement: MeasurementType) -> str | None:
    """``points`` or ``poses`` for the built-in types the kernels walk, None for any other."""
    if isinstance(measurement, PoseMeasurement):
        return "poses"
    if isinstance(measurement, PointMeasurement):
        return "points"
    return None


class NumbaBackend:
    """The compiled kernels (:mod:`~robocal_uncertainty.kernels._numba_walk`): the whole chord
    re-identification of the built-in measurement types, and the walk."""

    name = "numba"
    _ready = False

    def available(self) -> bool:
        try:
            import numba  # noqa: F401
        except ImportError:
            return False
        return True

    def version(self) -> str:
        import numba

        return str(numba.__version__)

    def warm_up(self) -> float:
        """Compile (or load from the disk cache) the kernels; return the seconds it took.

        The first time a process compiles them, the time is printed on stderr.
        """
        start = time.perf_counter()
        if NumbaBackend._ready:
            return time.perf_counter() - start
        from robocal_uncertainty.kernels import _numba_walk

        _warm_up_kernels()
        NumbaBackend._ready = True
        misses = 0
        for kernel in (_numba_walk.walk, _numba_walk.chord_solve):
            stats = getattr(kernel, "stats", None)  # cache statistics of the dispatcher
            misses += 1 if stats is None else sum(stats.cache_misses.values())
        elapsed = time.perf_counter() - start
        if misses:
            print(f"numba: trial kernels compiled in {elapsed:.1f} s (cached on disk for later runs)", file=sys.stderr)
        return elapsed

    def measurement_predictor(
        self, measurement: MeasurementType, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Predictor | None:
        from robocal_uncertainty.kernels.predictors import CompiledMeasurement, CompiledPredictor

        kind = _kind(measurement)
        if kind is None:
            return measurement.nearby_predictor(layout, params, joint_positions)
        self.warm_up()
        return CompiledMeasurement(CompiledPredictor.at(layout, params, joint_positions), orientation=kind == "poses")

    def tool_predictor(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> ToolPredictor | None:
        from robocal_uncertainty.kernels.predictors import CompiledPredictor

        if joint_positions.shape[0] <= NUMPY_WALK_UP_TO and NearbyPoints.supports(layout):
            return NearbyPoints.at(layout, params, joint_positions)
        self.warm_up()
        return CompiledPredictor.at(layout, params, joint_positions)


def _warm_up_kernels() -> None:
    """Run every compiled kernel once on a one-joint, one-pose problem, with the argument
    types of a real run (C-contiguous, writeable arrays): compiled once per process type."""
    from robocal_uncertainty.kernels._layout import flat_layout
    from robocal_uncertainty.kernels._numba_walk import chord_solve, walk

    layout = ParameterLayout(n_joints=1, has_beta=(False,))
    flat = flat_layout(layout)
    one = np.zeros((1, 1))
    trig = (np.zeros(layout.size), np.ones(layout.size), np.zeros(layout.size))
    walk(
        np.zeros((1, layout.size)),
        np.zeros((1, 1, 1)),
        flat.joints,
        flat.blocks,
        one,
        np.zeros(1),
        one,
        one,
        *trig,
        True,
        np.empty((1, 1, 12)),
        1,
    )
    index = np.zeros(1, dtype=np.int64)
    factors = (
        index,
        np.zeros(0, dtype=np.int64),
        np.zeros((1, 0)),
        np.ones((1, 1)),
        np.ones((1, 1)),
        np.ones(1),
        np.zeros((0, 1)),
        np.zeros((0, 0)),
    )
    problem = (
        np.zeros(layout.size),
        index,
        np.ones(1),
        np.ones(1),
        np.zeros((1, 3)),
        np.ones(3),
        np.zeros((1, 3, 1)),
        np.zeros((1, 1)),
        np.zeros((1, 3)),
        np.zeros((1, 1)),
    )
    walker = (flat.joints, flat.blocks, np.zeros((1, 1)), np.zeros(1), np.ones((1, 1)), np.zeros((1, 1)), *trig)
    chord_solve(
        np.zeros((1, 1, 1)),
        np.empty((0, 1, 1)),
        np.zeros((1, 1, 3)),
        np.empty((0, 1, 3)),
        np.empty((0, 1)),
        np.ones(1),
        np.zeros(1),
        problem,
        factors,
        walker,
        False,
        2,
        1e-3,
        np.empty((1, 1)),
        np.empty(1, dtype=np.int64),
        np.zeros(1, dtype=np.bool_),
        1,
    )


class CupyBackend:
    """The walk on an array module: CuPy, or numpy standing in (``module="numpy"``, for tests)."""

    name = "cupy"

    def __init__(self, module: str = "cupy") -> None:
        self.module = module

    def available(self) -> bool:
        try:
            xp: Any = __import__(self.module)
            if self.module == "cupy":
                return bool(xp.cuda.runtime.getDeviceCount() > 0)
        except Exception:  # no CuPy, no driver or no device: not available
            return False
        return True

    def version(self) -> str:
        xp: Any = __import__(self.module)
        return str(xp.__version__) + ("" if self.module == "cupy" else f" ({self.module} standing in)")

    def measurement_predictor(
        self, measurement: MeasurementType, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Predictor | None:
        from robocal_uncertainty.kernels.predictors import ArrayModulePredictor

        kind = _kind(measurement)
        if kind is None:
            return measurement.nearby_predictor(layout, params, joint_positions)
        predictor = ArrayModulePredictor.on(self.module, layout, params, joint_positions)
        return predictor if kind == "points" else predictor.poses

    def tool_predictor(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> ToolPredictor | None:
        from robocal_uncertainty.kernels.predictors import ArrayModulePredictor

        return ArrayModulePredictor.on(self.module, layout, params, joint_positions)


_REGISTRY: dict[str, Backend] = {}
_AUTO_ORDER = ("numba", "numpy")


def register_backend(backend: Backend) -> None:
    """Register `backend` under its name (replacing one of the same name)."""
    _REGISTRY[backend.name] = backend


def backend_names() -> tuple[str, ...]:
    """Names of the registered backends, installed or not."""
    return tuple(_REGISTRY)


def available_backends() -> tuple[str, ...]:
    """Names of the registered backends that can run here."""
    return tuple(name for name, backend in _REGISTRY.items() if backend.available())


def get_backend(name: str) -> Backend:
    """The backend registered as `name` (``auto``: the fastest installed).

    Raises
    ------
    ConfigError
        An unknown name, or a backend that is not installed (the message names its extra).
    """
    if name == "auto":
        for candidate in _AUTO_ORDER:
            if _REGISTRY[candidate].available():
                return _REGISTRY[candidate]
    if name not in _REGISTRY:
        msg = f"backend must be one of {', '.join(('auto', *_REGISTRY))}, got {name!r}"
        raise ConfigError(msg)
    backend = _REGISTRY[name]
    if not backend.available():
        extra = {"numba": "fast", "cupy": "gpu"}.get(name)
        hint = f": pip install 'robocal_uncertainty[{extra}]'" if extra else ""
        msg = f"backend {name!r} is not available here (not installed{', or no GPU' if name == 'cupy' else ''}){hint}"
        raise ConfigError(msg)
    return backend


def resolve_backend(name: str) -> BackendInfo:
    """The backend `name` resolves to, as recorded in reports."""
    backend = get_backend(name)
    return BackendInfo(name=backend.name, version=backend.version(), requested=name)


register_backend(NumpyBackend())
register_backend(NumbaBackend())
register_backend(CupyBackend())

BACKEND_CHOICES: tuple[str, ...] = ("auto", *_REGISTRY)
"""What ``--backend`` and the node parameter ``backend`` accept: ``auto`` and every backend
registered above (a new backend is one more line there)."""
