"""Backends of the blade-section trial, chosen by the same ``--backend`` names as the calibration's.

The section Monte Carlo (:class:`~robocal_uncertainty.inspection.section_mc.SectionTrials`)
draws each trial's CMM errors from its sources' own streams and evaluates the frozen model
(:class:`~robocal_uncertainty.inspection.frozen_model.FrozenSectionModel`). A backend takes over
both, consuming the very same draws:

``numpy``
    The reference: the frozen model's array operations over a batch of trials.
``numba``
    :mod:`~robocal_uncertainty.kernels.section_numba`: one trial at a time in compiled loops,
    drawing its values itself from the same generators (numba >= 0.56; older numba, or a source
    whose distribution is not rectangular, gets numpy's draws batch by batch).

There is no CuPy kernel of the section trial: ``--backend cupy`` is refused with a one-line
error, and ``auto`` takes numba where it imports, else numpy. Which backend ran, and its
version, is recorded in the section report.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.instruments.cmm import ErrorSource
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.kernels.registry import BackendInfo, available_backends, backend_names, get_backend
from robocal_uncertainty.montecarlo.distributions import Normal, Rectangular

__all__ = [
    "SECTION_BACKENDS",
    "NumbaSectionKernel",
    "pack_section_model",
    "resolve_section_backend",
]

SECTION_BACKENDS: tuple[str, ...] = ("numpy", "numba")
"""Backends with a section-trial kernel (of the names in ``--backend``)."""

_KIND_CODES = {"xy": 0, "along": 1, "common": 2}
_MAX_SOURCES = 4

Array = NDArray[np.float64]


def resolve_section_backend(name: str) -> BackendInfo:
    """The backend the section trial runs on for ``--backend name``, as recorded in reports.

    Raises
    ------
    ConfigError
        An unknown name, a backend not installed, or one without a section kernel (cupy).
    """
    if name == "auto":
        chosen = "numba" if "numba" in available_backends() else "numpy"
    elif name in backend_names() and name not in SECTION_BACKENDS:
        msg = f"backend {name!r} has no blade-section kernel: use numba or numpy (auto picks numba where installed)"
        raise ConfigError(msg)
    else:
        chosen = name
    backend = get_backend(chosen)
    return BackendInfo(name=backend.name, version=backend.version(), requested=name)


def _zero(distribution: Any) -> bool:
    """A point mass at 0 (a source of zero magnitude): its draws are all 0.0."""
    return isinstance(distribution, Normal) and distribution.mean == 0.0 and distribution.std == 0.0


# Writeable C-contiguous copies: numba types a read-only array (the frozen model's are) as
# another type, which would compile the kernels a second time beside the warmed-up ones.
def _int(values: Any, shape: tuple[int, ...] | None = None) -> NDArray[np.int64]:
    array = np.array(values, dtype=np.int64, order="C", copy=True)
    return array if shape is None else array.reshape(shape)


def _float(values: Any) -> Array:
    return np.array(values, dtype=np.float64, order="C", copy=True)


def _sources(sources: Sequence[ErrorSource], normals: Array, subset: NDArray[np.intp]) -> tuple[Any, ...]:
    """(kinds, counts, low, high, normal weights (4, n, 2), subset gains (4, m, 2)), padded to 4."""
    n, m = normals.shape[0], subset.shape[0]
    kinds = np.zeros(_MAX_SOURCES, dtype=np.int64)
    counts = np.zeros(_MAX_SOURCES, dtype=np.int64)
    low = np.zeros(_MAX_SOURCES)
    high = np.zeros(_MAX_SOURCES)
    nweight = np.zeros((_MAX_SOURCES, n, 2))
    sgain = np.zeros((_MAX_SOURCES, m, 2))
    for s, source in enumerate(sources):
        kinds[s] = _KIND_CODES[source.kind]
        counts[s] = 0 if _zero(source.distribution) else source.n_draws
        if isinstance(source.distribution, Rectangular):
            low[s], high[s] = source.distribution.low, source.distribution.high
        if source.kind == "xy":
            # The same products as ErrorSource.normal_displacement and .displacement.
            nweight[s] = source.gain[:, np.newaxis] * normals
            sgain[s] = source.gain[subset][:, np.newaxis]
        else:
            nweight[s, :, 0] = np.einsum("ij,ij->i", source.gain, normals)
            sgain[s] = source.gain[subset]
    return kinds, counts, low, high, nweight, sgain


def _runs(runs: tuple[tuple[tuple[int, int], ...], ...]) -> tuple[NDArray[np.int64], ...]:
    flat = [(a, b, region) for region, spans in enumerate(runs) for a, b in spans]
    table = _int(flat, (len(flat), 3))
    return _int(table[:, 0]), _int(table[:, 1]), _int(table[:, 2])


def _hat_factor(projector: Array) -> Array:
    """``U`` (m, 3) with ``U Uᵀ = I - projector``: the circle fit's hat matrix, a rank-3 projector
    (columns of zeros where the fit's rank is lower)."""
    hat = np.eye(projector.shape[0]) - projector
    values, vectors = np.linalg.eigh(0.5 * (hat + hat.T))
    keep = values > 0.5  # a projector's eigenvalues are 0 or 1
    factor = np.zeros((projector.shape[0], 3))
    rank = int(keep.sum())
    if rank > 3:
        msg = f"an edge window's circle fit has a hat matrix of rank {rank}, expected at most 3"
        raise ConfigError(msg)
    factor[:, :rank] = vectors[:, keep]
    return np.ascontiguousarray(factor)


def _edges(model: Any) -> tuple[Any, ...]:
    """The edge windows as flat arrays (see :func:`~.section_numba._profiles`); empty without them."""
    edges = model.edges or ()
    candidate_start, stops, offsets, check_start = [0], [], [], [0]
    ks, window_start, windows, residuals, projector_start, projectors = [], [0], [], [], [], []
    zone_start, zones, zone_offsets, codes = [0], [], [], []
    used = 0
    for edge in edges:
        candidate_start.append(candidate_start[-1] + edge.candidates.size)
        stops.extend(edge.certain_stop.tolist())
        offsets.extend(edge.candidate_offset.tolist())
        for checks in edge.checks:
            check_start.append(check_start[-1] + len(checks))
            for k, window, residual, projector in checks:
                ks.append(k)
                window_start.append(window_start[-1] + window.size)
                windows.extend(window.tolist())
                residuals.extend(residual.tolist())
                factor = _hat_factor(projector)
                projector_start.append(used)
                projectors.append(factor.ravel())
                used += factor.size
        zone_start.append(zone_start[-1] + edge.zone.size)
        zones.extend(edge.zone.tolist())
        zone_offsets.extend(edge.zone_offset.tolist())
        codes.append((edge.before, edge.after, edge.region))
    while len(candidate_start) < 3:
        candidate_start.append(candidate_start[-1])
        zone_start.append(zone_start[-1])
    pair_edges = np.zeros((0, 2)) if model.pair_edges is None else model.pair_edges
    return (
        _int(candidate_start),
        _int(stops),
        _int(offsets),
        _int(check_start),
        _int(ks),
        _int(window_start),
        _int(windows),
        _float(residuals),
        _int(projector_start),
        _float(np.concatenate(projectors) if projectors else np.zeros(0)),
        float(model.edge_tolerance),
        _int(pair_edges, (-1, 2)),
        _int(zone_start),
        _int(zones),
        _int(zone_offsets),
        _int(codes if codes else np.zeros((0, 3)), (-1, 3)),
    )


def pack_section_model(model: Any, sources: Sequence[ErrorSource]) -> tuple[Any, ...]:
    """The frozen model and its sources as the tuple of arrays the compiled kernels take.

    Parameters
    ----------
    model : FrozenSectionModel
        The batched section model.
    sources : sequence of ErrorSource
        At most four sources, in the trial block's order (the order the numpy path sums them in).

    Returns
    -------
    tuple
        ``(geometry, sources, lengths, profile, edges)``, see :mod:`~.section_numba`.
    """
    if len(sources) > _MAX_SOURCES:
        msg = f"the section kernels take at most {_MAX_SOURCES} sources, got {len(sources)}"
        raise ConfigError(msg)
    geometry = (
        _float(model.base),
        _float(model.residual),
        _float(model.solve_t),
        _float(model.jacobian_t),
        _float(model.points),
    )
    has_edges = model.edges is not None and model.pair_edges is not None
    runs = model.fixed_runs if has_edges else model.region_runs
    lengths = (
        _int(model.subset),
        _int(model.thickness_points),
        _int(model.thickness_segments),
        _int(model.chord_pairs),
    )
    return (
        geometry,
        _sources(sources, _float(model.normals), model.subset),
        lengths,
        (bool(has_edges), *_runs(runs)),
        _edges(model),
    )


def _generators_supported() -> bool:
    """Whether numba is installed and compiles numpy ``Generator`` arguments (numba >= 0.56)."""
    try:
        import numba
    except ImportError:  # the optional extra is absent (callers also ask before choosing numba)
        return False

    major, minor = (int(part) for part in numba.__version__.split(".")[:2])
    return (major, minor) >= (0, 56)


@dataclass(frozen=True, eq=False)
class NumbaSectionKernel:
    """The compiled section trial of one frozen model and its sources.

    Attributes
    ----------
    model : FrozenSectionModel
        The batched section model.
    sources : tuple of ErrorSource
        Enabled sources in the trial block's order.
    """

    model: Any
    sources: tuple[ErrorSource, ...]

    @cached_property
    def packed(self) -> tuple[Any, ...]:
        """The model as the kernels' tuple of arrays (:func:`pack_section_model`)."""
        return pack_section_model(self.model, self.sources)

    @property
    def fused(self) -> bool:
        """Whether the kernel draws the values itself: every source rectangular or zero, numba >= 0.56."""
        plain = all(isinstance(s.distribution, Rectangular) or _zero(s.distribution) for s in self.sources)
        return plain and _generators_supported()

    def trials(self, generators: Sequence[np.random.Generator], n: int, batch: int) -> Array:
        """Parameters of ``n`` trials drawn from ``generators`` (one per source), shape (n, 9)."""
        from robocal_uncertainty.kernels import section_numba

        warm_up()
        out = np.empty((n, 9))
        if self.fused:
            padding = [np.random.default_rng(0)] * (_MAX_SOURCES - len(generators))
            states = _pcg64_states(generators, _MAX_SOURCES)
            if states is None:
                section_numba.fused_trials((*generators, *padding), self.packed, out)
            else:
                section_numba.fused_pcg64_trials(states, self.packed, out)
                _set_pcg64_states(generators, states)
            return out
        for start in range(0, n, batch):
            size = min(batch, n - start)
            draws = [s.draw(g, size) for s, g in zip(self.sources, generators)]
            out[start : start + size] = self.evaluate(draws)
        return out

    def evaluate(self, draws: Sequence[Array]) -> Array:
        """Parameters for given draws (one (T, n_draws) array per source), shape (T, 9)."""
        from robocal_uncertainty.kernels import section_numba

        warm_up()
        trials = draws[0].shape[0]
        given = [np.ascontiguousarray(d, dtype=np.float64) for d in draws]
        given = [d if d.flags.writeable else d.copy() for d in given]
        padded = given + [np.zeros((trials, 0))] * (_MAX_SOURCES - len(draws))
        out = np.empty((trials, 9))
        section_numba.drawn_trials(tuple(padded), self.packed, out)
        return out


_WORD = (1 << 64) - 1


def _pcg64_states(generators: Sequence[np.random.Generator], rows: int) -> NDArray[np.uint64] | None:
    """The generators' PCG64 states as (rows, 4) uint64 (state high, low, increment high, low).

    None unless every generator's bit generator is exactly numpy's ``PCG64`` (what the engine's
    streams use), whose step the compiled draw repeats; padding rows are zeros (never drawn).
    """
    states = np.zeros((rows, 4), dtype=np.uint64)
    for row, generator in enumerate(generators):
        if type(generator.bit_generator) is not np.random.PCG64:
            return None
        inner = generator.bit_generator.state["state"]
        state, increment = int(inner["state"]), int(inner["inc"])
        states[row] = (state >> 64, state & _WORD, increment >> 64, increment & _WORD)
    return states


def _set_pcg64_states(generators: Sequence[np.random.Generator], states: NDArray[np.uint64]) -> None:
    """Write the advanced states back, so each generator continues where the kernel stopped."""
    for row, generator in enumerate(generators):
        full = dict(generator.bit_generator.state)
        words = [int(w) for w in states[row]]
        full["state"] = {"state": (words[0] << 64) | words[1], "inc": (words[2] << 64) | words[3]}
        generator.bit_generator.state = full


_READY = False


def warm_up() -> float:
    """Compile (or load from numba's disk cache) the section kernels; the seconds it took.

    The first compilation in a process is printed on stderr with its time.
    """
    global _READY  # noqa: PLW0603  (once per process)
    start = time.perf_counter()
    if _READY:
        return 0.0
    from robocal_uncertainty.kernels import section_numba

    _READY = True
    _compile_once()
    misses = 0
    for kernel in (section_numba.drawn_trials, section_numba.fused_trials, section_numba.fused_pcg64_trials):
        stats = getattr(kernel, "stats", None)  # cache statistics of the dispatcher
        misses += 0 if stats is None else int(sum(stats.cache_misses.values()))
    elapsed = time.perf_counter() - start
    if misses:
        print(f"numba: section kernels compiled in {elapsed:.1f} s (cached on disk for later runs)", file=sys.stderr)
    return elapsed


def _compile_once() -> None:
    """Run the kernels once on a tiny model with a real run's argument types."""
    from robocal_uncertainty.kernels import section_numba

    n = 3
    geometry = (np.zeros(9), np.zeros(n), np.zeros((n, 3)), np.zeros((3, n)), np.zeros((n, 2)))
    sources = (
        np.zeros(4, np.int64),
        np.zeros(4, np.int64),
        np.zeros(4),
        np.zeros(4),
        np.zeros((4, n, 2)),
        np.zeros((4, 1, 2)),
    )
    lengths = (np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros((1, 1, 2), np.int64), np.zeros((1, 2), np.int64))
    profile = (False, np.zeros(1, np.int64), np.ones(1, np.int64), np.zeros(1, np.int64))
    empty = np.zeros(0, np.int64)
    edges = (
        np.zeros(3, np.int64),
        empty,
        empty,
        np.zeros(1, np.int64),
        empty,
        np.zeros(1, np.int64),
        empty,
        np.zeros(0),
        empty,
        np.zeros(0),
        1.0,
        np.zeros((0, 2), np.int64),
        np.zeros(3, np.int64),
        empty,
        empty,
        np.zeros((0, 3), np.int64),
    )
    model = (geometry, sources, lengths, profile, edges)
    out = np.empty((1, 9))
    section_numba.drawn_trials(tuple(np.zeros((1, 0)) for _ in range(4)), model, out)
    if _generators_supported():
        rng = np.random.default_rng(0)
        section_numba.fused_trials((rng, rng, rng, rng), model, out)
        section_numba.fused_pcg64_trials(np.zeros((4, 4), dtype=np.uint64), model, out)
