"""Denoised reference cloud: the smoother's exactness, leverage, noise reduction and window choice."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.cmm_model import CmmInstrument, point_displacements
from robocal_uncertainty.inspection.denoise import (
    denoise_section,
    normal_noise_variance,
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
