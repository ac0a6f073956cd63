"""Batched Monte Carlo of the section parameters: agreement with the full algorithm,
reproducibility, independent source streams, GUM budget."""

from __future__ import annotations

import functools
import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from inspection_data import ROTOR37, ROTOR37_SCALE
from numpy.typing import NDArray

from robocal_uncertainty.core.instruments.cmm import SOURCE_NAMES, CmmInstrument, ErrorSource, point_displacements
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.bias_correction import bias_corrections
from robocal_uncertainty.inspection.coverage_study import FAMILIES, run_study
from robocal_uncertainty.inspection.frozen_model import build_frozen_model
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud, read_rotor37_section
from robocal_uncertainty.inspection.section import PARAMETER_NAMES, evaluate_section
from robocal_uncertainty.inspection.section_mc import (
    SectionTrials,
    full_section_trials,
    gum_source_budget,
    prepare_trials,
    section_sources,
    section_uncertainty,
)
from robocal_uncertainty.inspection.simulate import simulate_section_scan
from robocal_uncertainty.inspection.stored_studies import COVERAGE_STUDY
from robocal_uncertainty.kernels.section_kernels import resolve_section_backend
from robocal_uncertainty.montecarlo.engine import AdaptiveSettings, block_rng, run_trials
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.montecarlo.summary import summarize

TRUE_OFFSET = (-0.1013e-3, 0.0538e-3)  # the seed's measured offsets [m]
TRUE_TWIST = np.deg2rad(0.0512)  # the seed's measured twist [rad]


@pytest.fixture(scope="module")
def small_scan(rotor37_curve: NominalCurve) -> PointCloud:
    """A 400-point scan of the seed-sized Rotor 37 section with a 5 µm form error."""
    return simulate_section_scan(rotor37_curve, 400, offset=TRUE_OFFSET, twist=TRUE_TWIST, form_amplitude=5e-6)


def trials_of(
    cloud: PointCloud,
    curve: NominalCurve,
    names: tuple[str, ...] = SOURCE_NAMES,
    batch: int = 1000,
    *,
    resegment_edges: bool = True,
) -> SectionTrials:
    evaluation = evaluate_section(cloud, curve)
    every = section_sources(evaluation, CmmInstrument(), probe_vectors=cloud.probe_vectors)
    indices = tuple(SOURCE_NAMES.index(n) for n in names)
    chosen = tuple(every[k] for k in indices)
    model = build_frozen_model(evaluation, chosen, resegment_edges=resegment_edges)
    return SectionTrials(model, chosen, indices, batch)


