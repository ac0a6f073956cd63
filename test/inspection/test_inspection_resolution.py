"""Roughness envelope of the max/min intervals (issue 23): its quantiles against analytic cases and
the full thickness and chord algorithm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocal_uncertainty.core.instruments.cmm import CmmInstrument
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.denoise import normal_noise_variance
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.resolution import ENVELOPE_PARAMETERS, ENVELOPE_STREAM, resolution_envelope
from robocal_uncertainty.inspection.section import SectionEvaluation, chord_length, evaluate_section, max_thickness
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.segmentation import PRESSURE_SIDE, SUCTION_SIDE
from robocal_uncertainty.inspection.simulate import simulate_section_scan

PS = ENVELOPE_PARAMETERS.index("profile_pressure_side")
SS = ENVELOPE_PARAMETERS.index("profile_suction_side")


@pytest.fixture(scope="module")
def clean(rotor37_curve: NominalCurve) -> SectionEvaluation:
    """A noise-free 1 836-point scan of the nominal Rotor 37 section (deviations ~0)."""
    return evaluate_section(simulate_section_scan(rotor37_curve, 1836), rotor37_curve)


def test_a_single_point_extreme_has_the_error_of_two_points(clean: SectionEvaluation) -> None:
    """Smooth limit with one point 1 mm out and one 1 mm in on the pressure side: no draw of the
    bounded noise (micrometres) can move the extremes elsewhere, so the profile error is
    e_i - e_j exactly, whose 97.5 % quantile is ~1.96 sqrt(var_i + var_j) (six rectangular terms
    summed: within 3 % of the normal quantile; 20 000 draws: ~1 % quantile noise)."""
    sources = section_sources(clean, CmmInstrument())
    side = np.flatnonzero(clean.segmentation.labels == 2)
    i, j = side[len(side) // 3], side[2 * len(side) // 3]
    smooth = np.zeros(clean.points.shape[0])
    smooth[i], smooth[j] = 1e-3, -1e-3
    envelope = resolution_envelope(clean, sources, smooth, seed=5, n_draws=20_000)
    variance = normal_noise_variance(sources, clean.registration.normal)
    expected = 1.959964 * math.sqrt(variance[i] + variance[j])
    assert envelope.smooth_high[PS] == pytest.approx(expected, rel=0.05)
    # The rough limit (here the noise-free deviations, ~0 everywhere: every point an extreme)
    # has a range of ~900 noise values: its error is the noise range, far above zero.
    sd = math.sqrt(float(variance[side].mean()))
    assert envelope.rough_low[PS] > 4.0 * sd


def test_widen_never_narrows_and_leaves_other_parameters(clean: SectionEvaluation) -> None:
    sources = section_sources(clean, CmmInstrument())
    envelope = resolution_envelope(clean, sources, clean.registration.residual, seed=1)
    again = resolution_envelope(clean, sources, clean.registration.residual, seed=1)
    np.testing.assert_array_equal(envelope.rough_low, again.rough_low)  # seeded
    assert envelope.widen("twist_angle", 1.0, 2.0) == (1.0, 2.0)
    y = float(envelope.measured[SS])
    # A Monte Carlo interval already wider than the envelope stays as it is.
    assert envelope.widen("profile_suction_side", -1.0, 1.0) == (-1.0, 1.0)
    low, high = envelope.widen("profile_suction_side", math.inf, -math.inf)
    assert low == pytest.approx(y - envelope.smooth_high[SS]) and high == pytest.approx(y - envelope.rough_low[SS])


def test_thickness_and_chord_errors_equal_the_full_algorithm(clean: SectionEvaluation) -> None:
    """At the rough limit (the measured points themselves) the thickness and chord errors are
    those of :func:`max_thickness` and :func:`chord_length` run on every perturbed cloud, the same
    draws (per-point sources first, then the common ones, from the envelope's stream): the
    envelope's quantiles equal the full algorithm's to round-off."""
    sources = section_sources(clean, CmmInstrument())
    n = 120
    envelope = resolution_envelope(clean, sources, clean.registration.residual, seed=3, n_draws=n)
    rng = np.random.default_rng(np.random.SeedSequence(3, spawn_key=(ENVELOPE_STREAM,)))
    ordered = [s for s in sources if s.kind != "common"] + [s for s in sources if s.kind == "common"]
    index = np.arange(clean.points.shape[0])
    shift = np.zeros((n, index.size, 2))
    for source in ordered:
        shift += source.displacement(source.draw(rng, n), index)
    seg = clean.segmentation
    pressure, suction = seg.indices(PRESSURE_SIDE), seg.indices(SUCTION_SIDE)
    moved = clean.points + shift
    thickness = np.array([max_thickness(m[pressure], m[suction]).value for m in moved])
    chord = np.array([chord_length(m)[0] for m in moved])
    y = clean.parameters.as_array()[:2]
    full = np.column_stack([thickness, chord]) - y
    np.testing.assert_allclose(envelope.rough_low[:2], np.quantile(full, 0.025, axis=0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(envelope.measured[:2], y, rtol=0, atol=0)
    # A smooth limit 5 um of three waves away: its points moved along the normals, then the same.
    residual = clean.registration.residual
    smooth = residual + 5e-6 * np.sin(np.linspace(0.0, 6.0 * np.pi, residual.size))
    other = resolution_envelope(clean, sources, smooth, seed=3, n_draws=n)
    base = clean.points + (smooth - residual)[:, np.newaxis] * clean.registration.normal
    at_base = np.array([max_thickness(base[pressure], base[suction]).value, chord_length(base)[0]])
    moved = base + shift
    thickness = np.array([max_thickness(m[pressure], m[suction]).value for m in moved])
    chord = np.array([chord_length(m)[0] for m in moved])
    full = np.column_stack([thickness, chord]) - at_base
    np.testing.assert_allclose(other.smooth_high[:2], np.quantile(full, 0.975, axis=0), rtol=0, atol=1e-12)


def test_bad_settings_are_refused(clean: SectionEvaluation) -> None:
    sources = section_sources(clean, CmmInstrument())
    r = clean.registration.residual
    with pytest.raises(ConfigError, match="coverage"):
        resolution_envelope(clean, sources, r, seed=0, coverage=1.0)
    with pytest.raises(ConfigError, match="n_draws"):
        resolution_envelope(clean, sources, r, seed=0, n_draws=10)
    with pytest.raises(ConfigError, match="shape"):
        resolution_envelope(clean, sources, r[:-1], seed=0)


def test_plateau_extremes_flattens_what_the_fit_cannot_tell_from_the_extreme() -> None:
    """Hand-computed: region 0 = [0, 3.5, 4, 1, -2] with sd 1 -> the points within 1 of the
    maximum 4 (3.5) go to 4, those within 1 of the minimum -2 (none besides it) stay; region 1 is
    flat to within its band: each point goes to the nearer extreme, max and min stay."""
    from robocal_uncertainty.inspection.resolution import plateau_extremes

    d = np.array([0.0, 3.5, 4.0, 1.0, -2.0, 0.1, 0.0, 0.05, 0.2])
    labels = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1])
    out = plateau_extremes(d, np.ones(9), labels, 1.0)
    np.testing.assert_array_equal(out, [0.0, 4.0, 4.0, 1.0, -2.0, 0.2, 0.0, 0.0, 0.2])
    np.testing.assert_array_equal(plateau_extremes(d, np.ones(9), labels, 0.0), d)
    np.testing.assert_array_equal(plateau_extremes(d, np.zeros(9), labels, 1.0), d)


def test_a_flattened_plateau_has_the_larger_noise_bias(clean: SectionEvaluation) -> None:
    """A smooth limit with a 200-point suction-side plateau rippled by its fit's noise (0-3 um
    below its top point, sd 3 um): flattened, its profile errors equal those of the same limit
    with the plateau set flat by hand (the lengths keep the unflattened limit), and the 97.5 %
    quantile rises (200 points at the maximum instead of a few: a larger noise bias)."""
    sources = section_sources(clean, CmmInstrument())
    side = np.flatnonzero(clean.segmentation.labels == 3)
    smooth = np.zeros(clean.points.shape[0])
    smooth[side] = np.linspace(-20e-6, 0.0, side.size)
    plateau = side[side.size // 2 : side.size // 2 + 200]
    smooth[plateau] = 30e-6 - np.random.default_rng(0).uniform(0.0, 3e-6, plateau.size)
    smooth[plateau[100]] = 30e-6
    std = np.full(smooth.shape, 3e-6)
    plain = resolution_envelope(clean, sources, smooth, seed=4, n_draws=4000)
    flat = resolution_envelope(clean, sources, smooth, seed=4, n_draws=4000, smooth_std=std)
    by_hand = smooth.copy()
    by_hand[plateau] = 30e-6
    # The minimum band: the side's first 3 um of the ramp (points within 3 um of -20 um).
    by_hand[side[smooth[side] <= -17e-6]] = -20e-6
    reference = resolution_envelope(clean, sources, by_hand, seed=4, n_draws=4000)
    assert flat.plateau_factor == 1.0 and plain.plateau_factor == 0.0
    assert flat.smooth_high[SS] == pytest.approx(reference.smooth_high[SS], rel=0, abs=1e-15)
    sd = math.sqrt(float(normal_noise_variance(sources, clean.registration.normal)[side].mean()))
    assert flat.smooth_high[SS] > plain.smooth_high[SS] + 0.3 * sd
    np.testing.assert_array_equal(flat.smooth_high[:2], plain.smooth_high[:2])
    np.testing.assert_array_equal(flat.rough_low, plain.rough_low)
    with pytest.raises(ConfigError, match="smooth_std"):
        resolution_envelope(clean, sources, smooth, seed=0, smooth_std=-std)
