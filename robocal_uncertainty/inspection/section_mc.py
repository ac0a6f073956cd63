"""Monte Carlo (JCGM 101) and GUM uncertainty of the section parameters under the CMM model.

Batched model
-------------
Every trial perturbs every measured point by the CMM sources (:mod:`~robocal_uncertainty.core.instruments.cmm`) and
re-evaluates the nine section parameters. Many trials are evaluated at once with the
registration correspondences and the side regions frozen at the unperturbed solution; how
each parameter is evaluated there (linearised registration, exact max/min over candidate
sets, edge windows grown per trial) is described in :mod:`.frozen_model`. With the edge regions
frozen, a perturbation that moves the extreme point to its neighbour (common on densely scanned
edges) was missed and the edge-profile u differed from the full algorithm's by 2-4 % on 1 836-point
scans of blades twisted 0.3°; the windows are therefore grown per trial.

Method ``denoised`` (:func:`section_uncertainty`) builds the same model at the denoised cloud
(:mod:`.denoise`) and states ``f(y) - Δ`` per trial instead of ``f(y + e')``.

:func:`full_section_trials` runs the full algorithm (registration, segmentation and all) per
trial on the same random draws, for checking the batched model.

Random streams
--------------
The block contract of :func:`~robocal_uncertainty.montecarlo.engine.run_trials` holds (results
bit-identical whatever ``chunk_blocks`` and ``workers``; the internal ``batch`` keeps the draws
and changes the values only by round-off). Inside block ``b``
source ``s`` (index in :data:`~robocal_uncertainty.core.instruments.cmm.SOURCE_NAMES`) draws from
``default_rng(SeedSequence(seed, spawn_key=(b, s)))``, the ``s``-th child of the block's
sequence, so switching a source off leaves the other sources' draws unchanged.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.instruments.cmm import (
    SOURCE_NAMES,
    CmmInstrument,
    ErrorSource,
    point_error_sources,
)
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.denoise import DenoisedCloud, ResidualCheck, denoise_section
from robocal_uncertainty.inspection.frozen_model import FrozenSectionModel, build_frozen_model
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud
from robocal_uncertainty.inspection.resolution import ResolutionEnvelope, resolution_envelope
from robocal_uncertainty.inspection.section import (
    PARAMETER_NAMES,
    SectionEvaluation,
    SectionOptions,
    SectionParameters,
    evaluate_section,
)
from robocal_uncertainty.kernels.registry import BackendInfo
from robocal_uncertainty.kernels.section_kernels import NumbaSectionKernel, resolve_section_backend
from robocal_uncertainty.montecarlo.distributions import Distribution, Normal, StudentT
from robocal_uncertainty.montecarlo.engine import (
    DEFAULT_BLOCK_SIZE,
    AdaptiveSettings,
    MonteCarloResult,
    ProgressCallback,
    TrialsResult,
    monte_carlo_result,
    run_trials,
)
from robocal_uncertainty.montecarlo.gum import GumResult, propagate_gum
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.montecarlo.validation import GumValidation, validate_gum

__all__ = [
    "DEPRECATED_METHODS",
    "METHODS",
    "SectionTrials",
    "SectionUncertainty",
    "TrialSetup",
    "canonical_method",
    "full_section_trials",
    "gum_source_budget",
    "prepare_trials",
    "section_sources",
    "section_uncertainty",
]

METHODS: tuple[str, ...] = ("perturbed", "denoised")
"""Monte Carlo methods of :func:`section_uncertainty`: ``perturbed`` perturbs the measured cloud
(the reference paper's method); ``denoised`` samples the error Δ around the denoised cloud
(:mod:`.denoise`) and states the distribution of ``f(y) - Δ``."""

DEPRECATED_METHODS: dict[str, str] = {"seed": "perturbed"}
"""Old method names still accepted (with a :class:`DeprecationWarning`): ``seed`` named the
reference paper's method, and read like the random seed."""


def canonical_method(method: str) -> str:
    """The method name of :data:`METHODS` for ``method``, a deprecated alias mapped with a warning.

    Raises
    ------
    ConfigError
        For a name that is neither a method nor a deprecated alias.
    """
    if method in DEPRECATED_METHODS:
        new = DEPRECATED_METHODS[method]
        warnings.warn(f"method {method!r} is deprecated: use {new!r}", DeprecationWarning, stacklevel=3)
        return new
    if method not in METHODS:
        msg = f"method must be one of {list(METHODS)}, got {method!r}"
        raise ConfigError(msg)
    return method


def section_sources(
    evaluation: SectionEvaluation,
    instrument: CmmInstrument,
    *,
    probe_vectors: ArrayLike | None = None,
    reference: ArrayLike | None = None,
) -> tuple[ErrorSource, ...]:
    """CMM sources for the ordered points of an evaluation.

    Parameters
    ----------
    evaluation : SectionEvaluation
        Unperturbed evaluation of the measured cloud.
    instrument : CmmInstrument
        Source magnitudes.
    probe_vectors : array_like, shape (n, 2) or (n, 3), optional
        Probe vectors in the *input* order of the cloud (reordered here); None: along normals.
    reference : array_like, shape (2,) [m], optional
        Reference point of the MPE/thermal lengths; default the leading-edge extreme point
        (so the trailing-edge point's L is the chord, as in the reference paper's GUM budget).

    Returns
    -------
    tuple of ErrorSource
        In :data:`~robocal_uncertainty.core.instruments.cmm.SOURCE_NAMES` order.
    """
    points = evaluation.points
    ref = points[evaluation.segmentation.leading_edge_point] if reference is None else reference
    probe = None if probe_vectors is None else np.asarray(probe_vectors, dtype=np.float64)[evaluation.order]
    return point_error_sources(instrument, points, evaluation.registration.normal, reference=ref, probe_vectors=probe)


@dataclass(frozen=True, eq=False)
class SectionTrials:
    """Trial block for :func:`~robocal_uncertainty.montecarlo.engine.run_trials`.

    Attributes
    ----------
    model : FrozenSectionModel
        Batched section model.
    sources : tuple of ErrorSource
        Enabled sources.
    source_indices : tuple of int
        Stream key of each source (its index in :data:`~robocal_uncertainty.core.instruments.cmm.SOURCE_NAMES`).
    batch : int
        Trials evaluated per vectorised step (memory knob): the same draws whatever its value,
        the model values equal up to round-off of the regrouped matrix products (~1e-21 m).
    reflect : ndarray, shape (9,) [m, rad], optional
        None: a trial's value is the model value ``f(x + e')`` (the reference paper's method). Given
        ``c = f(y) + f(x̂)``: ``c - f(x̂ + e') = f(y) - Δ`` with ``Δ = f(x̂ + e') - f(x̂)``, the
        value the measurand would have if the measured ``f(y)`` carried the error Δ (method
        ``denoised`` of :func:`section_uncertainty`, ``model`` built at the denoised cloud x̂).
    backend : str
        ``numpy`` (the frozen model's array operations, the reference) or ``numba`` (the
        compiled trial of :mod:`robocal_uncertainty.kernels.section_kernels`): the same draws,
        the values equal to rounding.
    """

    model: FrozenSectionModel
    sources: tuple[ErrorSource, ...]
    source_indices: tuple[int, ...]
    batch: int = 1000
    reflect: NDArray[np.float64] | None = None
    backend: str = "numpy"

    def __call__(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Parameters of ``n`` trials, shape (n, 9) [m, rad]."""
        generators = [source_generator(rng, k) for k in self.source_indices]
        if self.backend == "numpy":
            out = np.empty((n, len(PARAMETER_NAMES)))
            for start in range(0, n, self.batch):
                size = min(self.batch, n - start)
                draws = [s.draw(g, size) for s, g in zip(self.sources, generators)]
                out[start : start + size] = self.evaluate_draws(draws)
        else:
            out = self.kernel.trials(generators, n, self.batch)
        if self.reflect is not None:
            np.subtract(self.reflect, out, out=out)
        return out

    @cached_property
    def kernel(self) -> NumbaSectionKernel:
        """The compiled trial (backend ``numba``)."""
        if self.backend != "numba":
            msg = f"the section trial has no {self.backend!r} kernel"
            raise ConfigError(msg)
        return NumbaSectionKernel(self.model, self.sources)

    def evaluate_draws(self, draws: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
        """Parameters for given draws (one (T, n_draws) array per source), shape (T, 9)."""
        if self.backend != "numpy":
            return self.kernel.evaluate(draws)
        model = self.model
        trials = draws[0].shape[0]
        normal_shift = np.zeros((trials, model.points.shape[0]))
        subset_shift = np.zeros((trials, model.subset.shape[0], 2))
        for source, values in zip(self.sources, draws):
            normal_shift += source.normal_displacement(values, model.normals)
            subset_shift += source.displacement(values, model.subset)
        return model.evaluate(normal_shift, subset_shift)

    def model_of_columns(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Parameters for concatenated draw columns x (T, Σ n_draws), evaluated in row chunks."""
        sizes = np.cumsum([s.n_draws for s in self.sources])[:-1]
        out = np.empty((x.shape[0], len(PARAMETER_NAMES)))
        for start in range(0, x.shape[0], self.batch):
            part = x[start : start + self.batch]
            out[start : start + part.shape[0]] = self.evaluate_draws(np.split(part, sizes, axis=1))
        return out


@dataclass(frozen=True)
class _FullTrials:
    """Trial block running the full algorithm per trial on the same draws as SectionTrials."""

    points: NDArray[np.float64]
    curve: NominalCurve
    options: SectionOptions
    sources: tuple[ErrorSource, ...]
    source_indices: tuple[int, ...]

    def __call__(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        generators = [source_generator(rng, k) for k in self.source_indices]
        index = np.arange(self.points.shape[0])
        shift = np.zeros((n, index.shape[0], 2))
        for source, generator in zip(self.sources, generators):
            shift += source.displacement(source.draw(generator, n), index)
        return np.array(
            [evaluate_section(self.points + shift[t], self.curve, self.options).parameters.as_array() for t in range(n)]
        )


def _select_sources(names: Sequence[str]) -> tuple[int, ...]:
    chosen = tuple(dict.fromkeys(names))
    unknown = [name for name in chosen if name not in SOURCE_NAMES]
    if unknown or not chosen:
        msg = f"sources must be a non-empty subset of {list(SOURCE_NAMES)}, got {list(names)!r}"
        raise ConfigError(msg)
    return tuple(SOURCE_NAMES.index(name) for name in chosen)


@dataclass(frozen=True, eq=False)
class TrialSetup:
    """What a Monte Carlo of a measured section perturbs (:func:`prepare_trials`).

    Attributes
    ----------
    measured : SectionEvaluation
        Evaluation of the measured cloud y (its parameters are the estimates).
    centre : SectionEvaluation
        Evaluation of the cloud the trials perturb: y (``perturbed``) or the denoised x̂ (``denoised``).
    sources : tuple of ErrorSource
        Enabled sources at ``centre``'s points.
    source_indices : tuple of int
        Stream key of each source.
    reflect : ndarray, shape (9,) or None
        ``f(y) + f(x̂)`` for ``denoised`` (see :class:`SectionTrials`), None for ``perturbed``.
    denoised : DenoisedCloud or None
        The denoised cloud (``denoised`` only).
    options : SectionOptions
        Evaluation settings.
    check : ResidualCheck
        The residual check of the measured cloud (:func:`~.denoise.denoise_section`), either method.
    measured_sources : tuple of ErrorSource
        Enabled sources at ``measured``'s points (for :meth:`envelope`).
    """

    measured: SectionEvaluation
    centre: SectionEvaluation
    sources: tuple[ErrorSource, ...]
    source_indices: tuple[int, ...]
    reflect: NDArray[np.float64] | None
    denoised: DenoisedCloud | None
    options: SectionOptions
    check: ResidualCheck
    measured_sources: tuple[ErrorSource, ...] = ()

    def envelope(self, seed: int, coverage: float = 0.95) -> ResolutionEnvelope | None:
        """The max/min parameters' roughness envelope (:mod:`.resolution`) for method ``denoised``, else None."""
        if self.denoised is None:
            return None
        return resolution_envelope(
            self.measured,
            self.measured_sources,
            self.denoised.smooth_deviation,
            seed=seed,
            coverage=coverage,
            smooth_std=self.denoised.smooth_std,
        )

    def trials(self, batch: int = 1000, *, resegment_edges: bool = True, backend: str = "numpy") -> SectionTrials:
        """The batched trial block (model at ``centre``, see :func:`build_frozen_model`) on
        ``backend`` (a resolved name: ``numpy`` or ``numba``)."""
        model = build_frozen_model(self.centre, self.sources, self.options, resegment_edges=resegment_edges)
        return SectionTrials(model, self.sources, self.source_indices, batch, self.reflect, backend)


def prepare_trials(
    cloud: PointCloud | ArrayLike,
    curve: NominalCurve,
    *,
    instrument: CmmInstrument | None = None,
    sources: Sequence[str] = SOURCE_NAMES,
    options: SectionOptions | None = None,
    reference: ArrayLike | None = None,
    method: str = "perturbed",
    denoise_half_width: float | None = None,
    backend: str = "numpy",
) -> TrialSetup:
    """Evaluate the measured cloud and, for ``denoised``, denoise and evaluate it again.

    Parameters as for :func:`section_uncertainty`. The probe vectors of a PointCloud orient
    the probing error at both clouds. ``backend`` (a resolved name, ``numpy`` or ``numba``)
    runs the denoising's local fits (:func:`~.denoise.denoise_section`).

    Returns
    -------
    TrialSetup
    """
    options = SectionOptions() if options is None else options
    instrument = instrument or CmmInstrument()
    indices = _select_sources(sources)
    method = canonical_method(method)
    evaluation = evaluate_section(cloud, curve, options)
    probe = cloud.probe_vectors if isinstance(cloud, PointCloud) else None
    every = section_sources(evaluation, instrument, probe_vectors=probe, reference=reference)
    # The noise variance of every per-point source weights the window choice and the residual
    # check, whichever sources the Monte Carlo enables: it is the noise in the measured points.
    denoised = denoise_section(evaluation, every, curve.period, half_width=denoise_half_width, backend=backend)
    if method == "perturbed":
        enabled = tuple(every[k] for k in indices)
        return TrialSetup(evaluation, evaluation, enabled, indices, None, None, options, denoised.check, enabled)
    centre = evaluate_section(denoised.points, curve, options)
    ordered_probe = None if probe is None else np.asarray(probe, dtype=np.float64)[evaluation.order]
    at_centre = section_sources(centre, instrument, probe_vectors=ordered_probe, reference=reference)
    reflect = evaluation.parameters.as_array() + centre.parameters.as_array()
    return TrialSetup(
        evaluation,
        centre,
        tuple(at_centre[k] for k in indices),
        indices,
        reflect,
        denoised,
        options,
        denoised.check,
        tuple(every[k] for k in indices),
    )


def full_section_trials(
    cloud: PointCloud | ArrayLike,
    curve: NominalCurve,
    *,
    seed: int,
    trials: int,
    instrument: CmmInstrument | None = None,
    sources: Sequence[str] = SOURCE_NAMES,
    options: SectionOptions | None = None,
    reference: ArrayLike | None = None,
    block_size: int = DEFAULT_BLOCK_SIZE,
    method: str = "perturbed",
    denoise_half_width: float | None = None,
) -> NDArray[np.float64]:
    """Parameters of each trial by the full algorithm (re-registration, re-segmentation).

    Same random draws as :func:`section_uncertainty` with the same ``seed``, ``block_size``,
    ``sources`` and ``method``; slow (about 0.1 s per trial for 1 836 points): for checking the
    batched model. With ``method="denoised"`` the full algorithm runs on the perturbed denoised
    cloud and the values are ``f(y) - (f(x̂ + e') - f(x̂))`` as in :class:`SectionTrials`.

    Returns
    -------
    ndarray, shape (trials, 9) [m, rad]
    """
    opts = SectionOptions() if options is None else options
    prepared = prepare_trials(
        cloud,
        curve,
        instrument=instrument,
        sources=sources,
        options=opts,
        reference=reference,
        method=method,
        denoise_half_width=denoise_half_width,
    )
    block = _FullTrials(prepared.centre.points, curve, opts, prepared.sources, prepared.source_indices)
    values = np.array(run_trials(block, seed=seed, n_trials=trials, block_size=block_size).samples)
    return values if prepared.reflect is None else prepared.reflect - values


def gum_source_budget(trials: SectionTrials) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-source GUM standard contributions from finite-difference sensitivities.

    Every draw column is perturbed by ±1 % of its standard uncertainty (central differences
    of the batched model at zero error); the squared contributions of a source's columns are
    summed: ``u_jk² = Σ_i∈k (∂y_j/∂x_i · u(x_i))²``.

    Returns
    -------
    budget : ndarray, shape (9, n_sources) [m, rad]
        Standard contribution of each source to each parameter.
    covariance : ndarray, shape (9, 9)
        First-order output covariance Σ_i c_i c_iᵀ u(x_i)² [products of m, rad].
    """
    widths = [s.n_draws for s in trials.sources]
    u = np.concatenate([np.full(w, s.draw_uncertainty) for s, w in zip(trials.sources, widths)])
    total = u.shape[0]
    step = np.where(u > 0, 0.01 * u, 1.0)
    budget = np.zeros((len(PARAMETER_NAMES), len(trials.sources)))
    covariance = np.zeros((len(PARAMETER_NAMES), len(PARAMETER_NAMES)))
    owner = np.repeat(np.arange(len(widths)), widths)
    chunk = 500
    for start in range(0, total, chunk):
        cols = np.arange(start, min(start + chunk, total))
        x = np.zeros((2 * cols.size, total))
        x[np.arange(cols.size), cols] = step[cols]
        x[cols.size + np.arange(cols.size), cols] = -step[cols]
        y = trials.model_of_columns(x)
        scaled = (y[: cols.size] - y[cols.size :]) / (2.0 * step[cols])[:, np.newaxis] * u[cols][:, np.newaxis]
        np.add.at(budget.T, owner[cols], scaled**2)
        covariance += scaled.T @ scaled
    return np.sqrt(budget), covariance


@dataclass(frozen=True, eq=False)
class SectionUncertainty:
    """Monte Carlo and GUM uncertainty of the section parameters.

    Attributes
    ----------
    parameters : SectionParameters
        Parameters of the measured cloud itself (the GUM estimate).
    monte_carlo : MonteCarloResult
        JCGM 101 summary per parameter (outputs in :data:`~.section.PARAMETER_NAMES` order);
        ``input_names`` are the enabled sources.
    gum : GumResult
        First-order GUM: inputs are the sources' standardised contributions, so its
        ``sensitivities`` (9, n_sources) are the per-source standard contributions [m, rad].
    gum_covariance : ndarray, shape (9, 9)
        First-order output covariance over all point-wise inputs [products of m, rad].
    validation : tuple of GumValidation
        JCGM 101 §8 comparison per parameter (instrument model only, as simulated).
    gum_with_repeatability : GumResult or None
        GUM budget with the repeatability of repeated scans added as a Type A input per
        parameter (the reference paper's u3; Student t with k - 1 degrees of freedom, Welch-Satterthwaite);
        None when no repeated scans were given. Its ``sensitivities`` (9, n_sources + 9) hold
        the instrument sources' contributions, then the repeatability standard deviations.
    sources : tuple of str
        Enabled sources.
    instrument : CmmInstrument
        Source magnitudes.
    reference : ndarray, shape (2,) [m]
        Reference point of the MPE/thermal lengths.
    candidate_counts : tuple of int
        Thickness candidate points, suction segments per candidate, chord pairs.
    method : str
        ``perturbed``: ``monte_carlo`` describes ``f(y + e')``, the measured cloud y perturbed (the
        reference paper's method; its mean exceeds the measured value by the noise bias of the max/min
        parameters). ``denoised``: ``monte_carlo`` describes ``f(y) - Δ``,
        ``Δ = f(x̂ + e') - f(x̂)`` the error sampled around the denoised cloud x̂: its mean is the
        bias-corrected estimate, its intervals are the intervals for the measurand.
    reference_parameters : ndarray, shape (9,) [m, rad]
        Parameters of the cloud the trials perturb (y for ``perturbed``, x̂ for ``denoised``).
    denoised : DenoisedCloud or None
        The denoised cloud and its window choice (``denoised`` only).
    check : ResidualCheck or None
        The measured cloud's residual check (:class:`~.denoise.ResidualCheck`, either method): when
        it flags the cloud, the intervals are not verified for it.
    envelope : ResolutionEnvelope or None
        Method ``denoised``: the max/min parameters' error quantiles at the smoothest and the
        roughest form the scan supports (:mod:`.resolution`); their stated intervals
        (:func:`~.bias_correction.bias_corrections`) are widened to them. None for ``perturbed``.
    n_points : int
        Points of the measured cloud (0 when not recorded).
    nominal_length : float
        Contour length of the nominal section [m] (nan when not recorded).
    backend : BackendInfo or None
        The backend that ran the trials and its version (None when not recorded).
    """

    parameters: SectionParameters
    monte_carlo: MonteCarloResult
    gum: GumResult
    gum_covariance: NDArray[np.float64]
    validation: tuple[GumValidation, ...]
    sources: tuple[str, ...]
    instrument: CmmInstrument
    reference: NDArray[np.float64]
    candidate_counts: tuple[int, int, int]
    gum_with_repeatability: GumResult | None = None
    method: str = "perturbed"
    reference_parameters: NDArray[np.float64] | None = None
    denoised: DenoisedCloud | None = None
    check: ResidualCheck | None = None
    envelope: ResolutionEnvelope | None = None
    n_points: int = 0
    nominal_length: float = float("nan")
    backend: BackendInfo | None = None


def section_uncertainty(
    cloud: PointCloud | ArrayLike,
    curve: NominalCurve,
    *,
    seed: int,
    trials: int | None = 1_000_000,
    adaptive: AdaptiveSettings | None = None,
    instrument: CmmInstrument | None = None,
    sources: Sequence[str] = SOURCE_NAMES,
    options: SectionOptions | None = None,
    reference: ArrayLike | None = None,
    coverage: float = 0.95,
    block_size: int = DEFAULT_BLOCK_SIZE,
    batch: int = 1000,
    chunk_blocks: int = 1,
    workers: int = 1,
    progress: ProgressCallback | None = None,
    keep_samples: bool = False,
    bins: int | str = 100,
    repeat_parameters: ArrayLike | None = None,
    method: str = "perturbed",
    denoise_half_width: float | None = None,
    backend: str = "numpy",
    executor: object | None = None,
) -> SectionUncertainty:
    """Monte Carlo of the nine section parameters under the CMM model, with the GUM comparison.

    Parameters
    ----------
    cloud, curve
        Measured section (PointCloud or (n, 2) array [m]; its probe vectors, if any, orient the
        probing error) and the nominal section (NominalCurve).
    seed, trials, adaptive
        Root seed (>= 0); fixed number of trials (default 10^6), or None with JCGM 101 §7.9
        ``adaptive`` settings.
    instrument, sources
        Source magnitudes (default the reference paper's CMM); enabled sources, a subset of
        :data:`~robocal_uncertainty.core.instruments.cmm.SOURCE_NAMES`.
    options, reference
        Evaluation settings; reference point (2,) [m] of the MPE/thermal lengths (default the
        leading-edge extreme point).
    coverage, keep_samples, bins
        Coverage probability p; keep the (trials, 9) model values; histogram bins.
    block_size, chunk_blocks, workers, progress, executor
        As for :func:`~robocal_uncertainty.montecarlo.engine.run_trials` (``executor``: where
        the blocks run instead of ``workers`` processes of their own; never changes the result).
    batch : int
        Trials per vectorised step inside a block (memory ~ 60 kB × n_points × batch / 1836).
    repeat_parameters : array_like, shape (k, 9) [m, rad], optional
        Parameters of k >= 2 repeated scans of the same section; their standard deviations
        enter ``gum_with_repeatability`` (the reference paper's u3).
    method : str
        One of :data:`METHODS` (see :attr:`SectionUncertainty.method`): ``perturbed`` perturbs the
        measured cloud (the reference paper's method; its max/min intervals under-cover),
        ``denoised`` states ``f(y) - Δ``, Δ sampled around the denoised cloud (:mod:`.denoise`).
        ``seed`` is a deprecated alias of ``perturbed``.
    denoise_half_width : float, optional
        Smoothing window half-width of ``denoised`` [m]; None: chosen by Mallows' Cp.
    backend : str
        Trial kernels: ``numpy`` (the reference), ``numba`` (compiled, extra ``fast``) or ``auto``
        (numba where installed); the same draws, the results equal to 1e-12 relative
        (:mod:`robocal_uncertainty.kernels.section_kernels`). Recorded in the result.

    Returns
    -------
    SectionUncertainty
    """
    _check_batch(batch)
    kernels = resolve_section_backend(backend)
    repeats = None if repeat_parameters is None else _check_repeats(repeat_parameters)
    inst = instrument or CmmInstrument()
    setup: dict[str, Any] = {"options": options, "reference": reference, "denoise_half_width": denoise_half_width}
    setup["backend"] = kernels.name
    prepared = prepare_trials(cloud, curve, instrument=inst, sources=sources, method=canonical_method(method), **setup)
    block = prepared.trials(batch, backend=kernels.name)
    engine: dict[str, Any] = {
        "block_size": block_size,
        "chunk_blocks": chunk_blocks,
        "workers": 1 if executor is not None else workers,
        "progress": progress,
        "executor": executor,
    }
    run = run_trials(block, seed=seed, n_trials=trials, adaptive=adaptive, **engine)
    p = coverage if adaptive is None else adaptive.coverage
    result = _section_result(
        prepared, block, run, p, inst, reference, curve, bins=bins, keep_samples=keep_samples, repeats=repeats
    )
    return replace(result, backend=kernels)


def _section_result(
    prepared: TrialSetup,
    block: SectionTrials,
    run: TrialsResult,
    p: float,
    instrument: CmmInstrument,
    reference: ArrayLike | None,
    curve: NominalCurve,
    *,
    bins: int | str,
    keep_samples: bool,
    repeats: NDArray[np.float64] | None,
) -> SectionUncertainty:
    """The statements of a finished Monte Carlo run (:func:`section_uncertainty`)."""
    evaluation = prepared.measured
    model = block.model
    names = tuple(SOURCE_NAMES[k] for k in prepared.source_indices)
    mc = _monte_carlo_result(run, p, bins, names, keep_samples=keep_samples)
    gum, covariance, validation, with_repeats = _gum_statements(
        block, evaluation.parameters.as_array(), names, p, mc, repeats
    )
    reference_point = (
        prepared.centre.points[prepared.centre.segmentation.leading_edge_point]
        if reference is None
        else np.asarray(reference, dtype=np.float64)
    )
    return SectionUncertainty(
        parameters=evaluation.parameters,
        monte_carlo=mc,
        gum=gum,
        gum_covariance=covariance,
        validation=validation,
        sources=names,
        instrument=instrument,
        reference=reference_point,
        candidate_counts=(
            int(model.thickness_points.size),
            int(model.thickness_segments.shape[1]),
            int(model.chord_pairs.shape[0]),
        ),
        gum_with_repeatability=with_repeats,
        method="denoised" if prepared.denoised is not None else "perturbed",
        reference_parameters=model.base.copy(),
        denoised=prepared.denoised,
        check=prepared.check,
        envelope=prepared.envelope(run.seed, p),
        n_points=int(evaluation.points.shape[0]),
        nominal_length=float(curve.period),
    )


def _monte_carlo_result(
    run: TrialsResult, p: float, bins: int | str, names: tuple[str, ...], *, keep_samples: bool
) -> MonteCarloResult:
    """The JCGM 101 summary of a finished run (``run_trials``' result) at coverage ``p``."""
    return monte_carlo_result(run, p, names=names, columns=names, bins=bins, keep_samples=keep_samples)


def _gum_statements(
    block: SectionTrials,
    base: NDArray[np.float64],
    names: tuple[str, ...],
    p: float,
    mc: MonteCarloResult,
    repeats: NDArray[np.float64] | None,
) -> tuple[GumResult, NDArray[np.float64], tuple[GumValidation, ...], GumResult | None]:
    """The GUM budget, its covariance, the JCGM 101 §8 validation and the budget with repeatability."""
    budget, covariance = gum_source_budget(block)

    def combined(z: NDArray[np.float64]) -> NDArray[np.float64]:
        return base + z @ budget.T

    gum = propagate_gum(combined, {name: Normal(0.0, 1.0) for name in names}, coverage=p)
    validation = tuple(validate_gum(gum, mc, output=j) for j in range(len(PARAMETER_NAMES)))
    if repeats is None:
        return gum, covariance, validation, None
    spread = repeats.std(axis=0, ddof=1)
    dof = repeats.shape[0] - 1
    full_budget = np.concatenate([budget, np.diag(spread)], axis=1)

    def with_repeatability(z: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(base + z @ full_budget.T, dtype=np.float64)

    inputs: dict[str, Distribution] = {name: Normal(0.0, 1.0) for name in names}
    inputs.update({f"repeatability[{name}]": StudentT(0.0, 1.0, dof) for name in PARAMETER_NAMES})
    return gum, covariance, validation, propagate_gum(with_repeatability, inputs, coverage=p)


def _check_batch(batch: int) -> None:
    if isinstance(batch, bool) or not isinstance(batch, int) or batch < 1:
        msg = f"batch must be an integer >= 1, got {batch!r}"
        raise ConfigError(msg)


def _check_repeats(values: ArrayLike) -> NDArray[np.float64]:
    repeats = np.asarray(values, dtype=np.float64)
    if repeats.ndim != 2 or repeats.shape[1] != len(PARAMETER_NAMES) or repeats.shape[0] < 2:
        msg = f"repeat_parameters must have shape (k, {len(PARAMETER_NAMES)}) with k >= 2, got {repeats.shape}"
        raise ConfigError(msg)
    if not np.isfinite(repeats).all():
        msg = "repeat_parameters must be finite, got NaN/inf"
        raise ConfigError(msg)
    return repeats