def test_batched_model_agrees_with_the_full_algorithm(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    n = 40
    full = full_section_trials(small_scan, rotor37_curve, seed=11, trials=n, block_size=16)
    batched = np.array(run_trials(trials_of(small_scan, rotor37_curve), seed=11, n_trials=n, block_size=16).samples)
    assert full.shape == batched.shape == (n, 9)
    # Thickness and chord: the candidate sets make the batched max/min exact.
    assert batched[:, :2] == pytest.approx(full[:, :2], abs=1e-15)
    # Offsets and twist: linearised registration, errors of second order in microns.
    assert batched[:, 2:4] == pytest.approx(full[:, 2:4], abs=2e-9)
    assert batched[:, 4] == pytest.approx(full[:, 4], abs=1e-8)
    # Profiles: linearised residuals; the edge regions grow per trial as in the full algorithm
    # (a junction point moves between an edge and a side in some trials).
    assert batched[:, 5:] == pytest.approx(full[:, 5:], abs=5e-9)


def test_edge_regions_grow_per_trial_as_in_the_full_algorithm(rotor37_curve: NominalCurve) -> None:
    # 1 836 points, 0.3° twist: the trailing-edge extreme point flips to its neighbour in some
    # trials and the edge window (symmetric about it) then ends one point earlier on one side.
    cloud = simulate_section_scan(rotor37_curve, 1836, offset=TRUE_OFFSET, twist=np.deg2rad(0.3), form_amplitude=5e-6)
    setup = prepare_trials(cloud, rotor37_curve)
    full = full_section_trials(cloud, rotor37_curve, seed=11, trials=40, block_size=20)
    grown = run_trials(setup.trials(), seed=11, n_trials=40, block_size=20).samples
    frozen = run_trials(setup.trials(resegment_edges=False), seed=11, n_trials=40, block_size=20).samples
    assert setup.trials().model.edges is not None and setup.trials(resegment_edges=False).model.edges is None
    assert grown[:, 5:] == pytest.approx(full[:, 5:], abs=5e-9)
    # The frozen segmentation misses the move by more than a micrometre in some trials.
    assert np.abs(frozen[:, 6] - full[:, 6]).max() > 1e-6


def test_results_do_not_depend_on_chunking_batching_or_workers(
    small_scan: PointCloud, rotor37_curve: NominalCurve
) -> None:
    reference = run_trials(trials_of(small_scan, rotor37_curve), seed=5, n_trials=90, block_size=40).samples
    # The internal batch only regroups BLAS products: same draws, round-off apart.
    chunked = run_trials(trials_of(small_scan, rotor37_curve, batch=7), seed=5, n_trials=90, block_size=40)
    assert chunked.samples == pytest.approx(reference, abs=1e-18, rel=1e-12)
    parallel = run_trials(
        trials_of(small_scan, rotor37_curve), seed=5, n_trials=90, block_size=40, chunk_blocks=2, workers=2
    )
    assert np.array_equal(parallel.samples, reference)
    other = run_trials(trials_of(small_scan, rotor37_curve), seed=6, n_trials=90, block_size=40).samples
    assert not np.array_equal(other, reference)


def test_switching_a_source_off_leaves_the_others_draws(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    both = run_trials(trials_of(small_scan, rotor37_curve, ("mpe", "probing")), seed=2, n_trials=50, block_size=20)
    mpe = run_trials(trials_of(small_scan, rotor37_curve, ("mpe",)), seed=2, n_trials=50, block_size=20)
    probing = run_trials(trials_of(small_scan, rotor37_curve, ("probing",)), seed=2, n_trials=50, block_size=20)
    base = evaluate_section(small_scan, rotor37_curve).parameters.as_array()
    # Offsets and twist are linear in the displacements: the two sources' effects add up
    # exactly only if each source drew the same numbers with and without the other.
    combined = mpe.samples[:, 2:5] + probing.samples[:, 2:5] - base[2:5]
    assert both.samples[:, 2:5] == pytest.approx(combined, abs=1e-15)
    first = source_generator(block_rng(2, 0), 2).random(3)
    again = source_generator(block_rng(2, 0), 2).random(3)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, source_generator(block_rng(2, 0), 0).random(3))


def test_gum_budget_of_the_chord(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    trials = trials_of(small_scan, rotor37_curve)
    budget, covariance = gum_source_budget(trials)
    assert budget.shape == (9, 4) and covariance.shape == (9, 9)
    assert np.sqrt(np.diag(covariance)) == pytest.approx(np.sqrt((budget**2).sum(axis=1)), rel=1e-9)
    chord = float(trials.model.base[1])
    # Thermal scale error: u = chord · Δt · 2e-6/√3, the seed's 1.15e-3·L·Δt µm (L in mm).
    assert budget[1, 1] == pytest.approx(chord * 0.3 * 2e-6 / np.sqrt(3), rel=1e-3)
    # MPE: the chord ends' x errors along the chord, E = 1.2 µm at the leading edge (L = 0)
    # and 1.2 + chord/350 µm at the trailing edge; u = sqrt(E_le² + E_te²)/√3.
    e_le, e_te = 1.2e-6, (1.2 + chord * 1e3 / 350) * 1e-6
    assert budget[1, 0] == pytest.approx(np.hypot(e_le, e_te) / np.sqrt(3), rel=0.02)


def test_section_uncertainty_end_to_end(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    result = section_uncertainty(small_scan, rotor37_curve, seed=1, trials=4000, block_size=1000, keep_samples=True)
    mc = result.monte_carlo
    assert len(mc.outputs) == len(result.validation) == len(result.gum.outputs) == 9
    assert mc.samples is not None and mc.samples.shape == (4000, 9)
    assert mc.input_names == SOURCE_NAMES and result.sources == SOURCE_NAMES
    assert result.gum.sensitivities.shape == (9, 4)
    # Offsets and twist are linear in the errors: GUM and Monte Carlo agree.
    for j in (2, 3, 4):
        assert mc.outputs[j].standard_uncertainty == pytest.approx(result.gum.outputs[j].standard_uncertainty, rel=0.05)
        assert mc.outputs[j].estimate == pytest.approx(result.parameters.as_array()[j], abs=0.1e-6)
    # The offsets recover the truth within a few standard uncertainties.
    assert result.parameters.axial_offset == pytest.approx(TRUE_OFFSET[0], abs=5 * mc.outputs[2].standard_uncertainty)
    assert result.reference.shape == (2,)
    assert result.candidate_counts[0] >= 1
    probing_only = section_uncertainty(
        small_scan, rotor37_curve, seed=1, trials=200, block_size=100, sources=("probing",)
    )
    assert probing_only.sources == ("probing",)
    assert probing_only.gum.sensitivities.shape == (9, 1)
    # The probing error is the largest source: alone it gives most of the thickness uncertainty.
    assert (
        0.3 * mc.outputs[0].standard_uncertainty
        < probing_only.monte_carlo.outputs[0].standard_uncertainty
        < mc.outputs[0].standard_uncertainty
    )


def test_bias_corrected_profiles_of_a_perfect_section_are_not_negative(rotor37_curve: NominalCurve) -> None:
    # No form error: measured profiles ~0, Monte Carlo profiles ~5-8 µm; the reflected
    # interval [2y - high, 2y - low] would be all negative and exclude the true 0.
    cloud = simulate_section_scan(rotor37_curve, 400, offset=TRUE_OFFSET, twist=TRUE_TWIST)
    result = section_uncertainty(cloud, rotor37_curve, seed=1, trials=400, block_size=200)
    fixes = bias_corrections(result)
    for fix in fixes[5:]:
        assert fix.measured < 1e-9 < fix.bias
        assert fix.estimate == 0.0 and fix.interval.low == 0.0
        assert fix.interval.contains(0.0)
    for fix in fixes[2:5]:  # linear parameters: the plain reflection, may be negative
        mc = result.monte_carlo.outputs[PARAMETER_NAMES.index(fix.name)].probabilistically_symmetric
        assert fix.interval.low == pytest.approx(2 * fix.measured - mc.high, abs=1e-18)


def test_denoised_method_states_the_error_sampled_around_the_denoised_cloud(
    small_scan: PointCloud, rotor37_curve: NominalCurve
) -> None:
    setup = prepare_trials(small_scan, rotor37_curve, method="denoised")
    assert setup.denoised is not None and setup.reflect is not None
    measured = setup.measured.parameters.as_array()
    centre = setup.centre.parameters.as_array()
    assert setup.reflect == pytest.approx(measured + centre, rel=1e-15)
    block = setup.trials()
    values = run_trials(block, seed=8, n_trials=60, block_size=20).samples
    plain = SectionTrials(block.model, block.sources, block.source_indices)
    perturbed = run_trials(plain, seed=8, n_trials=60, block_size=20).samples
    # f(y) - Δ with Δ = f(x̂ + e') - f(x̂), on the same draws.
    assert np.array_equal(values, setup.reflect - perturbed)
    parallel = run_trials(block, seed=8, n_trials=60, block_size=20, chunk_blocks=2, workers=2).samples
    assert np.array_equal(parallel, values)
    # The full algorithm on the perturbed denoised cloud, same draws: thickness and chord exact,
    # offsets and twist to second order.
    full = full_section_trials(small_scan, rotor37_curve, seed=8, trials=20, block_size=20, method="denoised")
    assert full[:, :2] == pytest.approx(values[:20, :2], abs=1e-15)
    assert full[:, 2:4] == pytest.approx(values[:20, 2:4], abs=2e-9)

    result = section_uncertainty(small_scan, rotor37_curve, seed=1, trials=4000, block_size=1000, method="denoised")
    seed = section_uncertainty(small_scan, rotor37_curve, seed=1, trials=4000, block_size=1000)
    assert result.method == "denoised" and seed.method == "perturbed" and seed.denoised is None
    assert np.array_equal(result.parameters.as_array(), measured)  # the estimate stays f(y)
    assert result.reference_parameters == pytest.approx(centre, rel=1e-15)
    fixes = bias_corrections(result)
    for j, (fix, out) in enumerate(zip(fixes, result.monte_carlo.outputs)):
        assert fix.bias == pytest.approx(measured[j] - out.estimate, rel=1e-12, abs=1e-20)
        if fix.recommended:
            # The max/min parameters: the Monte Carlo interval widened to the roughness envelope.
            assert result.envelope is not None
            low, high = result.envelope.widen(
                fix.name, out.probabilistically_symmetric.low, out.probabilistically_symmetric.high
            )
            assert low <= out.probabilistically_symmetric.low and high >= out.probabilistically_symmetric.high
            assert fix.interval.low == max(low, 0.0)
            assert fix.interval.high == max(high, 0.0)
    # The noise pushes the thickness and the profiles up (the chord of 400 points hardly: its
    # farthest pair has no near rival).
    assert all(fixes[j].bias > 0.3e-6 for j in (0, 5, 6, 7, 8)), [f.bias for f in fixes]
    # Offsets and twist are linear in the errors: both methods give the same u and no bias.
    for j in (2, 3, 4):
        u = result.monte_carlo.outputs[j].standard_uncertainty
        assert u == pytest.approx(seed.monte_carlo.outputs[j].standard_uncertainty, rel=0.03)
        assert abs(fixes[j].bias) < 0.1 * u
    # The seed's method counts the noise bias twice: its mean is above f(y) by about the bias
    # the denoised method takes off f(y).
    for j in (0, 5, 7, 8):
        above = seed.monte_carlo.outputs[j].estimate - measured[j]
        assert above == pytest.approx(fixes[j].bias, rel=0.35), PARAMETER_NAMES[j]
    with pytest.raises(ConfigError, match="method must be one of"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=10, method="reflected")


def test_configuration_errors(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    with pytest.raises(ConfigError, match="sources must be a non-empty subset"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=10, sources=("wind",))
    with pytest.raises(ConfigError, match="sources must be a non-empty subset"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=10, sources=())
    with pytest.raises(ConfigError, match="batch must be an integer"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=10, batch=0)
    with pytest.raises(ConfigError, match="n_trials must be an integer"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=0)


def test_parameter_names_match_the_model_columns() -> None:
    assert PARAMETER_NAMES[:5] == (
        "max_thickness",
        "chord_length",
        "axial_offset",
        "circumferential_offset",
        "twist_angle",
    )


@pytest.mark.slow
def test_batched_equals_full_algorithm_on_1000_trials(rotor37_curve: NominalCurve) -> None:
    """Issue 9: batched vs full per trial on 1 000 trials (same draws), within 2 % in u.

    The same draws feed both, so u differs by what the batching approximates, not by sampling:
    1 000 trials (50 s of the full algorithm) tell as much as the 2 000 this test ran before."""
    cloud = simulate_section_scan(rotor37_curve, 1836, offset=TRUE_OFFSET, twist=TRUE_TWIST, form_amplitude=5e-6)
    full = full_section_trials(cloud, rotor37_curve, seed=3, trials=1000)
    result = section_uncertainty(cloud, rotor37_curve, seed=3, trials=1000, keep_samples=True)
    batched = result.monte_carlo.samples
    assert batched is not None
    u_full = full.std(axis=0, ddof=1)
    u_batched = batched.std(axis=0, ddof=1)
    assert u_batched == pytest.approx(u_full, rel=0.02)
    assert batched[:, :2] == pytest.approx(full[:, :2], abs=1e-15)


def test_repeatability_enters_the_gum_budget(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    base = evaluate_section(small_scan, rotor37_curve).parameters.as_array()
    # Five repeated scans whose chord scatters by s = 2.087 µm (the seed's u3).
    offsets = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    repeats = np.tile(base, (5, 1))
    repeats[:, 1] += offsets / offsets.std(ddof=1) * 2.087e-6
    result = section_uncertainty(
        small_scan, rotor37_curve, seed=1, trials=200, block_size=100, repeat_parameters=repeats
    )
    gum = result.gum_with_repeatability
    assert gum is not None
    assert gum.sensitivities.shape == (9, 13)
    u_instrument = result.gum.outputs[1].standard_uncertainty
    assert gum.outputs[1].standard_uncertainty == pytest.approx(np.hypot(u_instrument, 2.087e-6), rel=1e-9)
    assert np.isfinite(gum.outputs[1].effective_dof) and gum.outputs[1].coverage_factor > 1.96
    assert gum.outputs[0].standard_uncertainty == pytest.approx(result.gum.outputs[0].standard_uncertainty)
    with pytest.raises(ConfigError, match=r"repeat_parameters must have shape \(k, 9\) with k >= 2"):
        section_uncertainty(small_scan, rotor37_curve, seed=1, trials=10, repeat_parameters=repeats[:1])


def test_adaptive_trial_count(small_scan: PointCloud, rotor37_curve: NominalCurve) -> None:
    settings = AdaptiveSettings(tolerance=0.05e-6, sequence_trials=2000, max_trials=40_000, monitored=(2, 3))
    result = section_uncertainty(small_scan, rotor37_curve, seed=4, trials=None, adaptive=settings, block_size=1000)
    report = result.monte_carlo.adaptive
    assert report is not None and report.converged
    assert result.monte_carlo.n_trials % 2000 == 0


@functools.cache
def _coverage_scenario() -> tuple[NominalCurve, NDArray[np.float64], NDArray[np.float64], tuple[ErrorSource, ...]]:
    """Nominal, true points and parameters, and instrument sources of the coverage study."""
    curve = NominalCurve(read_rotor37_section(ROTOR37, 2, scale=ROTOR37_SCALE))
    true_cloud = simulate_section_scan(curve, 1836, offset=TRUE_OFFSET, twist=TRUE_TWIST, form_amplitude=5e-6)
    clean = evaluate_section(true_cloud, curve)
    sources = section_sources(clean, CmmInstrument(), probe_vectors=true_cloud.probe_vectors)
    return curve, clean.points, clean.parameters.as_array(), sources


def _coverage_of_scan(k: int) -> NDArray[np.bool_]:
    """Whether scan k's 95 % intervals contain the truth, shape (3, 9): the seed's JCGM 101
    interval, it reflected about the measured value, and method ``denoised``."""
    curve, points, truth, true_sources = _coverage_scenario()
    rng = np.random.default_rng(np.random.SeedSequence(77, spawn_key=(k,)))
    noisy = points + point_displacements(true_sources, rng)[0]
    # The backend a user's `section` gets (auto: numba where installed, equal to numpy to 1e-12 and
    # with the same draws, test_section_backend.py): it halves the study's time.
    backend = resolve_section_backend("auto").name
    setup = prepare_trials(noisy, curve, method="denoised", backend=backend)
    y = setup.measured.parameters.as_array()
    sources = section_sources(setup.measured, CmmInstrument())
    block = SectionTrials(build_frozen_model(setup.measured, sources), sources, (0, 1, 2, 3), backend=backend)
    summary = summarize(run_trials(block, seed=k, n_trials=2000, block_size=2000).samples, 0.95, bins=10)
    intervals = [out.probabilistically_symmetric for out in summary.outputs]
    trials = setup.trials(backend=backend)
    denoised = summarize(run_trials(trials, seed=k, n_trials=2000, block_size=2000).samples, 0.95, bins=10)
    envelope = setup.envelope(k)
    assert envelope is not None
    stated = [
        envelope.widen(name, out.probabilistically_symmetric.low, out.probabilistically_symmetric.high)
        for name, out in zip(PARAMETER_NAMES, denoised.outputs)
    ]
    return np.array(
        [
            [iv.contains(t) for iv, t in zip(intervals, truth)],
            [2 * y[j] - iv.high <= truth[j] <= 2 * y[j] - iv.low for j, iv in enumerate(intervals)],
            [low <= t <= high for (low, high), t in zip(stated, truth)],
        ]
    )


@pytest.mark.slow
def test_coverage_over_200_simulated_scans() -> None:
    """Issue 9: over 200 simulated scans the 95 % intervals contain the true parameter 95 ± 3 %.

    Each scan is the true section (5 µm three-wave form error, the seed's offsets and twist)
    plus one draw of the instrument errors; the Monte Carlo (2 000 trials) runs on the noisy
    scan only, as on a real part. Measured coverage (thickness, chord, axial, circumferential,
    twist, profiles LE/TE/PS/SS):

    - method ``denoised`` (the error sampled around the denoised cloud, widest window by Cp,
      narrowed per point, twicing; the max/min parameters widened to the roughness envelope of
      ``inspection.resolution``, its profile extremes flattened within one fit sd): 96, 94, 93.5,
      94.5, 93.5, 96.5, 97.5, 97.5, 96 % (97 and 97 % for TE and PS unflattened): every
      parameter within 92-98 % (the offsets, linear in the errors and exact in either method,
      cover 93.5-94.5 % on the same scans: the binomial standard error is 1.5 %); thickness and
      chord without the envelope covered 94.5 and 93.5 %, the profiles 92.5, 93.5, 93.5, 92 %,
      and the profiles with one global Cp window
      (before issue 23) 92.5, 92.5, 94, 92 %;
    - method ``seed`` (the measured cloud perturbed), JCGM 101 interval:
      72, 89.5, 93.5, 94.5, 94.5, 0, 0, 0, 0 % (the noise bias of the max/min parameters counted
      twice); reflected about the measured value (bias-corrected): 89, 90.5, 93.5, 94.5, 93.5,
      73, 58.5, 7.5, 13 % (73.5 % for the leading edge with the edge regions frozen).

    The report quotes these numbers (``inspection.stored_studies.COVERAGE_STUDY``).
    """
    scans = 200
    # Scans are independent: two processes (CI has two cores) halve the wall time; each scan's
    # result depends only on its index.
    workers = min(2, os.cpu_count() or 1)
    if workers > 1:
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=context) as pool:
            hits = np.array(list(pool.map(_coverage_of_scan, range(scans), chunksize=10)))
    else:
        hits = np.array([_coverage_of_scan(k) for k in range(scans)])
    seed_hits, reflected_hits, denoised_hits = hits.sum(axis=0)
    coverage = denoised_hits / scans
    assert ((coverage >= 0.92) & (coverage <= 0.98)).all(), coverage
    seed_coverage = seed_hits / scans
    assert ((seed_coverage[2:5] >= 0.92) & (seed_coverage[2:5] <= 0.98)).all(), seed_coverage
    # The numbers the report quotes (COVERAGE_STUDY), to the 0.5 % of one scan in 200.
    study = np.array([COVERAGE_STUDY[name] for name in PARAMETER_NAMES])
    assert seed_coverage == pytest.approx(study[:, 0], abs=0.003), seed_coverage
    assert reflected_hits / scans == pytest.approx(study[:, 1], abs=0.003), reflected_hits / scans
    assert coverage == pytest.approx(study[:, 2], abs=0.003), coverage


@pytest.mark.slow
def test_coverage_over_scenario_families() -> None:
    """Issue 23: 10 scans of each scenario family (smooth forms of 2-13 waves; bumps and dents of
    1-10 µm over 1-20 mm on the sides and at the edges; edge erosion), truth from the noise-free
    part, method ``denoised`` with 2 000 trials and the residual check; 23 s on two idle cores
    with numba (40 s with numpy). The study the report quotes (``FAMILY_STUDY``) is 600 scans per
    family of the same seeds (``benchmarks/bench_section_coverage.py --scans 600``); with 10 scans per family one
    miss is 10 % and the binomial standard uncertainty at 95 % is 7 %.
    """
    workers = min(2, os.cpu_count() or 1)
    backend = resolve_section_backend("auto").name  # what `section` runs; equal to numpy to 1e-12
    outcomes = run_study(FAMILIES, 10, workers=workers, backend=backend)
    by_family = {f: [o for o in outcomes if o.family == f] for f in FAMILIES}
    # Results depend only on (family, scan): scan 3 of "edge" alone gives the same outcome.
    alone = run_study(("edge",), 1, first=3, backend=backend)[0]
    again = by_family["edge"][3]
    assert np.array_equal(alone.inside, again.inside) and alone.p_value == again.p_value
    smooth = by_family["smooth"]
    assert sum(o.flagged for o in smooth) <= 1  # false alarms: level 5 %
    inside = np.array([o.inside for o in smooth if not o.flagged])
    assert (inside.mean(axis=0) >= 0.8).all(), inside.mean(axis=0)
    local = [o for f in ("side", "edge", "erosion") for o in by_family[f]]
    # The check fires on local features (140 of 600 in the 200-scan study).
    assert sum(o.flagged for o in local) >= 4
    kept = np.array([o.inside for o in local if not o.flagged])
    coverage = kept.mean(axis=0)
    # Every parameter holds with local features, the side profiles too now that their intervals
    # reach the roughest form the scan supports (inspection.resolution; before it they covered
    # 81-88 % of the unflagged scans in the 50-scan study and 0.7 was all this test could ask).
    assert (coverage >= 0.85).all(), coverage


@pytest.mark.slow
@pytest.mark.parametrize("index", [0, 1])
def test_linear_parameters_u_equals_the_spread_over_repeated_scans(rotor37_curve: NominalCurve, index: int) -> None:
    """Independent reference for the offsets' and twist's u (issue 23: the twist covered 91.8 % in
    the smooth family): the full extraction run on 300 fresh noisy scans of one smooth-family part
    (scan 0: 2 waves, scan 1: 13 waves, 2.1 µm) spreads as much as the denoised Monte Carlo of
    one of those scans says. The standard deviation of 300 values has ~4 % sampling error: the
    ratio must lie within 12 % of 1. Here: axial, circumferential, twist 0.94, 0.92, 0.99 (scan 0)
    and 0.97, 0.97, 1.05 (scan 1); the twist over six parts 0.93-1.05, mean 0.996."""
    from robocal_uncertainty.inspection import coverage_study as cs

    part_seq, noise_seq, _ = np.random.SeedSequence(23, spawn_key=(0, index)).spawn(3)
    part = cs.draw_part("smooth", np.random.default_rng(part_seq))
    true_scan = simulate_section_scan(
        rotor37_curve,
        cs.N_POINTS,
        offset=cs.OFFSET,
        twist=cs.TWIST,
        form_amplitude=part.form_amplitude,
        form_waves=part.form_waves,
        form_phase=part.form_phase,
    )
    clean = evaluate_section(true_scan, rotor37_curve)
    sources = section_sources(clean, CmmInstrument(), probe_vectors=true_scan.probe_vectors)
    linear = [PARAMETER_NAMES.index(n) for n in ("axial_offset", "circumferential_offset", "twist_angle")]
    rng = np.random.default_rng(1000 + index)
    values = np.array(
        [
            evaluate_section(clean.points + point_displacements(sources, rng)[0], rotor37_curve).parameters.as_array()
            for _ in range(300)
        ]
    )[:, linear]
    noisy = clean.points + point_displacements(sources, np.random.default_rng(noise_seq))[0]
    setup = prepare_trials(noisy, rotor37_curve, method="denoised")
    outputs = summarize(run_trials(setup.trials(), seed=1, n_trials=4000).samples, 0.95, bins=10).outputs
    u = np.array([outputs[j].standard_uncertainty for j in linear])
    spread = values.std(axis=0, ddof=1)
    np.testing.assert_allclose(spread / u, 1.0, atol=0.12)
    # And no bias: the mean of the 300 estimates lies within 4 standard errors of the truth (the
    # noise-free part's extraction), so a coverage below 95 % cannot come from an offset either.
    z = (values.mean(axis=0) - clean.parameters.as_array()[linear]) / (spread / math.sqrt(len(values)))
    assert (np.abs(z) < 4).all(), z
