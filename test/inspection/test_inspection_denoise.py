"""Denoised reference cloud: the smoother's exactness, leverage, noise reduction and window choice."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.core.instruments.cmm import CmmInstrument, point_displacements
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.denoise import (
    _hat_matrix,
    _smoother_rows,
    denoise_section,
    normal_noise_variance,
    residual_check,
    smooth_normal_deviation,
    window_candidates,
)
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.section import evaluate_section
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.simulate import simulate_section_scan


@pytest.fixture(scope="module")
def contour(rotor37_curve: NominalCurve) -> tuple[np.ndarray, np.ndarray, float]:
    """Parameters and normals of a 1 836-point scan of the seed-sized Rotor 37 section."""
    cloud = simulate_section_scan(rotor37_curve, 1836)
    registration = evaluate_section(cloud, rotor37_curve).registration
    return registration.parameter, registration.normal, rotor37_curve.period


def test_a_quadratic_and_a_translation_are_reproduced(contour: tuple[np.ndarray, np.ndarray, float]) -> None:
    u, normal, period = contour
    # A rigid translation of the nominal by v shows as n(s)·v: a bump of the edge radius's width
    # at each edge. The local translation term follows it where the normal turns; elsewhere the
    # quadratic does, to within the term's threshold (1 % of |v|, here 30 nm).
    v = np.array([2e-6, -3e-6])
    bump = normal @ v
    for half_width in (5e-3, 40e-3):
        fit, _ = smooth_normal_deviation(u, bump, normal, period, half_width)
        assert np.abs(fit - bump).max() < 0.01 * np.linalg.norm(v)
    # A parabola in s is reproduced wherever the window does not wrap around (exact local model).
    middle = (u > 0.3 * period) & (u < 0.7 * period)
    parabola = 1e-6 * ((u - 0.5 * period) / 0.1) ** 2
    fit, _ = smooth_normal_deviation(u, parabola, normal, period, 20e-3)
    assert fit[middle] == pytest.approx(parabola[middle], abs=1e-15)


def test_leverage_is_the_hat_diagonal_and_the_fit_is_linear(contour: tuple[np.ndarray, np.ndarray, float]) -> None:
    u, normal, period = contour
    rng = np.random.default_rng(3)
    r = rng.normal(0.0, 1e-6, u.shape[0])
    fit, leverage = smooth_normal_deviation(u, r, normal, period, 10e-3)
    for i in (0, 20, 500, 917, 1835):  # edges (dense points, translation term) and sides
        unit = np.zeros_like(r)
        unit[i] = 1.0
        column, _ = smooth_normal_deviation(u, unit, normal, period, 10e-3)
        assert column[i] == pytest.approx(leverage[i], rel=1e-9)
    at = np.array([5, 917])
    part, part_leverage = smooth_normal_deviation(u, r, normal, period, 10e-3, at=at)
    assert part == pytest.approx(fit[at], rel=1e-12, abs=1e-20)
    assert part_leverage == pytest.approx(leverage[at], rel=1e-12)
    twice, _ = smooth_normal_deviation(u, 2 * r, normal, period, 10e-3)
    assert twice == pytest.approx(2 * fit, rel=1e-9, abs=1e-20)


def test_window_choice_follows_the_form_wavelength(rotor37_curve: NominalCurve) -> None:
    instrument = CmmInstrument()
    chosen = []
    errors = []
    for waves in (3, 24):
        cloud = simulate_section_scan(rotor37_curve, 1836, form_amplitude=5e-6, form_waves=waves)
        clean = evaluate_section(cloud, rotor37_curve)
        sources = section_sources(clean, instrument, probe_vectors=cloud.probe_vectors)
        noisy = clean.points + point_displacements(sources, np.random.default_rng(waves))[0]
        evaluation = evaluate_section(noisy, rotor37_curve)
        denoised = denoise_section(evaluation, sources, rotor37_curve.period)
        assert denoised.half_width in denoised.candidates
        assert denoised.risk[denoised.candidates.index(denoised.half_width)] == min(denoised.risk)
        chosen.append(denoised.half_width)
        # The denoised deviations are much closer to the true ones than the measured ones.
        true_deviation = evaluate_section(clean.points, rotor37_curve).registration.residual
        measured_error = np.sqrt(np.mean((evaluation.registration.residual - true_deviation) ** 2))
        denoised_error = np.sqrt(np.mean((denoised.deviation - true_deviation) ** 2))
        errors.append((measured_error, denoised_error))
        assert denoised.noise_std == pytest.approx(
            np.sqrt(normal_noise_variance(sources, evaluation.registration.normal)), rel=0.05
        )
    # A 3-wave form (270 mm wavelength) gets a wider window than a 24-wave one (34 mm).
    assert chosen[0] > 2 * chosen[1]
    assert errors[0][1] < 0.15 * errors[0][0] and errors[1][1] < 0.35 * errors[1][0], errors


def test_candidates_and_bad_windows(contour: tuple[np.ndarray, np.ndarray, float]) -> None:
    u, normal, period = contour
    candidates = window_candidates(u, period)
    assert candidates[0] == pytest.approx(0.005 * period) and candidates[-1] == pytest.approx(0.15 * period)
    assert window_candidates(u[::40], period)[0] >= 4 * np.diff(u[::40]).max()
    with pytest.raises(ConfigError, match="half_width must be in"):
        smooth_normal_deviation(u, np.zeros_like(u), normal, period, period)


def _noisy_scan(curve: NominalCurve, features: tuple, seed: int) -> tuple[np.ndarray, np.ndarray, object, tuple]:
    """True deviations, a noisy evaluation and the sources of a 1 836-point scan with features."""
    from robocal_uncertainty.inspection.coverage_study import feature_deviation

    cloud = simulate_section_scan(
        curve,
        1836,
        form_amplitude=5e-6,
        deviation=(lambda u: feature_deviation(u, features, curve.period)) if features else None,
    )
    clean = evaluate_section(cloud, curve)
    sources = section_sources(clean, CmmInstrument(), probe_vectors=cloud.probe_vectors)
    noisy = clean.points + point_displacements(sources, np.random.default_rng(seed))[0]
    evaluation = evaluate_section(noisy, curve)
    return clean.registration.residual, clean.registration.parameter, evaluation, sources


def test_local_windows_follow_a_bump_the_global_window_flattens(rotor37_curve: NominalCurve) -> None:
    from robocal_uncertainty.inspection.coverage_study import Feature

    # A 4 µm bump 10 mm wide on the suction side, 20 mm behind the trailing edge: Cp, a global
    # risk, still picks an 81 mm window (a 6 µm x 12 mm bump would pull it down to 8 mm everywhere).
    centre = 0.4214
    true_deviation, u, evaluation, sources = _noisy_scan(rotor37_curve, (Feature("bump", centre, 4e-6, 10e-3),), 5)
    adaptive = denoise_section(evaluation, sources, rotor37_curve.period)
    fixed = denoise_section(evaluation, sources, rotor37_curve.period, half_width=adaptive.half_width)
    at_bump = np.abs(u - centre) < 2e-3
    far = np.abs(u - centre) > 60e-3
    # Windows narrow at the bump and stay at the Cp choice far from it.
    assert adaptive.local_half_width[at_bump].max() < 0.5 * adaptive.half_width
    assert np.median(adaptive.local_half_width[far]) == adaptive.half_width
    assert (adaptive.local_half_width <= adaptive.half_width).all()
    # The bump's top: the fixed Cp window flattens it by micrometres, the local windows follow it.
    fixed_error = np.abs(fixed.deviation - true_deviation)[at_bump].max()
    local_error = np.abs(adaptive.deviation - true_deviation)[at_bump].max()
    assert fixed_error > 3e-6 and local_error < 0.6 * fixed_error, (fixed_error, local_error)


def test_residual_check_flags_a_feature_narrower_than_every_window(rotor37_curve: NominalCurve) -> None:
    from robocal_uncertainty.inspection.coverage_study import Feature

    smooth = denoise_section(*_noisy_scan(rotor37_curve, (), 7)[2:], rotor37_curve.period)
    assert not smooth.check.flagged and smooth.check.p_value > 0.05
    # An 8 µm dent 3 mm wide on the pressure side: narrower than the narrowest window (4 mm half-width).
    centre = 0.2
    *_, evaluation, sources = _noisy_scan(rotor37_curve, (Feature("dent", centre, 8e-6, 3e-3),), 7)
    dented = denoise_section(evaluation, sources, rotor37_curve.period)
    check = dented.check
    assert check.flagged and check.p_value <= check.level
    assert abs(check.location - centre) < 2e-3 and check.extent < 3e-3
    assert "FLAGGED" in check.describe()
    # Reproducible: the null draws come from the stated seed.
    again = denoise_section(evaluation, sources, rotor37_curve.period)
    assert again.check.p_value == check.p_value and again.check.seed == 0


def test_residual_check_null_is_calibrated(rotor37_curve: NominalCurve) -> None:
    # Residuals that are themselves instrument noise through the smoother: the p-value is
    # uniform, so about `level` of such clouds are flagged (binomial: 0-7 of 40 at 5 %).
    *_, evaluation, sources = _noisy_scan(rotor37_curve, (), 11)
    u = evaluation.registration.parameter
    normal = evaluation.registration.normal
    n = u.shape[0]
    weights, source, _ = _smoother_rows(u, normal, rotor37_curve.period, 20e-3, np.arange(n))
    hat = _hat_matrix([(weights, source)], np.zeros(n, dtype=np.intp), n)

    def smoother(values: np.ndarray) -> np.ndarray:
        return np.asarray(hat @ values.T).T

    rng = np.random.default_rng(99)
    per_point = [s for s in sources if s.kind != "common"]
    noise = sum(s.normal_displacement(s.draw(rng, 40), normal) for s in per_point)
    residuals = noise - smoother(noise)
    local = np.full(n, 20e-3)
    p_values = [residual_check(r, smoother, sources, normal, u, local, seed=3).p_value for r in residuals]
    flagged = sum(p <= 0.05 for p in p_values)
    assert flagged <= 7, p_values
    assert 0.3 < float(np.mean(p_values)) < 0.7, p_values
    # A 6 µm plateau over 20 consecutive points (about 9 mm on the side), as the smoother leaves it.
    plateau = np.where((np.arange(n) >= 600) & (np.arange(n) < 620), 6e-6, 0.0)[np.newaxis, :]
    stepped = residuals[0] + (plateau - smoother(plateau))[0]
    assert residual_check(stepped, smoother, sources, normal, u, local, seed=3).flagged
