"""Roughness envelope of the profile intervals (issue 23): its quantiles against analytic cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.cmm_model import CmmInstrument
from robocal_uncertainty.inspection.denoise import normal_noise_variance
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.resolution import PROFILE_PARAMETERS, resolution_envelope
from robocal_uncertainty.inspection.section import SectionEvaluation, evaluate_section
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.simulate import simulate_section_scan

PS = PROFILE_PARAMETERS.index("profile_pressure_side")
SS = PROFILE_PARAMETERS.index("profile_suction_side")


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
    assert envelope.widen("chord_length", 1.0, 2.0) == (1.0, 2.0)
    y = float(envelope.measured[SS])
    # A Monte Carlo interval already wider than the envelope stays as it is.
    assert envelope.widen("profile_suction_side", -1.0, 1.0) == (-1.0, 1.0)
    low, high = envelope.widen("profile_suction_side", math.inf, -math.inf)
    assert low == pytest.approx(y - envelope.smooth_high[SS]) and high == pytest.approx(y - envelope.rough_low[SS])


def test_bad_settings_are_refused(clean: SectionEvaluation) -> None:
    sources = section_sources(clean, CmmInstrument())
    r = clean.registration.residual
    with pytest.raises(ConfigError, match="coverage"):
        resolution_envelope(clean, sources, r, seed=0, coverage=1.0)
    with pytest.raises(ConfigError, match="n_draws"):
        resolution_envelope(clean, sources, r, seed=0, n_draws=10)
    with pytest.raises(ConfigError, match="shape"):
        resolution_envelope(clean, sources, r[:-1], seed=0)
